"""A lone robot's run in one process: its in-process twin, the exact path a run where nothing
is late takes.

Theory of operation. A lone robot's run is deterministic when nothing is late: the world
steps, the robot answers each frame within its step, and its timer and planner finish a
step's work before the next frame is acted on (node.motion `_keep_step_order` holds a frame
until they have). Then the order of everything that decides the path is fixed, and `twin()`
executes it step by step with the world's and the robot's own code, in one thread, with no
clock, no network and no processes:

- the world (testbed.world.world.World, made as testbed.run.prepare makes it) at step 0 casts
  the lasers and sends the frames; then each step (testbed.run.steploop.StepLoop.step) takes
  the robot's command and "done" (they came by the deadline), moves the body, writes the
  positions row, casts, sends the next frame, and ends the run when `steploop.over` says so
  (the robot's `RobotRecord` has its "done": the step after the one it was decided at; or
  the step cap);
- the frame and the command travel through the body link's own encoders and decoder
  (node.body: poses and targets are float32 on the wire, and the robot sees what it sends);
- the robot (a node.robot.Robot, its parts driven directly instead of on their threads) on
  each frame does what motion control does (node.motion `_motion`): puts the scan into its
  map where it moved (`_put_scan_native` or `_put_scan`, as the step core is built), steers
  along the current plan (`_follow`), applies a fresh plan (`_plan_applied`) and answers;
  then its timer's rule for the step (node.timerpart `_timer_rule`, the robot's seeded phase
  in the first period; the coordination's period after) asks for a plan (`request`), and
  after the first frame motion control asks for the first one. A plan asked for at step s is
  computed at once from the map and pose of step s (what node.planning's thread takes under
  the lock before frame s + 1 is acted on) with the planner's own function, and installed as
  node.planning installs it; a plan that finds nothing left sends "done" before that.
  The map floods go to no one and change no path: they are left out, as are the books
  (events, CPU, latencies) that change nothing.

The twin is of the Python robot (the reference); the C++ robot (native/robot) calls the same
step core and is held to the same paths by tests/integration/test_lone_exactness.py.
tests/unit/test_lone_twin.py holds the twin to those runs' positions.csv (seeds 1-3 at
K = 5), byte for byte.

What it covers: one robot (a team's messages arrive when the network delivers them, which no
twin knows), on the run's map, laser, speed, radius, periods, coordination, start placement,
seed and step cap. Every network option (routing, medium, loss, delay, middleware, maps)
reaches no teammate and so changes no path; the robot program (python, cpp) runs the same
algorithm. Not covered (`not_covered`): --kill and a battery failure (the run stops the
robot), --isolate (a window the twin does not play), and a run that did not end by itself
(crashed, interrupted, failed): its path was cut short.

`check(out, ...)`: a finished run's positions.csv held against its twin, row for row (the
robot's finish and its standing still afterwards included: a "done" that reached the world
late only adds rows where the robot stands where the twin ended), for the fidelity verdict
(testbed.run.fidelity.with_twin). `python -m testbed.run.twin RUN_DIR...` checks finished runs
after the fact (runs written before the check, a sweep's lone runs), one line each.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import os
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from node import body, coordination, planner, stepcore
from node.events import EventLog
from node.motion import _grow_box
from node.robot import Robot, RobotConfig
from node.timing import RobotTimings
from testbed.files.csvfiles import POSITIONS_NAME, positions_header
from testbed.files.runconfig import RunConfig
from testbed.run import prepare
from testbed.run.record import RobotRecord
from testbed.run.steploop import over

log = logging.getLogger(__name__)

# The statuses of a run that ended by itself: its robot finished, or the step cap came.
ENDED_BY_ITSELF = ("complete", "step_cap")


@dataclass(frozen=True)
class TwinRun:
    """A lone robot's run computed in-process: its `status` ("complete" or "step_cap"), the
    world's `steps`, the step the robot decided it was done at (`finish_step`), and
    positions.csv's rows (`rows`: the header, then step, x1, y1 of steps 0..steps, as the run
    writes them)."""

    status: str
    steps: int
    finish_step: int | None
    rows: tuple[tuple[str, ...], ...]
    wall_s: float

    def csv_text(self) -> str:
        """positions.csv as the run writes it (csv's \\r\\n line ends)."""
        buf = io.StringIO(newline="")
        csv.writer(buf).writerows(self.rows)
        return buf.getvalue()


def not_covered(cfg: RunConfig, status: str = "complete") -> str | None:
    """Why the twin does not cover a run of `cfg` that ended with `status` (one line), or
    None when it does."""
    if cfg.robots != 1:
        return (f"a team of {cfg.robots}: the teammates' messages arrive when the network "
                "delivers them, which no in-process twin knows")  # fmt: skip
    if cfg.kill:
        return "--kill stops the robot"
    if cfg.battery_failure != "none":
        return "a battery failure stops the robot"
    if cfg.isolate:
        return "--isolate's windows are not played by the twin"
    if status not in ENDED_BY_ITSELF:
        return f"the run ended {status}, not by itself"
    return None


class _Lone:
    """The lone robot's parts, driven in a run's order (see the module docstring)."""

    def __init__(self, cfg: RunConfig, shape: tuple[int, int], cell: float, phase: int):
        rc = RobotConfig(
            robot=1, robots=1, shape=shape, cell=cell, laser_range=cfg.laser_range,
            laser_rays=cfg.laser_rays, speed=cfg.speed, radius=cfg.radius,
            plan_period=cfg.plan_period, map_period=cfg.map_period,
            timing=RobotTimings(time_scale=cfg.time_scale, map_period=cfg.map_period),
            phase=max(0, phase), coordination=cfg.coordination,
        )  # fmt: skip
        # No body link, flooder or messenger: nothing driven here sends through them.
        self.r = Robot(rc, cast(body.BodyClient, None), cast(Any, None), cast(Any, None),
                       EventLog(None))  # fmt: skip
        for fd in (self.r.wake_r, self.r.wake_w):  # stop()'s wake-up pipe: no thread to wake
            os.close(fd)
        self.fallback = coordination.allows_fallback(cfg.coordination)
        self.last_xy: tuple[float, float] | None = None
        self.started = False
        self.done: int | None = None  # the step of the "done" sent, not yet taken by the world

    def frame(self, data: bytes) -> bytes:
        """Frame `data` in, its command out: motion control, then the step's timer rule and
        the plan it asks for (node.motion `_motion`, nothing behind it, nothing late)."""
        msg = body.parse(data)
        f: body.Frame = msg[1]
        r, s = self.r, self.r.s
        moved = (f.x, f.y) != self.last_xy
        self.last_xy = (f.x, f.y)
        with r.lock:
            if moved:
                if stepcore.NATIVE:
                    r._put_scan_native(f)
                else:
                    r._put_scan(f, *r.laser.scan_window(f.x, f.y, f.ranges))
                s.dirty = _grow_box(s.dirty, r._footprint(f.x, f.y))
            s.pose = (f.x, f.y)
            s.step = f.step
            target = r._follow(moved)
            if s.plan_fresh is not None:
                r._plan_applied(f.step)
        answer = body.cmd(f.step, target)
        with r.lock:  # node.timerpart `_tick`: the timer's rule for this step
            work = r._timer_rule(f.step)
        if work is not None and work.plan and work.due_step is not None:
            self._ask("timer")
        if not self.started:
            self.started = True
            self._ask("start")
        return answer

    def _ask(self, cause: str) -> None:
        """A plan asked for (RobotCore.request), computed and installed before the next
        frame, as node.planning `_planning` does it (a lone robot avoids no teammate's goal)."""
        r = self.r
        r.request(cause)
        if r.requests.empty():
            return  # not asked: finished, or a plan already pending
        r.requests.get_nowait()
        s = r.s
        with r.lock:
            t, pose, step = s.grid.ternary(), s.pose, s.step
        p = planner.plan(t, pose, [], r.cfg.laser_range, r.params, fallback=self.fallback)
        if p.status == "done":
            self.done = step  # body.done(step), sent before the plan is installed
        with r.lock:
            s.plan, s.wp = p, 0
            s.plan_fresh = s.plan_asked
            s.plan_fresh_waited = s.plan_asked_while_sending
            s.last_plan_step = step
            s.plan_pending = False
            if p.status == "done":
                s.finished = True


def twin(
    cfg: RunConfig,
    starts: list[tuple[float, float]] | None = None,
    phases: tuple[int, ...] | None = None,
) -> TwinRun:
    """The in-process twin of a lone robot's run of `cfg` (`not_covered(cfg)` must be None):
    its start and timer phase those `cfg.seed` gives, unless `starts` and `phases` (a run's
    config.json has them) say otherwise."""
    why = not_covered(cfg)
    if why:
        raise ValueError(f"no twin: {why}")
    t0 = time.perf_counter()
    truth = prepare.ground_truth(cfg)
    if starts is None or phases is None:
        starts, phases = prepare.seeded_placement(cfg, truth)
    world = prepare.make_world(cfg, truth, starts)
    robot = _Lone(cfg, truth.shape, truth.cell, phases[0])
    record = RobotRecord(1)
    live = np.ones(1, dtype=bool)
    rows: list[tuple[str, ...]] = [tuple(positions_header(1))]

    def positions(step: int) -> None:  # testbed.run.files.RunFiles.positions
        rows.append((str(step), *(f"{v:.3f}" for p in world.positions() for v in p)))

    def frame(step: int) -> bytes:  # BodyServer.send_frames, the reference
        x, y, theta = world.frame_xyt[0].tolist()
        ranges = world.frame_ranges[0] if world.frame_has[0] == 1 else None
        if ranges is None:
            ranges = np.full(world.frame_ranges.shape[1], np.inf, np.float32)
        return body.frame(step, x, y, theta, ranges)

    world.cast_live(live)  # StepLoop.__init__
    positions(0)
    answer = robot.frame(frame(0))
    step, ended = 0, None
    while ended is None:
        _, _, target = body.parse(answer)  # StepLoop._collect_commands
        record.answered(step)
        world.command(0, target)
        if robot.done is not None:
            record.finished(step, robot.done)
            robot.done = None
        world.move()
        step += 1
        positions(step)
        world.cast_live(live)
        answer = robot.frame(frame(step))
        ended = over([record], step, cfg.max_steps)
    return TwinRun(ended[0], step, record.finish_step, tuple(rows),
                   round(time.perf_counter() - t0, 3))  # fmt: skip


def run_config(config: Mapping[str, Any], out: str | None = None) -> RunConfig:
    """The RunConfig of a run's config.json (its options; what preparing found is left out);
    with `out`, --map is the run's own copy of the PNG (out/map.png)."""
    names = {f.name for f in dataclasses.fields(RunConfig)}
    cfg = RunConfig.from_dict({k: v for k, v in config.items() if k in names})
    if cfg.map and out is not None and os.path.exists(os.path.join(out, "map.png")):
        cfg = dataclasses.replace(cfg, map=os.path.join(out, "map.png"))
    return cfg


def differences(run_rows: Iterable[list[str]], twin_rows: tuple[tuple[str, ...], ...]
                ) -> tuple[int | None, int]:  # fmt: skip
    """Where a run's positions.csv rows (`run_rows`, the header first) differ from its twin's:
    the first step that differs (None: none does) and how many steps differ. Rows the run
    has past the twin's last step are the same while the robot stands where the twin ended
    (a "done" that reached the world late: the world ran on, the robot stood still); a step
    the run lacks (it ended before its twin) differs. A header that is not the twin's is a
    difference at step 0."""
    last, n, first, count = twin_rows[-1], 0, None, 0
    for i, row in enumerate(run_rows):
        n = i + 1
        if i < len(twin_rows):
            same = tuple(row) == twin_rows[i]
        else:
            same = tuple(row[1:]) == last[1:] and row[0] == str(i - 1)
        if not same:
            count += 1
            if first is None:
                first = max(0, i - 1)  # row i is step i - 1 (the header is row 0)
    if n < len(twin_rows):
        count += len(twin_rows) - n
        if first is None:
            first = max(0, n - 1)
    return first, count


def check(out: str, config: Mapping[str, Any], status: str) -> dict | str:
    """result.json's `fidelity.twin` for the run in `out` (its config.json's contents
    `config`, its `status`): "not applicable: <why>", or {ok, steps (the twin's), wall_s,
    and, when not ok, differs_from_step and steps_differing}."""
    try:
        cfg = run_config(config, out)
    except (TypeError, ValueError) as e:
        return f"not applicable: its config.json does not make a run ({e})"
    why = not_covered(cfg, status)
    if why:
        return f"not applicable: {why}"
    path = os.path.join(out, POSITIONS_NAME)
    if not os.path.isfile(path):
        return f"not applicable: the run wrote no {POSITIONS_NAME}"
    starts = [tuple(p) for p in config.get("starts") or []] or None
    phases = tuple(config.get("timer_phases") or ()) or None
    try:
        t = twin(cfg, cast(Any, starts), phases)
        with open(path, newline="") as f:
            at, count = differences(csv.reader(f), t.rows)
    except (OSError, ValueError) as e:
        log.warning("the run's twin: %s", e)
        return f"not applicable: the twin could not be made ({e})"
    result: dict[str, Any] = {"ok": at is None, "steps": t.steps, "wall_s": t.wall_s}
    if at is not None:
        result.update(differs_from_step=at, steps_differing=count)
    return result


def main(argv: list[str]) -> int:
    """`python -m testbed.run.twin RUN_DIR...`: each finished run held against its twin
    (one line each: its fidelity.twin as the results would record it); 1 when a path differs."""
    from common.boundedfile import Refused
    from testbed.files import configfile
    from testbed.files.resultfile import RunResult

    differs = False
    for out in argv:
        result = RunResult.read(out)
        try:
            config = configfile.read(configfile.config_path(out)).to_dict()
        except (Refused, ValueError) as e:
            config = None
            outcome: dict | str = f"not applicable: config.json: {e}"
        if result is None:
            outcome = "not applicable: no readable result.json"
        elif config is not None:
            outcome = check(out, config, result.status)
        differs = differs or (isinstance(outcome, dict) and not outcome["ok"])
        print(f"{out}: {json.dumps(outcome)}")
    return 1 if differs else 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
