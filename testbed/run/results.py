"""What a finished run writes about itself: robots/rK.json, paths.png and its RunResult.

`write(record)` reads what the robot processes logged (robots/rK.events.jsonl) and the
run's frozen record (testbed.run.record: what the world and its clock saw), writes each
robot's detailed record and the picture of the paths, and, last and atomically, result.json
from a `RunResult` (testbed.files.resultfile, the file's one type; docs/run-results.md says what
every key means). A picture that cannot be drawn is logged, never a reason to lose the
results.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from typing import TYPE_CHECKING

import cv2
import numpy as np

from aodv.statsfile import DaemonStats, StatsError, run_stats_path
from node import events, render, stepcore
from testbed.files import isolation, layout, mediumfile, robotfile
from testbed.files.resultfile import HostStalls, Plan, RobotResult, RunResult
from testbed.run import fidelity, twin
from testbed.world.world import World
from topology.kernel import neightable

if TYPE_CHECKING:
    from testbed.run.record import RobotOutcome, RunRecord

log = logging.getLogger(__name__)

# What each robot's summary line (its last event) says, copied into robots/rK.json.
SUMMARY_KEYS = (
    "send_failed", "flood", "frames_skipped", "plan_ms_median", "cpu_s", "max_rss_mb", "busy_s",
    "frames", "latency_ms", "thread_cpu_s", "lateness", "middleware", "messenger", "arrivals",
    "maps", "priority", "malformed", "events_failed",
)  # fmt: skip
# The team's messaging totals (result.json's "messaging"): these are summed over the robots,
# the others are the largest of any robot.
MESSAGING_SUMS = (
    "sent", "failed", "received", "blocked_s", "sending", "messages", "duplicates", "late",
)  # fmt: skip
MESSAGING_MAX = ("blocked_max_s", "delay_steps_max")
# The team's map sharing totals (result.json's "maps"), likewise.
MAPS_SUMS = ("published", "failed", "bytes_published", "received", "bytes_received", "blocked_s")
MAPS_MAX = ("blocked_max_s",)
PLAN_DETAIL_KEYS = ("step", "cause", "status", "goal", "cost", "ms")


def robot_result(rec: RunRecord, r: RobotOutcome) -> tuple[RobotResult, dict]:
    """Robot r's entry in result.json, and its summary event ({} when it left none: its
    lateness, node.lateness, and CPU); its fuller record goes to robots/rK.json."""
    ev = events.read(layout.robot_events(rec.out, r.k))
    plans = tuple(Plan(e.step, e.fields["cause"]) for e in ev if e.e == "plan")
    sent: dict[str, int] = {}
    received: dict[str, int] = {}
    for e in ev:
        if e.e == "send":
            sent[e.fields["kind"]] = sent.get(e.fields["kind"], 0) + 1
        elif e.e == "recv":
            received[e.fields["kind"]] = received.get(e.fields["kind"], 0) + 1
    summary: dict = next((e.to_dict() for e in reversed(ev) if e.e == "summary"), {})
    b = rec.world.bodies[r.k - 1]
    out = RobotResult(
        name=f"r{r.k}", finish_step=r.finish_step, crashed=r.crashed, plans=plans, sent=sent,
        received=received, path_length_m=round(b.path_length, 3), stopped_step=r.stopped_step,
        exit_status=r.exit_status,
    )  # fmt: skip
    detail = out.to_dict()
    detail.update(
        crash_step=r.crash_step, done_late_steps=r.done_late, deadlines_missed=r.missed,
        deadlines_missed_steps=list(r.missed_steps),
        collisions=b.collisions, final_pose=[round(b.x, 3), round(b.y, 3)],
        plan_details=[{k: e.get(k) for k in PLAN_DETAIL_KEYS} for e in ev if e.e == "plan"],
    )  # fmt: skip
    detail.update({k: summary.get(k) for k in SUMMARY_KEYS})
    robotfile.write(rec.out, r.k, detail)
    return out, summary


def write(rec: RunRecord) -> RunResult:
    """robots/rK.json, paths.png and, last, result.json; returns what result.json holds."""
    t0 = time.monotonic()
    result = contents(rec)
    parts = dict(result.wall_parts_s, results=round(time.monotonic() - t0, 3))
    result = dataclasses.replace(result, wall_parts_s=parts)
    result.write(rec.out)
    return result


def contents(rec: RunRecord) -> RunResult:
    """robots/rK.json and paths.png; returns the run's result (not yet written)."""
    robots = [robot_result(rec, r) for r in rec.robots]
    clock = rec.clock
    try:
        paths_png(rec.world, os.path.join(rec.out, "paths.png"))
    except Exception as e:  # a picture must not lose the results
        log.warning("paths.png: %s", e)
    mean_finish = rec.mean_finish_step
    summaries = [sm for _, sm in robots]
    display = display_summary(rec.out)
    daemons = daemon_stats(rec.out, len(rec.robots) + 1)
    verdict = fidelity.verdict(
        fidelity.measures(
            clock.miss_fraction_outside_stalls if clock.steps else None,
            [sm.get("lateness") for sm in summaries],
            display.get("lateness"),
            [d.timer_lateness_ms for d in daemons],
            channel_relay_lag(rec.out),
            clock.stepping,
            [r.done_late for r in rec.robots],
        )
    )
    # A lone robot's path against its in-process twin (testbed.run.twin): a changed path is
    # not faithful, however few steps were late.
    verdict = fidelity.with_twin(verdict, twin.check(rec.out, rec.config.to_dict(), rec.status))
    # Sends the kernel dropped for want of a neighbour entry (topology.kernel.neightable).
    verdict = fidelity.with_neighbour_table(verdict, rec.neighbour_table_fulls, neightable.limit())
    # Whether TCP kept emulated time, from the robots' network timers (topology.kernel.nettimers).
    verdict["network"] = fidelity.network_verdict(rec.network_timers, rec.time_scale)
    config = rec.config.result_config()
    return RunResult(
        config=config,
        status=rec.status,
        status_detail=rec.detail,
        steps=clock.steps,
        last_finish_step=rec.last_finish_step,
        mean_finish_step=None if mean_finish is None else round(mean_finish, 2),
        mean_finish_step_robots=len(rec.counted_robots),
        survivors_finished=rec.survivors_finished,
        isolated=tuple(isolation.record(rec.outages, clock.steps)),
        coverage_final=round(rec.world.coverage(), 5),
        time_scale_requested=rec.time_scale,
        time_scale_achieved=round(clock.time_scale_achieved, 3),
        deadlines_missed=clock.deadlines_missed,
        deadline_miss_fraction=clock.miss_fraction,
        deadlines_missed_world=clock.missed_world,
        # Misses while the host stalled the whole machine (testbed.run.stalls), and the fraction
        # without them: what a lower time scale could have avoided.
        host_stalls=HostStalls(**clock.stalls),
        deadline_miss_fraction_outside_stalls=clock.miss_fraction_outside_stalls,
        wall_time_s=round(time.monotonic() - rec.t_start, 2),
        step_loop_wall_s=round(clock.loop_wall_s, 2),
        wall_parts_s=dict(rec.parts),
        world_priority=rec.priority,
        step_core=stepcore.kind(),
        step_loop=rec.world_timing.get("step_loop"),  # testbed.run.steploop.loop_kind
        robot=rec.robot,
        robot_reason=rec.robot_reason,
        aodv_daemon=rec.aodv_daemon,
        aodv_daemon_reason=rec.aodv_daemon_reason,
        display={
            "robot": len(rec.robots) + 1,
            "coverage_final": display_coverage(rec.out, rec.world),
            "snapshots": snapshot_steps(rec.out),
        },
        world_timing_s={k: v for k, v in rec.world_timing.items() if k != "step_loop"},
        world_missed_steps_ms_late=tuple(tuple(m) for m in clock.world_missed_steps),
        robots=tuple(r for r, _ in robots),
        cpu_s=cpu_seconds(rec, summaries, display, daemons),
        messaging=messaging(config.middleware, {r.name: sm for r, sm in robots}),
        maps=map_sharing(
            config.maps,
            config.middleware,
            {r.name: sm for r, sm in robots},
            display.get("maps"),
        ),  # fmt: skip
        fidelity=verdict,
        network_timers=rec.network_timers,
    )


