"""The steps of a started run (testbed.run.execute starts and finishes it).

Theory of operation. `StepLoop.run()` sends step 0's frames and steps until the run is over.
Each step is one tick of the clock (testbed.run.stepclock): it sleeps to the step's deadline
and takes the robots' commands that arrived by then, moves each robot toward the target its
process last commanded, feeds all positions to the topology controller (links follow before
the step goes on: --isolate's windows first), stops the robots --kill names, notices the ones
that died, casts the lasers and sends each robot its frame (step, pose, scan) and the
display its clock. `over` says when the run is over and with what status; `final_status`
names the first crash. What changes during a run lives in the clock, the robots' records,
the timing counters and the files, each a class of its own module. The display is sent only
the frames of the steps it acts on (node.displaysteps) and the last step's.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import time
from typing import TYPE_CHECKING

import numpy as np

from node import body
from testbed.run import isolation
from testbed.run.progress import ProgressLine
from testbed.run.record import RobotRecord
from testbed.run.stepclock import StepClock, StepTiming

if TYPE_CHECKING:
    from testbed.run.execute import Started
    from testbed.run.prepare import PreparedRun

log = logging.getLogger(__name__)

WARMUP_STEPS = 3  # the first steps wait for every robot's answer (see _collect_commands)
WARMUP_WAIT_S = 5.0  # at most this long a step: a robot that is not up by then misses it
WAIT_POLL_S = 0.0002


class StepLoop:
    """The steps of a started run: `run()` sends step 0's frames and steps until the end."""

    def __init__(self, prep: PreparedRun, started: Started, robots: dict[int, RobotRecord],
                 progress: bool) -> None:  # fmt: skip
        self.prep = prep
        self.world = prep.world
        self.net, self.server, self.files = started.net, started.server, started.files
        self.live = started.live
        self.robots = robots
        self.n = len(robots)
        kills: dict[int, list[int]] = {}
        for k, s in prep.cfg.kills:
            kills.setdefault(s, []).append(k)
        self.kills = kills
        self.timing = StepTiming()
        self.progress = ProgressLine(progress, prep.cfg.max_steps, self.n)
        self.positions: list = []  # the robots' positions at the last step
        # Robot k's process is in the run (not crashed, not stopped) where live_robots[k - 1].
        self.live_robots = np.array([not robots[k].gone for k in range(1, self.n + 1)], bool)
        self.world.cast_live(self.live_robots)
        self.cpu0 = time.process_time()
        self.clock = StepClock(prep.cfg.time_scale, self.n, time.monotonic())
        self.display_steps = prep.display_steps

    def run(self) -> tuple[str, str]:
        """Step 0 (the first frames go out), then every step until the run is over;
        returns its (status, detail)."""
        self.files.coverage(0, self.world.coverage())
        self.files.positions(0, self.world.positions())
        self._send_frames()
        status = None
        while status is None:
            status = self.step()
        if not self.display_steps.wanted(self.clock.step):  # its final snapshot is named after it
            self._send_display_frame(time.monotonic())
        self.clock.stop(time.monotonic())
        self.timing.world_cpu_s = time.process_time() - self.cpu0
        self.progress.end()
        return final_status(status, list(self.robots.values()))

    def step(self) -> tuple[str, str] | None:
        """One step of the clock; the run's (status, detail) when it is over, else None."""
        self._collect_commands()
        clock, t, world = self.clock, self.timing, self.world
        step = clock.advance()
        tw = time.monotonic()
        world.move()
        self._update_links(step)
        self._inject_kills(step)
        self._notice_crashes(step)
        ts = time.monotonic()
        world.cast_live(self.live_robots)
        cov = world.coverage()
        self.files.coverage(step, cov)
        if self.live is not None:
            achieved = round(clock.achieved_scale(time.monotonic()), 2)
            self.live.feed.publish(step, self.positions, self.net.current, cov,
                                   clock.missed_robots, achieved)  # fmt: skip
        tf = time.monotonic()
        t.scan_s += tf - ts
        self._send_frames()
        t.send_s += time.monotonic() - tf
        t.world_s += time.monotonic() - tw
        clock.world_done(time.monotonic())
        self._show_progress(cov)
        return self._over()

    def _collect_commands(self) -> None:
        """Sleep until the step's deadline, then take every command that arrived by then
        and count who had not answered the step's frame. The commands wait in their
        sockets meanwhile: nothing is done with one before the deadline, and waking for
        each (once per robot per step) cost the world more than its own step. In the first
        WARMUP_STEPS steps the world waits for every live robot's answer (up to
        WARMUP_WAIT_S), and the schedule moves by the wait: a robot's first frames and
        first plan run cold (its pages, its caches), and at time scale 100 a step is 1 ms."""
        clock = self.clock
        step = clock.step
        left = clock.deadline() - time.monotonic()
        if left > 0:
            time.sleep(left)
        grace = clock.woke(time.monotonic())
        if grace > 0:  # a host stall stopped the robots too: their time is given back
            time.sleep(grace)
        self._take_commands(step)
        if step < WARMUP_STEPS:
            clock.warmed_up(self._wait_for_answers(step, WARMUP_WAIT_S))
        for r in self.robots.values():
            if r.missed_deadline(step):
                clock.robots_missed(1)

    def _take_commands(self, step: int) -> None:
        for k, msg in self.server.take(self.n):
            if not 1 <= k <= self.n:
                continue
            r = self.robots[k]
            if msg[0] == "cmd":
                r.answered(msg[1])
                self.world.command(k - 1, msg[2])
            elif msg[0] == "done":
                r.finished(step, msg[1])

    def _wait_for_answers(self, step: int, limit_s: float) -> float:
        """Take commands until every live robot answered `step`'s frame (or `limit_s`
        passed); returns the seconds waited."""
        t0 = time.monotonic()
        waited = 0.0
        while waited < limit_s and any(
            not r.gone and r.finish_step is None and r.last_cmd < step for r in self.robots.values()
        ):
            time.sleep(WAIT_POLL_S)
            self._take_commands(step)
            waited = time.monotonic() - t0
        return waited

    def _update_links(self, step: int) -> None:
        """The new positions to the topology controller; links.csv gets what changed."""
        tn = time.monotonic()
        self._isolate(step)
        positions = self.world.positions()
        self.positions[:] = positions
        added, removed = self.net.set_positions(positions + [self.prep.display_pos])
        spent = time.monotonic() - tn
        self.timing.net_s += spent
        self.timing.net_max_s = max(self.timing.net_max_s, spent)
        self.files.links(step, added, removed)
        self.files.positions(step, positions)

    def _isolate(self, step: int) -> None:
        """--isolate: the robots whose radio is out at this step, to the topology controller
        (links off, or back as the positions want) when that changed; events.jsonl says so."""
        if not self.prep.cfg.isolate and not self.net.isolated:
            return  # most runs: no window, nobody out
        out = isolation.isolated_at(self.prep.cfg.isolate, step)
        was = self.net.isolated
        if out == was:
            return
        added, removed = self.net.set_isolated(out)
        self.files.links(step, added, removed)
        for k in sorted(out - was):
            self.files.event(step, "isolated", k)
            log.info("r%d out of everyone's radio range at step %d", k, step)
        for k in sorted(was - out):
            self.files.event(step, "back_in_range", k)

    def _inject_kills(self, step: int) -> None:
        """--kill: the robot's process is SIGKILLed and it is stopped (not crashed) from now on;
        its body stays where it is."""
        for k in self.kills.get(step, []):
            r = self.robots[k]
            if r.gone:  # it died unasked before: a crash, as recorded
                continue
            with contextlib.suppress(ProcessLookupError):
                os.kill(r.process.pid, signal.SIGKILL)
            r.stop(step)
            self.live_robots[k - 1] = False
            self.world.bodies[k - 1].alive = False
            self.files.event(step, "stopped", k)
            log.info("r%d stopped at step %d (--kill)", k, step)

    def _notice_crashes(self, step: int) -> None:
        """The robots whose process exited since the last step: one look at the fork
        server's exit reports a step (as Forked.poll would take for each robot), then each
        robot's exit status."""
        live = [(k, r) for k, r in self.robots.items() if not r.gone]
        for server in {r.process.server for _, r in live}:
            server.collect(0.0)
        for k, r in live:
            if r.process.returncode is not None:
                r.died(step, r.process.returncode)
                self.live_robots[k - 1] = False
                self.world.bodies[k - 1].alive = False
                log.warning("r%d exited with status %s at step %d", k, r.exit_status, step)

    def _send_frames(self) -> None:
        now = time.monotonic()
        self.files.frames_out(now)
        step, w = self.clock.step, self.world
        self.server.send_frames(step, now, w.frame_xyt, w.frame_ranges, w.frame_has,
                                self.live_robots)  # fmt: skip
        if self.display_steps.wanted(step):
            self._send_display_frame(now)

    def _send_display_frame(self, now: float) -> None:
        """The display's frame of this step (only the steps it acts on: node.displaysteps)."""
        step = self.clock.step
        x, y = self.prep.display_pos
        self.server.send(self.prep.display_k, body.frame(step, x, y, 0.0, None, now), True)

    def _show_progress(self, coverage: float) -> None:
        now = time.monotonic()
        if not self.progress.due(now):
            return
        live = [r for r in self.robots.values() if not r.gone]
        done = sum(1 for r in live if r.finish_step is not None)
        clock = self.clock
        self.progress.show(now, clock.step, coverage, done, self.n - len(live),
                           clock.achieved_scale(now), clock.summary().deadlines_missed)  # fmt: skip

    def _over(self) -> tuple[str, str] | None:
        return over(list(self.robots.values()), self.clock.step, self.prep.cfg.max_steps)


