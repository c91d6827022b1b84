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

Two loops, one behaviour. The step above is written twice: `_step_python`, the reference,
and `_step_compiled`, which does the same with the per-robot work in compiled code
(testbed.world.stepfast: the deadline's sleep, the commands into the bodies and the records,
the deadline count, the moves) and calls Python only for what is rare or changes: a "done",
a hang-up, a kill, a fork server's exit report, and the run's end (`over` is asked again
only when a robot's state changed or the step cap is reached). The compiled loop takes over
after the warm-up steps (the Python loop's, whose waits are rare by nature) wherever the step
core was built with the world's step; `TESTBED_STEP_LOOP=python` (read by `loop_kind`, the
one place) runs the reference throughout, and result.json's `step_loop` says which ran.
tests/integration/test_step_loop_twin.py holds the two to the same positions.csv.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import time
from typing import TYPE_CHECKING

import numpy as np

from common.errors import UsageError
from node import body
from testbed.files import isolation
from testbed.run.progress import ProgressLine
from testbed.run.record import RobotRecord
from testbed.run.stepclock import StepClock, StepTiming
from testbed.world import stepfast
from topology.spec import VETH

if TYPE_CHECKING:
    from testbed.run.prepare import PreparedRun
    from testbed.run.started import Started

log = logging.getLogger(__name__)

WARMUP_STEPS = 3  # the first steps wait for every robot's answer (see _collect_commands)
WARMUP_WAIT_S = 5.0  # at most this long a step: a robot that is not up by then misses it
WAIT_POLL_S = 0.0002
STEP_LOOP_ENV = "TESTBED_STEP_LOOP"
LOOP_KINDS = ("compiled", "python")  # the first: what unset means


def loop_kind() -> str:
    """The step loop a run runs: "compiled" (the default, where the step core was built with
    the world's step: testbed.world.stepfast) or "python" (the reference; asked for with
    TESTBED_STEP_LOOP=python, or the only one there is). UsageError for a value it does not
    know. The one reading of TESTBED_STEP_LOOP."""
    got = os.environ.get(STEP_LOOP_ENV, "").strip().lower() or LOOP_KINDS[0]
    if got not in LOOP_KINDS:
        shown = os.environ.get(STEP_LOOP_ENV, "")[:40].encode("unicode_escape").decode()
        raise UsageError(f"{STEP_LOOP_ENV}={shown!r} is not one of {', '.join(LOOP_KINDS)}")
    return got if stepfast.AVAILABLE else "python"


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
        self.kind = loop_kind()
        self.timing.loop = self.kind
        # The compiled steps' state (after the warm-up): it holds the records' answered steps
        # and misses from the first compiled step until the loop ends.
        self.fast = (
            stepfast.WorldStep(self.world, self.live_robots) if self.kind == "compiled" else None
        )

    def run(self) -> tuple[str, str]:
        """Step 0 (the first frames go out), then every step until the run is over;
        returns its (status, detail)."""
        self.files.coverage(0, self.world.coverage())
        self.files.positions(0, self.world.positions())
        self._send_frames()
        status = None
        try:
            while status is None:
                status = self.step()
        finally:
            if self.fast is not None and self.fast.records_held:
                self.fast.store_records(self.robots)
        if not self.display_steps.wanted(self.clock.step):  # its final snapshot is named after it
            self._send_display_frame(time.monotonic())
        self.clock.stop(time.monotonic())
        self.timing.world_cpu_s = time.process_time() - self.cpu0
        self.progress.end()
        return final_status(status, list(self.robots.values()))

    def step(self) -> tuple[str, str] | None:
        """One step of the clock; the run's (status, detail) when it is over, else None."""
        if self.fast is not None and self.clock.step >= WARMUP_STEPS:
            return self._step_compiled()
        return self._step_python()

    def _step_python(self) -> tuple[str, str] | None:
        """`step`, the reference."""
        self._collect_commands()
        step = self.clock.advance()
        tw = time.monotonic()
        self.world.move()
        self._update_links(step)
        self._inject_kills(step)
        self._notice_crashes(step)
        self._cast_and_send(step, tw)
        return self._over()

    def _step_compiled(self) -> tuple[str, str] | None:
        """`step` with the per-robot work compiled (see the module's docstring)."""
        fast, clock, world, server = self.fast, self.clock, self.world, self.server
        assert fast is not None
        if not fast.records_held:
            self._start_compiled()
        step = clock.step
        deadline = clock.deadline()
        now = fast.sleep_until(deadline)
        while now < deadline:  # a signal ended the sleep (its Python handler has run)
            now = fast.sleep_until(deadline)
        grace = clock.woke(now)
        if grace > 0:  # a host stall stopped the robots too: their time is given back
            time.sleep(grace)
        socks = server.step_sockets(self.n)
        fast.sockets(socks)
        used, hung, missed, spoke = fast.take(step, True)
        if used or hung:
            self._fast_messages(step, server.taken_rest(socks, used, hung))
        if missed:
            clock.robots_missed(missed)
        step = clock.advance()
        tw = time.monotonic()
        if not fast.move():  # a position not finite, or the log full: World.move's own path
            world.move()
        if fast.links_due() or self.prep.cfg.isolate or self.net.isolated:
            self._update_links(step)
            fast.links_taken()
        else:  # no link can have come or gone: the controller would say so (stepfast)
            positions = world.positions()
            self.positions[:] = positions
            self.files.positions(step, positions)
        if step in self.kills:
            self._inject_kills(step)
            self._watch_servers()
        if spoke or fast.crash_pending:
            fast.crash_pending = False
            self._notice_crashes(step)
            self._watch_servers()
        self._cast_and_send(step, tw)
        if fast.changed or step >= self.prep.cfg.max_steps:
            fast.changed = False
            return self._over()
        return None  # no robot changed since `over` said None, and the cap is not reached

    def _cast_and_send(self, step: int, tw: float) -> None:
        """Both loops' end of a step (its world work began at `tw`): the lasers cast, the
        coverage written (and fed to the live view), every robot's frame sent."""
        clock, t, world = self.clock, self.timing, self.world
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

    def _start_compiled(self) -> None:
        """The first compiled step: the records' state into the arrays, the fork servers to
        watch. The Python steps before took in every report the servers had sent (each
        `_notice_crashes` reads until nothing waits), so only a new one makes a watched
        descriptor readable; one already read and not yet noticed is noticed at the step."""
        assert self.fast is not None
        self._watch_servers()
        live = [r for r in self.robots.values() if not r.gone]
        servers = {r.process.server for r in live}
        self.fast.crash_pending = any(r.process.returncode is not None for r in live) or any(
            b"\n" in getattr(server, "buf", b"") for server in servers
        )
        self.fast.load_records(self.robots)
        spec = self.net.spec
        # topology.radio.slack.Slack.applies: links follow the positions alone.
        if spec.range_model == "disc" and spec.medium == VETH and not self.net.persistent:
            self.fast.links_follow_positions(spec.comm_range, self.prep.display_pos)

    def _watch_servers(self) -> None:
        """The compiled step watches the fork servers of the robots still in the run."""
        assert self.fast is not None
        live = [r for r in self.robots.values() if not r.gone]
        self.fast.watch(sorted({r.process.server.ctl.fileno() for r in live}))
        self.fast.changed = True

    def _fast_messages(self, step: int, msgs: list[tuple[int, tuple]]) -> None:
        """`_take_commands` for what the compiled take left to Python (a command among them
        goes to the arrays the compiled steps keep)."""
        assert self.fast is not None
        for k, msg in msgs:
            if not 1 <= k <= self.n:
                continue
            if msg[0] == "cmd":
                self.fast.last_cmd[k - 1] = max(int(self.fast.last_cmd[k - 1]), msg[1])
                self.world.command(k - 1, msg[2])
            elif msg[0] == "done":
                self.robots[k].finished(step, msg[1])
                self.fast.changed = True

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