def messaging(middleware: str, summaries: dict[str, dict]) -> dict:
    """The goal messages' middleware and what it did: each robot's messenger counters and
    arrivals (node.messaging.stats, node.messaging.arrivals; None for a robot that left no
    summary), and the team's totals over the robots that did."""
    robots: dict[str, dict | None] = {}
    for k, sm in summaries.items():
        if sm.get("messenger") is None:
            robots[k] = None
            continue
        robots[k] = dict(sm["messenger"], **(sm.get("arrivals") or {}))
    counted = [v for v in robots.values() if v is not None]
    team: dict = {"robots": len(counted)}
    for key in MESSAGING_SUMS:
        team[key] = sum(v.get(key) or 0 for v in counted)
    for key in MESSAGING_MAX:
        team[key] = max((v.get(key) or 0 for v in counted), default=0)
    for key in ("blocked_s", "blocked_max_s"):
        team[key] = round(team[key], 6)
    return {"middleware": middleware, "team": team, "robots": robots}


def map_sharing(
    transport: str, middleware: str, summaries: dict[str, dict], display: dict | None
) -> dict:
    """How the robots shared their maps (`--maps`: flood, or pubsub on `middleware`) and what
    that did: each robot's map counters (node.mapstats; None for a robot that left none),
    the team's totals over the robots that did, and the display's counters."""
    robots = {k: sm.get("maps") for k, sm in summaries.items()}
    counted = [v for v in robots.values() if v is not None]
    team: dict = {"robots": len(counted)}
    for key in MAPS_SUMS:
        team[key] = sum(v.get(key) or 0 for v in counted)
    for key in MAPS_MAX:
        team[key] = max((v.get(key) or 0 for v in counted), default=0)
    for key in ("blocked_s", "blocked_max_s"):
        team[key] = round(team[key], 6)
    return {
        "transport": transport,
        "middleware": middleware if transport == "pubsub" else None,
        "team": team,
        "robots": robots,
        "display": display,
    }


