"""A random-waypoint trace in ns-2 format (as BonnMotion's NSFile writes it), for
`testbed net up --mobility`.

    python -m testbed.tools.randomwaypoint --nodes 100 --size 200 200 --duration 300 \
        --speed 0.5 2 --pause 5 --seed 1 > rwp.ns2

Each node starts at a uniform random point, then repeatedly picks a uniform random
destination, travels to it at a speed uniform in [min, max] and pauses, until the duration.
"""

import argparse
import math
import random
import sys


def trace(nodes: int, width: float, height: float, duration: float, speed: tuple[float, float],
          pause: float, seed: int) -> list[str]:  # fmt: skip
    rng = random.Random(seed)
    lines = [f"# random waypoint: {nodes} nodes, {width:g} x {height:g} m, {duration:g} s, "
             f"speed {speed[0]:g}-{speed[1]:g} m/s, pause {pause:g} s, seed {seed}"]  # fmt: skip
    legs = []
    for i in range(nodes):
        x, y = rng.uniform(0, width), rng.uniform(0, height)
        lines += [f"$node_({i}) set X_ {x:.3f}", f"$node_({i}) set Y_ {y:.3f}",
                  f"$node_({i}) set Z_ 0.000"]  # fmt: skip
        t = 0.0
        while t < duration:
            nx, ny = rng.uniform(0, width), rng.uniform(0, height)
            v = rng.uniform(*speed)
            legs.append((t, f'$ns_ at {t:.3f} "$node_({i}) setdest {nx:.3f} {ny:.3f} {v:.3f}"'))
            t += math.hypot(nx - x, ny - y) / v + pause
            x, y = nx, ny
    return lines + [line for _, line in sorted(legs, key=lambda leg: leg[0])]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m testbed.tools.randomwaypoint")
    p.add_argument("--nodes", type=int, default=100, help="nodes (default 100)")
    p.add_argument("--size", type=float, nargs=2, default=(200.0, 200.0), metavar=("W", "H"),
                   help="the area (metres; default 200 200)")  # fmt: skip
    p.add_argument("--duration", type=float, default=300.0,
                   help="a node starts no new leg after this (seconds; default 300); the leg "
                        "under way is finished, so the trace ends somewhat later")  # fmt: skip
    p.add_argument("--speed", type=float, nargs=2, default=(0.5, 2.0), metavar=("MIN", "MAX"),
                   help="speed of a leg, uniform in [MIN, MAX] (m/s; default 0.5 2)")  # fmt: skip
    p.add_argument("--pause", type=float, default=5.0,
                   help="pause at each destination (seconds; default 5)")  # fmt: skip
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    a = p.parse_args(argv)
    if a.nodes < 1 or min(a.size) <= 0 or a.duration <= 0 or not 0 < a.speed[0] <= a.speed[1]:
        print("randomwaypoint: need nodes >= 1, a positive size and duration, "
              "0 < MIN <= MAX speed", file=sys.stderr)  # fmt: skip
        return 2
    if a.pause < 0:
        print("randomwaypoint: pause must be >= 0", file=sys.stderr)
        return 2
    width, height = a.size
    sys.stdout.write("\n".join(trace(a.nodes, width, height, a.duration, tuple(a.speed), a.pause,
                                     a.seed)) + "\n")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
