"""Benchmark of the line-of-sight range model: its cost per world step, against the disc's.

Ten robots at random free spots of the shipped office map (20 x 20 m, 0.05 m pixels), range
20 m (every pair a candidate: the worst case), and 5 m; each step moves every robot 0.1 m.
The time of ranges.wanted_links per step, median over STEPS steps, for disc and los. The
step budget at time scale 15 is 6.7 ms; the world's own step takes about 1 ms of it.
"""

import os
import random
import time
from typing import Any

from testbed import PROJECT_ROOT
from testbed.bench.common import median, write
from topology.radio import ranges
from topology.radio.los import Walls
from topology.spec import CELL_M

STEPS = 2000
OFFICE = os.path.join(PROJECT_ROOT, "testbed", "experiments", "maps", "office.png")


def _walk(walls: Walls, rng: random.Random) -> list[list[tuple[float, float]]]:
    def free(x: float, y: float) -> bool:
        r, c = int(y / walls.cell), int(x / walls.cell)
        return (
            0 <= r < walls.occupied.shape[0]
            and 0 <= c < walls.occupied.shape[1]
            and not (walls.occupied[r, c])
        )

    pos: list[tuple[float, float]] = []
    while len(pos) < 10:
        p = (rng.uniform(0.5, 19.5), rng.uniform(0.5, 19.5))
        if free(*p):
            pos.append(p)
    steps = []
    for _ in range(STEPS):
        pos = [(x + rng.uniform(-0.1, 0.1), y + rng.uniform(-0.1, 0.1)) for x, y in pos]
        steps.append(list(pos))
    return steps


def _time(steps, comm_range: float, model: str, walls: Walls | None) -> float:
    ts = []
    for pos in steps:
        t0 = time.perf_counter()
        ranges.wanted_links(pos, comm_range, model, walls)
        ts.append(time.perf_counter() - t0)
    return 1e6 * median(ts)


def run() -> None:
    walls = Walls.from_png(OFFICE, CELL_M)
    steps = _walk(walls, random.Random(1))
    result: dict[str, Any] = {"robots": 10, "steps": STEPS}
    for comm in (5.0, 20.0):
        result[f"range_{comm:g}m"] = {
            "disc_us_median": _time(steps, comm, "disc", None),
            "los_us_median": _time(steps, comm, "los", walls),
        }
    write("los", result)
    r = result["range_20m"]
    at5 = result["range_5m"]["los_us_median"]
    print(f"los: {r['los_us_median']:.0f} us per 10-robot step at 20 m range (disc "
          f"{r['disc_us_median']:.0f} us); at 5 m {at5:.0f} us")  # fmt: skip
