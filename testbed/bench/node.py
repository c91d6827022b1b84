"""Benchmark of the robot application and the world.

- plan generation: one robot explores the empty 20 x 20 m terrain in-process (the world, the
  robot's log-odds map and planner, no network), planning every 20 steps as a robot does;
  every plan on the 400 x 400 map is timed (the planner works on 10 cm planning cells, 200 x
  200, see node/planner.py). Also the per-frame map update.
- 10-robot runs (empty terrain, comm range 20 m, babel) capped at RUN_STEPS steps (the
  start, when all ten explore at once, is the busiest part) at increasing time scales: the
  fraction of step deadlines missed (world and robots, see testbed/run/execute.py) at each, and the
  highest scale missing under 1 % (best of two attempts per scale), searched three times:
  the median is the result, since a host that steals CPU time for a minute (recorded per
  run from /proc/stat) decides one search alone. Per robot: CPU (fraction of a core, ms per
  step) and peak resident memory.
Targets: plan <= 20 ms median; a 10-robot run at time scale >= 5 missing < 1 % of deadlines;
<= 150 MB per robot process. The machine is shared: its load average is recorded.
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
import tempfile
import time
import uuid
from typing import Any

import numpy as np

from node import stepcore
from node.grid import OccupancyGrid
from node.planner import PlannerParams, plan
from node.rays import _BIAS, Laser
from testbed.bench.common import median, write
from testbed.files import robotfile
from testbed.world.world import World
from testbed.world.worldmap import empty_terrain, free_space, start_positions

RUN_STEPS = 300
ATTEMPTS = 2
SEARCHES = 3  # the result is the median of this many searches
CLK_TCK = os.sysconf("SC_CLK_TCK")
SCALES = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
MAX_SIM_STEPS = 6000


def simulate_exploration(seed: int = 1, positions: bool = False) -> dict:
    """One robot, in-process: the robot's own loop without threads or network, with the
    per-step work the robot runs (compiled where node.stepcore is built). `positions`: the
    result also has the robot's position after every step."""
    truth = empty_terrain()
    laser = Laser(2.0, 360, truth.cell)
    starts = start_positions(truth, 1, np.random.default_rng(seed), 0.15)
    world = World(truth, starts, laser, free_space(truth, starts), 0.1, 0.15)
    grid = OccupancyGrid(truth.shape, truth.cell, pad=laser.pad)
    own = np.zeros(grid.Lp.shape, dtype=np.uint8)  # the robot's local map
    prm = PlannerParams(truth.cell, 2, 0.15)
    plan_ms, update_ms, track = [], [], []
    path, i, status, step = [], 0, "ok", 0
    for step in range(MAX_SIM_STEPS):
        b = world.bodies[0]
        ranges = world.scan(0)
        t0 = time.perf_counter()
        if not (stepcore.NATIVE and stepcore.scan_into(laser, b.x, b.y, ranges, grid.Lp, own,
                                                       grid.params, _BIAS)):  # fmt: skip
            r0, c0, free, occ = laser.scan_window(b.x, b.y, ranges)  # as node.robot does
            grid.update_window(r0, c0, free, occ)
        update_ms.append((time.perf_counter() - t0) * 1000)
        if step % 20 == 0:
            t0 = time.perf_counter()
            p = plan(grid.ternary(), (b.x, b.y), [], 2.0, prm)
            plan_ms.append((time.perf_counter() - t0) * 1000)
            status, path, i = p.status, p.path, 0
            if status == "done":
                break
        while i < len(path) and np.hypot(path[i][0] - b.x, path[i][1] - b.y) < 1e-3:
            i += 1
        world.command(0, path[i] if i < len(path) else None)
        world.move()
        if positions:
            track.append((b.x, b.y))
    out = {
        "steps": step,
        "finished": status == "done",
        "coverage": round(world.coverage(), 4),
        "plans": len(plan_ms),
        "plan_ms": _stats(plan_ms),
        "map_update_ms": _stats(update_ms),
        "step_core": stepcore.kind(),
    }
    if positions:
        out["positions"] = track
    return out


def _stats(v: list[float]) -> dict:
    a = np.asarray(v)
    return {
        "median": round(float(np.median(a)), 3),
        "p90": round(float(np.percentile(a, 90)), 3),
        "max": round(float(a.max()), 3),
        "n": len(v),
    }


