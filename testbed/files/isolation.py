"""Radio outages a run makes on purpose (`--isolate ROBOT:STEP:STEPS`): a partition.

Theory of operation. An outage takes robot K out of everyone's radio range from step STEP
for STEPS steps: from that step on, the topology controller switches every link of K off
(topology.network: `Network.set_isolated`), whatever the positions say, and at step
STEP + STEPS the links the positions call for come back. Only the radio is out: the robot's
process, its body, its laser and its routing daemon go on as before, so it keeps exploring
alone, and its teammates and it learn of the break only from missing HELLOs and failed
sends, as on a real radio out of range. The display (robot N+1) is a teammate here too.

`Outage` is one window as the option gives it; `isolated_at` says which robots are out at a
step (a pure function of the windows, so the step loop keeps no state of its own for it);
`record` is what result.json says happened: each window the run reached, with the step its
robot came back at (None: the run ended first).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from testbed.files.resultfile import Isolated

_TEXT = re.compile(r"r?([0-9]{1,4}):([0-9]{1,8}):([0-9]{1,8})")


@dataclass(frozen=True)
class Outage:
    """Robot `robot` out of everyone's radio range for steps start .. start + steps - 1."""

    robot: int
    start: int
    steps: int

    @property
    def end(self) -> int:
        """The first step it is back in range."""
        return self.start + self.steps

    def covers(self, step: int) -> bool:
        return self.start <= step < self.end

    @classmethod
    def parse(cls, text: str) -> Outage:
        """From ROBOT:STEP:STEPS (e.g. r3:200:100); ValueError saying what is wrong."""
        m = _TEXT.fullmatch(text)
        if not m:
            raise ValueError(f"--isolate {text!r} is not ROBOT:STEP:STEPS (e.g. r3:200:100)")
        robot, start, steps = (int(v) for v in m.groups())
        if start < 1 or steps < 1:
            raise ValueError(f"--isolate {text!r}: STEP and STEPS must be at least 1")
        return cls(robot, start, steps)

    def text(self) -> str:
        """The inverse of parse."""
        return f"r{self.robot}:{self.start}:{self.steps}"


def isolated_at(outages: tuple[Outage, ...], step: int) -> frozenset[int]:
    """The robots whose radio is out at `step` (windows of one robot may overlap)."""
    return frozenset(o.robot for o in outages if o.covers(step))


def record(outages: tuple[Outage, ...], steps_run: int) -> list[Isolated]:
    """result.json's `isolated`: each window the run reached (in start order), with the step
    its robot came back in range, or None when the run ended while it was out."""
    out = []
    for o in sorted(outages, key=lambda o: (o.start, o.robot)):
        if o.start > steps_run:
            continue
        back = o.end if o.end <= steps_run else None
        out.append(Isolated(robot=f"r{o.robot}", from_step=o.start, back_step=back))
    return out
