"""Benchmark of oracle routing (topology.oracle): how fast routes follow the links.

- re-route: robots 1 - 2 - 3 in a line (8 m apart, range 10 m); robot 2 steps out of range
  and back, REPEATS times each way. From Network.move() returning to robot 3's kernel
  holding (or no longer holding) its route to robot 1, read with a netlink route lookup in
  robot 3's namespace; and the whole move (links switched, routes installed). Target:
  under 5 ms, median.
- keep-up: 10 robots walking to random waypoints at 1 m/s on a 20 x 20 m map, range 5 m,
  one world step (0.1 s of robot time) every 0.1 / 15 s as at time scale 15, for STEPS
  steps. Per step with a link change: the time to switch the links and install every
  robot's new routes (Network.set_positions), against the step's budget of 6.7 ms.
"""

import random
import socket
import time
import uuid
from typing import Any

from testbed.bench.common import median, write
from topology import names
from topology.kernel import netns, routequery, rtnl
from topology.network import Network
from topology.spec import NetworkSpec

REPEATS = 50
STEPS = 1500
TIME_SCALE = 15.0
STEP_S = 0.1


def _name() -> str:
    return "bo" + uuid.uuid4().hex[:6]


def has_route(sock: socket.socket, dest: str) -> bool:
    """Does the namespace of `sock` hold a route to `dest` on wlan0 (the view's lookup)?"""
    return routequery.next_hop(sock, dest) is not None


def reroute() -> dict:
    spec = NetworkSpec(_name(), ((0, 0), (8, 0), (16, 0)), 10.0, routing="oracle")
    lags, moves = [], []
    with Network(spec) as net:
        sock = netns.run_in(names.robot_ns(spec.name, 3), rtnl.open_socket)
        try:
            for i in range(2 * REPEATS):
                present = i % 2 == 1  # step out (route gone), then back (route there)
                t0 = time.perf_counter()
                net.move(2, (8.0, 0.0) if present else (8.0, 30.0))
                t1 = time.perf_counter()
                while has_route(sock, "10.0.0.1") != present:
                    if time.perf_counter() - t1 > 1.0:
                        raise RuntimeError("route did not follow the move within 1 s")
                t2 = time.perf_counter()
                lags.append(t2 - t1)
                moves.append(t2 - t0)
        finally:
            sock.close()
    return {
        "changes": len(lags),
        "lag_after_move_ms_median": 1000 * median(lags),
        "lag_after_move_ms_max": 1000 * max(lags),
        "move_to_route_ms_median": 1000 * median(moves),
        "move_to_route_ms_max": 1000 * max(moves),
        "target_ms": 5.0,
    }


def keep_up(seed: int = 1) -> dict:
    rng = random.Random(seed)
    pos = [(rng.uniform(0, 20), rng.uniform(0, 20)) for _ in range(10)]
    goals = [(rng.uniform(0, 20), rng.uniform(0, 20)) for _ in range(10)]
    spec = NetworkSpec(_name(), tuple(pos), 5.0, routing="oracle", time_scale=TIME_SCALE)
    budget = STEP_S / TIME_SCALE
    update_s, route_s, changed_steps, over = [], [], 0, 0
    with Network(spec) as net:
        oracle = net.oracle
        assert oracle is not None  # routing "oracle"
        next_step = time.perf_counter()
        for _ in range(STEPS):
            for k in range(10):
                (x, y), (gx, gy) = pos[k], goals[k]
                d = ((gx - x) ** 2 + (gy - y) ** 2) ** 0.5
                if d < 0.1:
                    goals[k] = (rng.uniform(0, 20), rng.uniform(0, 20))
                    continue
                pos[k] = (x + 0.1 * (gx - x) / d, y + 0.1 * (gy - y) / d)
            t0 = time.perf_counter()
            added, removed = net.set_positions(pos)
            dt = time.perf_counter() - t0
            if added or removed:
                changed_steps += 1
                update_s.append(dt)
                route_s.append(oracle.last_update_s)
                over += dt > budget
            next_step += budget
            time.sleep(max(0.0, next_step - time.perf_counter()))
        updates = oracle.updates

    def p95(xs: list[float]) -> float:
        return sorted(xs)[int(0.95 * (len(xs) - 1))] if xs else 0.0

    return {
        "robots": 10,
        "time_scale": TIME_SCALE,
        "steps": STEPS,
        "steps_with_link_changes": changed_steps,
        "route_updates": updates,
        "step_budget_ms": 1000 * budget,
        "links_and_routes_ms_median": 1000 * median(update_s) if update_s else 0.0,
        "links_and_routes_ms_p95": 1000 * p95(update_s),
        # The oracle's own part: from the new link set to the last route acknowledged.
        "routes_ms_median": 1000 * median(route_s) if route_s else 0.0,
        "routes_ms_p95": 1000 * p95(route_s),
        "routes_ms_max": 1000 * max(route_s, default=0.0),
        "changed_steps_over_budget": over,
    }


def run() -> None:
    result: dict[str, Any] = {
        "reroute": reroute(),
        "keep_up": keep_up(),
        "load_avg": list(_loadavg()),
    }
    write("oracle", result)
    r, k = result["reroute"], result["keep_up"]
    print(
        f"oracle: route in the far robot {r['lag_after_move_ms_median']:.3f} ms after move() "
        f"returned (median of {r['changes']}), {r['move_to_route_ms_median']:.2f} ms from the "
        f"move's start; 10 robots at time scale 15: routes {k['routes_ms_median']:.2f} ms "
        f"median, {k['routes_ms_p95']:.2f} ms p95 after the links; links and routes "
        f"{k['links_and_routes_ms_median']:.2f} ms median, {k['links_and_routes_ms_p95']:.2f} "
        f"ms p95, budget {k['step_budget_ms']:.1f} ms, {k['changed_steps_over_budget']} of "
        f"{k['steps_with_link_changes']} changing steps over it"
    )


def _loadavg() -> tuple[float, float, float]:
    with open("/proc/loadavg") as f:
        a, b, c = f.read().split()[:3]
    return float(a), float(b), float(c)
