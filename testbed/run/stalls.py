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
spanned, plus one). Every miss is still counted in the run's `deadline_miss_fraction`; the
ones in stalls are also counted apart, so that the sweep (testbed.sweep.command) slows a team size
down only for the misses a slower clock would have avoided.
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
        }
