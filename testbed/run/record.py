"""What a run knows of itself: robots' records while it goes, the frozen record at its end.

Theory of operation. While the step loop runs, each robot's process has a `RobotRecord` the
loop updates (its last answered step, when it finished, whether it crashed or was stopped,
its missed deadlines). A robot is *stopped* when the run itself killed it (`--kill`, a
battery failure on purpose) and *crashed* when its process died unasked; either way it is
gone for the rest of the run, but only a crash is a failure of the run, and a stopped
robot's exploration is cut short on purpose, so the averages over robots leave it out.
When the run ends, `Run.execute` (testbed.run.execute) freezes everything the results
need into a `RunRecord`: the configuration, the status, the world, each robot's
`RobotOutcome`, the clock's summary (testbed.run.stepclock) and the wall time of each stage.
testbed.run.results writes result.json and the per-robot files from that record alone.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from testbed.files.resultfile import MAX_MISSED_STEPS_KEPT
from testbed.run.stepclock import ClockSummary
from testbed.world.world import World

if TYPE_CHECKING:
    from testbed.files.configfile import RunConfigFile
    from topology.kernel.forkserver import Forked


@dataclass
class RobotRecord:
    """What the world knows of one robot's process during the run."""

    k: int
    proc: Forked | None = None  # from the run's fork server, once spawned
    last_cmd: int = -1  # the latest step whose frame it answered
    finish_step: int | None = None
    done_late: int = 0  # steps its "done" reached the world after the step it was decided at
    crashed: bool = False
    crash_step: int | None = None
    exit_status: int | None = None
    missed: int = 0
    missed_steps: list = field(default_factory=list)
    stopped_step: int | None = None  # the step the run killed it at (--kill)

    @property
    def process(self) -> Forked:
        """Its process (the run spawns every robot's before it steps)."""
        assert self.proc is not None
        return self.proc

    @property
    def gone(self) -> bool:
        """Whether its process is out of the run: crashed, or stopped on purpose."""
        return self.crashed or self.stopped_step is not None

    def answered(self, step: int) -> None:
        self.last_cmd = max(self.last_cmd, step)

    def finished(self, step: int, decided: int | None = None) -> None:
        """The robot said it is done, having decided it at step `decided` (its message's;
        None: at `step`), while the world's last step was `step`. Its finish is the step it
        decided at; a "done" that came after that step's deadline is counted in `done_late`
        (the run went on that many steps longer: the fidelity verdict's measures count it). A step
        past the world's is no step it could have decided at: the world's is taken."""
        if self.finish_step is not None:
            return
        if decided is None or decided > step:
            decided = step
        self.finish_step = decided
        self.done_late = step - decided

    def missed_deadline(self, step: int) -> bool:
        """Whether a live robot had not answered `step`'s frame by the deadline (counted)."""
        if self.gone or self.last_cmd >= step:
            return False
        self.missed += 1
        if len(self.missed_steps) < MAX_MISSED_STEPS_KEPT:
            self.missed_steps.append(step)
        return True

    def died(self, step: int, status: int | None) -> None:
        """Its process died unasked (noticed at `step`)."""
        self.crashed, self.crash_step, self.exit_status = True, step, status

    def stop(self, step: int) -> None:
        """The run killed it at `step` on purpose (--kill)."""
        self.stopped_step = step

    def outcome(self) -> RobotOutcome:
        return RobotOutcome(
            k=self.k, finish_step=self.finish_step, crashed=self.crashed,
            crash_step=self.crash_step, exit_status=self.exit_status, missed=self.missed,
            missed_steps=tuple(self.missed_steps), stopped_step=self.stopped_step,
            done_late=self.done_late,
        )  # fmt: skip


@dataclass(frozen=True)
class RobotOutcome:
    """A robot's record, frozen at the end of the run."""

    k: int
    finish_step: int | None
    crashed: bool
    crash_step: int | None
    exit_status: int | None
    missed: int
    missed_steps: tuple
    stopped_step: int | None  # killed on purpose at this step (--kill); None: it was not
    done_late: int = 0  # steps its "done" reached the world late (RobotRecord.finished)

    @property
    def counted(self) -> bool:
        """Whether the averages over robots count it: every robot but a stopped one."""
        return self.stopped_step is None


class WallParts:
    """Wall seconds of each stage of a run (result.json's wall_parts_s)."""

    def __init__(self, now: float) -> None:
        self.t_start = now
        self._mark = now
        self.parts: dict[str, float] = {}

    def mark(self, name: str, now: float | None = None) -> None:
        """Stage `name` ended now; it began where the last one ended."""
        now = time.monotonic() if now is None else now
        self.parts[name] = round(now - self._mark, 3)
        self._mark = now


@dataclass(frozen=True)
class RunRecord:
    """Everything the results of one run are written from (testbed.run.results)."""

    out: str
    config: RunConfigFile  # config.json's contents
    time_scale: float  # requested
    status: str
    detail: str
    world: World
    robots: tuple[RobotOutcome, ...]
    clock: ClockSummary
    world_timing: dict  # StepTiming.seconds(), {} when the loop never started
    parts: dict
    priority: str | None  # what the step loop's thread got
    t_start: float  # CLOCK_MONOTONIC when the run began
    network_timers: dict | None = (
        None  # topology.kernel.nettimers' record; None: no network came up
    )
    outages: tuple = ()  # testbed.files.isolation.Outage: the radio outages asked for (--isolate)
    robot: str | None = None  # the robot program: "cpp", "python" or (a test's) "mixed"
    robot_reason: str = ""  # why that one
    aodv_daemon: str | None = None  # the AODV daemon: "cpp", "python"; None: the routing has none
    aodv_daemon_reason: str = ""  # why that one
    # The host's ARP table overflows during the steps (topology.kernel.neightable); None: not read
    neighbour_table_fulls: int | None = None

    @property
    def steps(self) -> int:
        return self.clock.steps

    @property
    def finish_steps(self) -> list[int]:
        return [r.finish_step for r in self.robots if r.finish_step is not None]

    @property
    def last_finish_step(self) -> int | None:
        """The step at which the last robot to finish said so (None: nobody finished)."""
        return max(self.finish_steps, default=None)

    @property
    def counted_robots(self) -> tuple[RobotOutcome, ...]:
        """The robots the averages count: all but those stopped on purpose."""
        return tuple(r for r in self.robots if r.counted)

    @property
    def mean_finish_step(self) -> float | None:
        """The mean over the counted robots of their finishing step, a robot that never
        finished counting the run's last step: the paper's exploration time (Fig. 2). None
        when no robot counts."""
        counted = self.counted_robots
        if not counted:
            return None
        return statistics.fmean(
            r.finish_step if r.finish_step is not None else self.steps for r in counted
        )

    @property
    def survivors_finished(self) -> bool:
        """Whether every robot that was neither stopped nor crashed finished (False when
        none is left)."""
        left = [r for r in self.robots if r.counted and not r.crashed]
        return bool(left) and all(r.finish_step is not None for r in left)
