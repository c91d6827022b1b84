"""What a finished run writes about itself: robots/rK.json, paths.png and the result dict.

`write(run)` reads what the robot processes logged (robots/rK.events.jsonl) and what the
world recorded on the `Run` (testbed.run), writes each robot's detailed record and the
picture of the paths, and returns the contents of result.json, which the run writes last
(docs/run-results.md says what every key means). A picture that cannot be drawn is logged,
never a reason to lose the results.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
from typing import TYPE_CHECKING

import cv2
import numpy as np

from node import render
from testbed.runconfig import STEP_S
from testbed.world.world import World
from topology.jsonfile import write_json_atomic

if TYPE_CHECKING:
    from testbed.run import RobotRecord, Run

log = logging.getLogger(__name__)

RESULT_FORMAT = 1
# The keys of config.json that result.json repeats under "config" (the contract's).
RESULT_CONFIG_KEYS = (
    "robots", "comm_range", "laser_range", "seed", "time_scale", "routing", "map", "loss_pct",
    "delay_ms", "capture", "max_steps", "coordination", "start",
)  # fmt: skip
# What each robot's summary line (its last event) says, copied into robots/rK.json.
SUMMARY_KEYS = (
    "send_failed", "flood", "frames_skipped", "plan_ms_median", "cpu_s", "max_rss_mb", "busy_s",
    "frames", "latency_ms", "thread_cpu_s",
)  # fmt: skip
PLAN_DETAIL_KEYS = ("step", "cause", "status", "goal", "cost", "ms")
NO_STALLS = {"events": 0, "stalled_s": 0.0, "deadlines_missed": 0}


def read_events(path: str) -> list[dict]:
    """A robot's event log; a line cut short by a crash is skipped, a missing log is empty."""
    out = []
    try:
        with open(path) as f:
            for line in f:
                with contextlib.suppress(json.JSONDecodeError):
                    out.append(json.loads(line))
    except FileNotFoundError:
        pass
    return out


def robot_result(run: Run, r: RobotRecord) -> dict:
    """Robot r's entry in result.json; its fuller record goes to robots/rK.json."""
    ev = read_events(os.path.join(run.out, "robots", f"r{r.k}.events.jsonl"))
    plans = [{"step": e["step"], "cause": e["cause"]} for e in ev if e["e"] == "plan"]
    sent: dict[str, int] = {}
    received: dict[str, int] = {}
    for e in ev:
        if e["e"] == "send":
            sent[e["kind"]] = sent.get(e["kind"], 0) + 1
        elif e["e"] == "recv":
            received[e["kind"]] = received.get(e["kind"], 0) + 1
    summary = next((e for e in reversed(ev) if e["e"] == "summary"), {})
    b = run.world.bodies[r.k - 1]
    rec = {
        "finish_step": r.finish_step,
        "crashed": r.crashed,
        "exit_status": r.exit_status,
        "plans": plans,
        "messages": {"sent": sent, "received": received},
        "path_length_m": round(b.path_length, 3),
    }
    detail = dict(rec)
    detail.update(
        crash_step=r.crash_step, killed_at=r.killed_at, deadlines_missed=r.missed,
        deadlines_missed_steps=r.missed_steps,
        collisions=b.collisions, final_pose=[round(b.x, 3), round(b.y, 3)],
        plan_details=[{k: e.get(k) for k in PLAN_DETAIL_KEYS} for e in ev if e["e"] == "plan"],
    )  # fmt: skip
    detail.update({k: summary.get(k) for k in SUMMARY_KEYS})
    write_json_atomic(os.path.join(run.out, "robots", f"r{r.k}.json"), detail)
    return rec


def write(run: Run) -> dict:
    """robots/rK.json and paths.png; returns result.json's contents (not yet written)."""
    robot_out = {f"r{k}": robot_result(run, r) for k, r in run.robots.items()}
    steps, n = run.step_no, run.n
    missed = run.missed_world + sum(r.missed for r in run.robots.values())
    checks = max(1, steps * (n + 1))
    stalls = run.stalls.summary() if run.timing else dict(NO_STALLS)
    wall = run.loop_wall_s
    achieved = steps * STEP_S / wall if wall > 0 else 0.0
    try:
        paths_png(run.world, os.path.join(run.out, "paths.png"))
    except Exception as e:  # a picture must not lose the results
        log.warning("paths.png: %s", e)
    result = {
        "format": RESULT_FORMAT,
        "config": {k: run.config[k] for k in RESULT_CONFIG_KEYS},
        "status": run.status,
        "status_detail": run.detail,
        "steps": steps,
        "coverage_final": round(run.world.coverage(), 5),
        "time_scale_requested": run.cfg.time_scale,
        "time_scale_achieved": round(achieved, 3),
        "deadlines_missed": missed,
        "deadline_miss_fraction": round(missed / checks, 5) if steps else 0.0,
        "deadlines_missed_world": run.missed_world,
        # Misses while the host stalled the whole machine (testbed.stalls), and the fraction
        # without them: what a lower time scale could have avoided.
        "host_stalls": stalls,
        "deadline_miss_fraction_outside_stalls": (
            round((missed - stalls["deadlines_missed"]) / checks, 5) if steps else 0.0
        ),
        "wall_time_s": round(run.total_wall_s, 2),
        "step_loop_wall_s": round(wall, 2),
        "wall_parts_s": dict(run.parts),
        "world_priority": run.priority,
        "display": {"robot": n + 1, "coverage_final": display_coverage(run.out, run.world)},
        "world_timing_s": run.timing.seconds() if run.timing else {},
        "world_missed_steps_ms_late": run.timing.missed_steps if run.timing else [],
        "robots": robot_out,
    }
    result["config"]["extra"] = {k: v for k, v in run.config.items() if k not in result["config"]}
    return result


def display_coverage(out: str, world: World) -> float | None:
    """The share of the free space the display's merged map knows (display/map.npy)."""
    try:
        t = np.load(os.path.join(out, "display", "map.npy"))
    except (OSError, ValueError):
        return None
    if t.shape != world.free_space.shape:
        return None
    known = (t == 1) & world.free_space
    return round(float(known.sum()) / world.free_total, 5)


def paths_png(world: World, path: str, scale: int = 2) -> None:
    """The ground truth, what anybody's laser saw, and each robot's path."""
    t = np.zeros(world.truth.shape, dtype=np.uint8)  # unknown where nobody looked
    t[world.seen & ~world.truth.occupied] = 1
    t[world.truth.occupied] = 2
    img = render.map_image(t, scale)
    paths = {k + 1: p[:: max(1, len(p) // 2000)] + p[-1:] for k, p in enumerate(world.paths)}
    render.draw_paths(img, paths, world.truth.cell, scale, thickness=2)
    cv2.imwrite(path, img)
