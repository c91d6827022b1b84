"""How late a process kept its time promises, in emulated time: O(1) per event.

Theory of operation. Time dilation is faithful while every piece of work that belongs to a
step is done within that step, as it would be on hardware at time scale 1: a robot's plan is
applied at the first frame after it was asked for, its timer fires at the step it is due, a
frame is answered before the next one. A `Lateness` records, for one such promise, how late
each event was (in emulated steps or emulated milliseconds: the unit is the caller's), as a
count, a running maximum and a histogram over fixed bounds; nothing is kept per event, so a
run of any length costs the same few integers, and recording changes nothing of what the
robot does. `as_dict()` is what the robot's summary (and so robots/rK.json) says;
testbed.run.fidelity judges a run from those.
"""

from __future__ import annotations

from collections.abc import Sequence

STEP_BOUNDS = (0, 1, 2, 4, 8)  # steps late: on time, one step, two, up to 4, up to 8, more
MS_BOUNDS = (10, 25, 50, 100, 200)  # emulated ms: up to a tenth of a step ... two steps


class Lateness:
    """Events of one kind and how late each was; `bounds` are the histogram's upper bounds
    (inclusive), in increasing order; a last bucket holds everything above them."""

    def __init__(self, bounds: Sequence[float] = STEP_BOUNDS) -> None:
        self.bounds = tuple(bounds)
        if list(self.bounds) != sorted(self.bounds) or not self.bounds:
            raise ValueError(f"bounds must be increasing and not empty: {bounds}")
        self.counts = [0] * (len(self.bounds) + 1)
        self.n = 0
        self.max = 0.0
        self.late = 0  # events later than 0

    def add(self, late: float) -> None:
        """One event, `late` units after it was due (0 or less: on time)."""
        self.n += 1
        if late > 0:
            self.late += 1
        if late > self.max:
            self.max = late
        for i, b in enumerate(self.bounds):
            if late <= b:
                self.counts[i] += 1
                return
        self.counts[-1] += 1

    def over(self, threshold: float) -> int:
        """Events later than `threshold`, which must be one of the bounds."""
        i = self.bounds.index(threshold)
        return sum(self.counts[i + 1 :])

    def as_dict(self) -> dict:
        labels = [f"<={_num(b)}" for b in self.bounds] + [f">{_num(self.bounds[-1])}"]
        return {
            "n": self.n,
            "late": self.late,
            "max": round(self.max, 3),
            "hist": dict(zip(labels, self.counts, strict=True)),
        }


def _num(b: float) -> str:
    return str(int(b)) if float(b).is_integer() else str(b)
