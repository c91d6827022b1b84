"""What a run knows of itself: robots' records while it goes, the frozen record at its end.

Theory of operation. While the step loop runs, each robot's process has a `RobotRecord` the
loop updates (its last answered step, when it finished, whether it crashed, its missed
deadlines). When the run ends, `Run.execute` (testbed.run) freezes everything the results
need into a `RunRecord`: the configuration, the status, the world, each robot's
`RobotOutcome`, the clock's summary (testbed.stepclock) and the wall time of each stage.
testbed.runresults writes result.json and the per-robot files from that record alone.
"""

from __future__ import annotations

import statistics
import subprocess
import time
from dataclasses import dataclass, field

from testbed.stepclock import MAX_MISSED_STEPS_KEPT, ClockSummary
from testbed.world.world import World


@dataclass
class RobotRecord:
    """What the world knows of one robot's process during the run."""

    k: int
    proc: subprocess.Popen | None = None
    last_cmd: int = -1  # the latest step whose frame it answered
    finish_step: int | None = None
    crashed: bool = False
    crash_step: int | None = None
    exit_status: int | None = None
    missed: int = 0
    missed_steps: list = field(default_factory=list)
    killed_at: int | None = None

    def answered(self, step: int) -> None:
        self.last_cmd = max(self.last_cmd, step)

    def finished(self, step: int) -> None:
        """The robot said it is done while the world's last step was `step`."""
        if self.finish_step is None:
            self.finish_step = step

    def missed_deadline(self, step: int) -> bool:
        """Whether a live robot had not answered `step`'s frame by the deadline (counted)."""
        if self.crashed or self.last_cmd >= step:
            return False
        self.missed += 1
        if len(self.missed_steps) < MAX_MISSED_STEPS_KEPT:
            self.missed_steps.append(step)
        return True

    def died(self, step: int, status: int | None) -> None:
        self.crashed, self.crash_step, self.exit_status = True, step, status

    def outcome(self) -> RobotOutcome:
        return RobotOutcome(
            k=self.k, finish_step=self.finish_step, crashed=self.crashed,
            crash_step=self.crash_step, exit_status=self.exit_status, missed=self.missed,
            missed_steps=tuple(self.missed_steps), killed_at=self.killed_at,
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
    killed_at: int | None


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
    """Everything the results of one run are written from (testbed.runresults)."""

    out: str
    config: dict  # config.json's contents
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
    network_timers: dict | None = None  # topology.nettimers' record; None: no network came up

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
    def mean_finish_step(self) -> float | None:
        """The mean over robots of their finishing step, a robot that never finished
        counting the run's last step: the paper's exploration time (Fig. 2)."""
        if not self.robots:
            return None
        return statistics.fmean(
            r.finish_step if r.finish_step is not None else self.steps for r in self.robots
        )