def over(robots: list[RobotRecord], step: int, max_steps: int) -> tuple[str, str] | None:
    """The run's (status, detail) if it is over at `step`, else None: `complete` when every
    robot still in it finished (a stopped robot is not waited for), `stopped` when every
    robot was stopped on purpose, `robot_crashed` when none is left and one crashed, the
    step cap."""
    live = [r for r in robots if not r.gone]
    stopped = [r for r in robots if r.stopped_step is not None]
    finished = [r.finish_step for r in live if r.finish_step is not None]
    if live and len(finished) == len(live):
        last = max(finished)
        if not stopped:
            return "complete", f"all robots finished by step {last}"
        return "complete", f"the robots not stopped finished by step {last}; " + ", ".join(
            f"r{r.k} stopped at step {r.stopped_step}" for r in stopped
        )
    if not live:
        if len(stopped) == len(robots):
            return "stopped", "every robot was stopped (--kill)"
        return "robot_crashed", "every robot process died"
    if step >= max_steps:
        return "step_cap", f"the step cap ({max_steps}) was reached"
    return None


def final_status(status: tuple[str, str], robots: list[RobotRecord]) -> tuple[str, str]:
    """The status of a loop that ended, with the first crash named when a robot died unasked
    (a robot stopped on purpose is no crash)."""
    crashed = [r for r in robots if r.crashed]
    if not crashed:
        return status
    r = crashed[0]
    what = f"r{r.k} exited with status {r.exit_status} at step {r.crash_step}"
    if status[0] == "robot_crashed":
        return "robot_crashed", what + "; all died"
    return "robot_crashed", what + (f"; {len(crashed) - 1} more" if len(crashed) > 1 else "")
