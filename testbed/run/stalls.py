"""Host stalls: steps whose deadlines nothing in the testbed could have met.

Theory of operation. The world's step loop runs at real-time priority (SCHED_RR 2, above
everything a run starts). When it wakes for a step's deadline more than STALL_S late, or its
own work for a step runs that far past the next deadline, nothing on the machine was running:
the virtual machine's host had taken the CPU (steal; on the 2-core development machine the
world was seen 25-98 ms late while the host took 5-25%). A robot that misses a deadline
during such a stall, or in the step after it while it catches up, missed it because of the
host, not because of the load the run puts on the machine, and no lower time scale would
have saved it: a stall of 30 ms eats 30 ms at any scale.

`StallTracker` follows the step loop: `late(step, s)` reports the world's lateness for a
step, `covers(step)` says whether a miss at that step falls in a stall (the steps the stall
spanned, plus one).

Time stops in a stall. Everything in the machine stood still in it, the robots too, so the
step it fell in left them less than a period of wall time for their work. The world gives
that time back: having woken late by L for a step's deadline, it waits `grace(L)` (L, at
most one period) before it takes the step's commands, and the clock's schedule moves on by
as much, so the steps after the stall are not squeezed either. A plan that a stall held back
then lands in the step it would have landed in had the machine not stopped, and the robot's
path stays what it is without stalls (docs/architecture.md, "The process tree and its
priorities"). What was given back is counted (`granted_s`): the achieved time scale shows it.

Every miss is still counted in the run's `deadline_miss_fraction`; the ones in stalls are
also counted apart, so that the sweep (testbed.sweep.command) slows a team size down only for
the misses a slower clock would have avoided.
"""

from __future__ import annotations

import math

STALL_S = 0.002  # the world at real-time priority wakes within ~0.2 ms when the host lets it


class StallTracker:
    def __init__(self, period: float):
        self.period = period
        self.until = -1  # misses at steps up to this one fall in a stall
        self.events = 0
        self.stalled_s = 0.0
        self.missed = 0  # misses (world's and robots') in stalls
        self.granted_s = 0.0  # wall seconds given back to the robots after stalls

    def grace(self, seconds: float) -> float:
        """Seconds the world waits after waking `seconds` late for a deadline: the time a
        stall took from the robots in that step (at most one period; none when the world
        woke within STALL_S)."""
        if seconds <= STALL_S:
            return 0.0
        return min(seconds, self.period)

    def granted(self, seconds: float) -> None:
        self.granted_s += seconds

    def late(self, step: int, seconds: float) -> None:
        """The world was `seconds` late for `step`'s deadline (or with `step`'s frames)."""
        if seconds <= STALL_S:
            return
        self.events += 1
        self.stalled_s += seconds
        self.until = max(self.until, step + math.ceil(seconds / self.period) + 1)

    def covers(self, step: int) -> bool:
        return step <= self.until

    def count(self, step: int, misses: int) -> None:
        """`misses` deadlines were missed at `step`; those in a stall are counted."""
        if misses and self.covers(step):
            self.missed += misses

    def summary(self) -> dict:
        return {
            "events": self.events,
            "stalled_s": round(self.stalled_s, 3),
            "deadlines_missed": self.missed,
            "granted_s": round(self.granted_s, 3),
        }