def ten_robot_run(time_scale: float, seed: int = 3) -> dict:
    from testbed.run.execute import RunConfig, run
    from topology.network import destroy

    name = "tn" + uuid.uuid4().hex[:6]
    out = tempfile.mkdtemp(prefix="bench-node-")
    cfg = RunConfig(robots=10, comm_range=20.0, seed=seed, time_scale=time_scale,
                    routing="babel", max_steps=RUN_STEPS)  # fmt: skip
    load = os.getloadavg()[0]
    try:
        r = run(cfg, out, name, progress=False)
        robots = [rec for k in range(1, 11) if (rec := robotfile.read(out, k)) is not None]
    finally:
        destroy(name)
        shutil.rmtree(out, ignore_errors=True)
    wall = r.step_loop_wall_s or 1e-9
    steps = r.steps or 0
    cpu = [d.cpu_s for d in robots if d.cpu_s is not None]
    rss = [d.max_rss_mb for d in robots if d.max_rss_mb is not None]
    answer = [d.latency_ms["answer"]["p50"] for d in robots if d.latency_ms]
    return {
        "time_scale": time_scale,
        "status": r.status,
        "steps": r.steps,
        "time_scale_achieved": r.time_scale_achieved,
        "deadline_miss_fraction": r.deadline_miss_fraction,
        "deadlines_missed_world": r.deadlines_missed_world,
        # For reading, not for the search (which counts every miss): how many of the misses
        # fell while the host held the machine (testbed/run/stalls.py).
        "deadline_miss_fraction_outside_stalls": r.deadline_miss_fraction_outside_stalls,
        "host_stalls": r.host_stalls.to_dict(),
        "world_cpu_ms_per_step": round(
            1000 * r.world_timing_s.get("world_cpu_s", 0) / max(1, steps), 2
        ),
        # Robot CPU from the fork (the imports were done once, in the fork server).
        "robot_cpu_core_fraction_mean": round(statistics.mean(cpu) / wall, 3) if cpu else None,
        "robot_cpu_ms_per_step_mean": round(1000 * statistics.mean(cpu) / max(1, steps), 2)
        if cpu
        else None,
        "robot_max_rss_mb": max(rss) if rss else None,
        "robot_answer_ms_p50_median": round(median(answer), 2) if answer else None,
        "load_average_before": round(load, 2),
    }


def _steal_jiffies() -> int:
    """CPU time the hypervisor took from this machine so far (/proc/stat, all CPUs)."""
    with open("/proc/stat") as f:
        fields = f.readline().split()
    return int(fields[8]) if len(fields) > 8 else 0


def scale_search() -> tuple[float | None, list[dict]]:
    """Raise the time scale until a 10-robot run misses 1% of its deadlines (best of
    ATTEMPTS per scale); the highest scale that did not, and every run."""
    runs, best = [], None
    for k in SCALES:
        ok = False
        for _ in range(ATTEMPTS):  # the machine is shared: one unlucky run does not decide
            st0, t0 = _steal_jiffies(), time.monotonic()
            res = ten_robot_run(k)
            wall = time.monotonic() - t0
            res["host_steal_fraction"] = round(
                (_steal_jiffies() - st0) / CLK_TCK / (wall * (os.cpu_count() or 1)), 3
            )
            runs.append(res)
            print(
                f"bench node: 10 robots at time scale {k}: {res['deadline_miss_fraction']:.2%} "
                f"deadlines missed, achieved {res['time_scale_achieved']}x, host steal "
                f"{res['host_steal_fraction']:.0%}",
                file=sys.stderr,
            )
            if res["deadline_miss_fraction"] < 0.01:
                ok = True
                break
        if not ok:
            break  # higher scales only miss more
        best = k
    return best, runs


def run() -> dict:
    sim = simulate_exploration()
    searches: list[dict[str, Any]] = []
    for _ in range(SEARCHES):  # a host that steals CPU for a while decides one search alone
        found, found_runs = scale_search()
        searches.append({"max_time_scale_under_1pct_missed": found, "runs": found_runs})
    bests = sorted(x["max_time_scale_under_1pct_missed"] or 0.0 for x in searches)
    best = bests[len(bests) // 2] or None
    runs = [r for x in searches for r in x["runs"]]
    ref = next((r for r in runs if r["time_scale"] == 5.0), runs[-1])
    # What the CPU alone allows: 10 K steps per second of wall time, each costing the robots'
    # and the world's CPU per step, on all of this machine's cores (an upper bound: start-up
    # CPU is included, other work on the machine and scheduling delays are not).
    cores = os.cpu_count() or 1
    per_step = 10 * ref["robot_cpu_ms_per_step_mean"] + ref["world_cpu_ms_per_step"]
    cpu_bound = round(cores * 100.0 / per_step, 2) if per_step > 0 else None
    rss = max(r["robot_max_rss_mb"] or 0 for r in runs)
    plan_median = sim["plan_ms"]["median"]
    data = {
        "plan_generation": {
            "grid": "400 x 400 map (5 cm), planned on 200 x 200 cells of 10 cm",
            **sim,
        },
        "scale_searches": searches,
        "max_time_scale_under_1pct_missed": best,
        "max_time_scale_each_search": [x["max_time_scale_under_1pct_missed"] for x in searches],
        "cpu_bound_time_scale_estimate": cpu_bound,
        "cores": cores,
        "per_robot": {
            "at_time_scale": ref["time_scale"],
            "cpu_core_fraction": ref["robot_cpu_core_fraction_mean"],
            "cpu_ms_per_step": ref["robot_cpu_ms_per_step_mean"],
            "max_rss_mb": rss,
        },
        "targets": {
            "plan_ms_median": {"target": 20.0, "measured": plan_median, "met": plan_median <= 20.0},
            "time_scale_10_robots": {
                "target": 5.0,
                "measured": best,
                "met": best is not None and best >= 5.0,
            },
            "robot_rss_mb": {"target": 150.0, "measured": rss, "met": rss <= 150.0},
        },  # fmt: skip
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),
        "note": "2-core machine shared with other work: deadline misses grow with its load",
    }
    path = write("node", data)
    print(f"bench node: wrote {path}", file=sys.stderr)
    return data


if __name__ == "__main__":
    if os.geteuid() != 0:
        print("bench node: needs root (network namespaces)", file=sys.stderr)
        sys.exit(2)
    run()
