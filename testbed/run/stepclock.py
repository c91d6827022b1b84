"""The world's step clock: deadlines, who missed them, and the time scale achieved.

Theory of operation. A step is STEP_S (100 ms) of emulated time and `period` = STEP_S / time
scale of wall time. Step k's deadline is `anchor + (k + 1) * period`, the anchor being the
moment the first frames went out. The world misses a deadline when its own work for a step
overruns it: the clock then moves the anchor by the overrun and a period, so that the robots
have a whole period for the frames that went out late (one hiccup counts once, and the
schedule does not try to catch up by running steps back to back, which would squeeze the
robots), and the achieved time scale shows the slip. A robot misses a deadline when it
has not answered the step's frame by then; the step loop counts those and tells the clock.

Every miss is counted; the ones that fall in a host stall (testbed.run.stalls: the machine
itself stopped, the world at real-time priority woke too late) are also counted apart.

The clock never reads the time: every method that needs "now" is given it, so the
arithmetic is tested with made-up times (tests/unit/test_stepclock.py), and the step loop
(testbed.run.execute) is the one place that reads CLOCK_MONOTONIC. `summary()` computes, once, what
result.json says of the clock: steps, wall seconds, achieved scale, misses and stalls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from node.timing import STEP_S
from testbed.files.resultfile import MAX_MISSED_STEPS_KEPT
from testbed.run.stalls import StallTracker

NO_STALLS = {"events": 0, "stalled_s": 0.0, "deadlines_missed": 0, "granted_s": 0.0}


@dataclass(frozen=True)
class ClockSummary:
    """What a run's clock did, computed once when the step loop ends."""

    steps: int  # the last step done
    robots: int  # robots checked at each step (the world is one more)
    loop_wall_s: float  # wall seconds of the step loop (0 when it did not end normally)
    time_scale_achieved: float
    missed_world: int
    missed_robots: int
    stalls: dict = field(default_factory=lambda: dict(NO_STALLS))
    world_missed_steps: tuple = ()  # (step, ms late) of the world's misses, the first 1000
    stepping: tuple[float, float] | None = None  # CLOCK_MONOTONIC s of step 0 and the end

    @property
    def deadlines_missed(self) -> int:
        return self.missed_world + self.missed_robots

    def _fraction(self, missed: int) -> float:
        if not self.steps:
            return 0.0
        return round(missed / max(1, self.steps * (self.robots + 1)), 5)

    @property
    def miss_fraction(self) -> float:
        """Misses over steps x (robots + 1): every robot and the world, at every step."""
        return self._fraction(self.deadlines_missed)

    @property
    def miss_fraction_outside_stalls(self) -> float:
        """The misses a lower time scale could have avoided (what the sweep acts on)."""
        return self._fraction(self.deadlines_missed - self.stalls["deadlines_missed"])


def no_clock(robots: int) -> ClockSummary:
    """The summary of a run whose step loop never started."""
    return ClockSummary(0, robots, 0.0, 0.0, 0, 0)


class StepClock:
    """The schedule of one run's steps; `step` is the last step whose frames are out."""

    def __init__(self, time_scale: float, robots: int, now: float) -> None:
        self.period = STEP_S / time_scale
        self.robots = robots
        self.t0 = now  # when step 0's frames went out
        self.anchor = now  # step k's deadline is anchor + (k + 1) * period
        self.step = 0
        self.stalls = StallTracker(self.period)
        self.missed_world = 0
        self.missed_robots = 0
        self.world_missed_steps: list[tuple[int, float]] = []
        self.stopped_at: float | None = None
        self.warmup_s = 0.0  # waited for the robots' first answers (not emulated time)

    def deadline(self, step: int | None = None) -> float:
        """When `step`'s commands are due (default: the next step's, `self.step + 1`'s
        frames answer `self.step`'s)."""
        return self.anchor + ((self.step if step is None else step) + 1) * self.period

    def late(self, now: float) -> float:
        """Seconds past the current step's deadline at `now` (negative: early)."""
        return now - self.deadline()

    def woke(self, now: float) -> float:
        """The world woke at `now` for the current step's deadline; waking late is a host
        stall when it is over the stall threshold. Returns the seconds the world waits
        before it takes the step's commands (testbed.run.stalls, "Time stops in a stall"):
        the schedule moves by as much, and the deadline is then `now` plus that."""
        late = self.late(now)
        self.stalls.late(self.step, late)
        grace = self.stalls.grace(late)
        if grace > 0:
            self.stalls.granted(grace)
            self.anchor += late + grace
        return grace

    def warmed_up(self, seconds: float) -> None:
        """The world waited `seconds` for the robots' first answers (the step loop's warm-up):
        the schedule moves by as much, and it is counted apart (`warmup_s`)."""
        self.anchor += seconds
        self.warmup_s += seconds

    def robots_missed(self, misses: int) -> None:
        """`misses` robots had not answered the current step's frame by its deadline."""
        self.missed_robots += misses
        self.stalls.count(self.step, misses)

    def advance(self) -> int:
        """The next step begins; returns its number."""
        self.step += 1
        return self.step

    def world_done(self, now: float) -> float:
        """The world finished its work for the current step, its frames sent, at `now`. Past
        the step's deadline, that is the world's miss: counted once, and the schedule moves
        by the overrun and a period, so that the robots have a whole period to answer the
        frames that only went out now (moved by the overrun alone, the deadline would be
        `now`: every robot would miss the step, stand still and change its path). Returns how
        late (s; 0 when in time)."""
        late = self.late(now)
        if late <= 0:
            return 0.0
        self.missed_world += 1
        self.stalls.late(self.step, late)
        self.stalls.count(self.step, 1)
        self.anchor += late + self.period
        if len(self.world_missed_steps) < MAX_MISSED_STEPS_KEPT:
            self.world_missed_steps.append((self.step, round(late * 1000, 1)))
        return late

    def achieved_scale(self, now: float) -> float:
        """Emulated time over wall time since step 0, at `now`."""
        return self.step * STEP_S / max(1e-9, now - self.t0)

    def stop(self, now: float) -> None:
        """The step loop ended normally at `now`."""
        self.stopped_at = now

    def summary(self) -> ClockSummary:
        """What result.json says of the clock. A loop that did not end normally (interrupted,
        failed) has no wall time and no achieved scale."""
        end = self.stopped_at  # None: it did not end normally
        return ClockSummary(
            steps=self.step,
            robots=self.robots,
            loop_wall_s=end - self.t0 if end is not None else 0.0,
            time_scale_achieved=self.achieved_scale(end) if end is not None else 0.0,
            missed_world=self.missed_world,
            missed_robots=self.missed_robots,
            stalls=self.stalls.summary(),
            world_missed_steps=tuple(self.world_missed_steps),
            stepping=(self.t0, end) if end is not None else None,
        )


@dataclass
class StepTiming:
    """Wall seconds the world spent on each part of its steps (result.json's
    world_timing_s)."""

    net_s: float = 0.0
    net_max_s: float = 0.0
    world_s: float = 0.0
    scan_s: float = 0.0
    send_s: float = 0.0
    world_cpu_s: float = 0.0
    loop: str = "python"  # the step loop that ran (testbed.run.steploop.loop_kind)

    def seconds(self) -> dict[str, float | str]:
        """The seconds, and `step_loop`: which loop ran (result.json's field of that name)."""
        out: dict[str, float | str] = {
            k: round(getattr(self, k), 3)
            for k in ("net_s", "net_max_s", "world_s", "scan_s", "send_s", "world_cpu_s")
        }
        out["step_loop"] = self.loop
        return out