def cpu_seconds(
    rec: RunRecord, summaries: list[dict], display: dict, daemons: list[DaemonStats]
) -> dict:
    """CPU seconds of the run's processes (the robots', the display's, the world's step
    loop, the AODV daemons'), and all of it per robot-step in ms: what a cluster's run
    needs per robot (testbed.sweep.slurm)."""
    parts = {
        "robots": sum(sm.get("cpu_s") or 0.0 for sm in summaries),
        "display": display.get("cpu_s") or 0.0,
        "world": rec.world_timing.get("world_cpu_s", 0.0),
        "routing": sum(d.cpu_s or 0.0 for d in daemons),
    }
    out = {k: round(v, 3) for k, v in parts.items()}
    robot_steps = rec.clock.steps * len(rec.robots)
    out["per_robot_step_ms"] = (
        round(sum(parts.values()) / robot_steps * 1000, 3) if robot_steps else None
    )
    return out


def channel_relay_lag(out: str) -> mediumfile.RelayLag | None:
    """The ns3-wifi channel's `relay_lag` counters (medium.json), None without that channel; a
    medium.json that is not what the channel writes is named in a warning and not judged
    (the run's results are written all the same)."""
    try:
        channel = mediumfile.read(out)
    except mediumfile.ResultError as e:
        log.warning("%s: the channel's relay lag not judged", e)
        return None
    return channel.relay_lag if channel is not None else None


def display_summary(out: str) -> dict:
    """The display's summary event ({} when it wrote none)."""
    ev = events.read(layout.display_events(out), only=("summary",))
    return ev[-1].to_dict() if ev else {}


def daemon_stats(out: str, n: int) -> list[DaemonStats]:
    """The AODV daemons' statistics (aodv/rK.json), for those that wrote them (a file that is
    not one is left out, as one that is missing)."""
    found = []
    for k in range(1, n + 1):
        try:
            found.append(DaemonStats.read(run_stats_path(out, k)))
        except StatsError:
            continue
    return found


def snapshot_steps(out: str) -> list[int]:
    """The steps of the display's snapshots that were written (display/step-NNNNN.png)."""
    try:
        names = os.listdir(layout.display_dir(out))
    except OSError:
        return []
    stems = (n.removeprefix("step-").removesuffix(".png") for n in names if n.endswith(".png"))
    return sorted(int(s) for s in stems if s.isdigit())


def display_coverage(out: str, world: World) -> float | None:
    """The share of the free space the display's merged map knows (display/map.npy)."""
    try:
        t = np.load(layout.map_path(out))
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
