"""The progress line of `testbed run` on stderr while the steps go, and its last line.

On a terminal the line is redrawn in place twice a second; in a log (a sweep's run) a line
is written every 10 s. `summary_line` is what `testbed run` prints when the run is over:
its status, steps, coverage, where the results are and the command that shows them.
"""

from __future__ import annotations

import shlex
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from testbed.files.resultfile import RunResult


class ProgressLine:
    def __init__(self, enabled: bool, max_steps: int, robots: int) -> None:
        self.enabled = enabled
        self.tty = enabled and sys.stderr.isatty()
        self.max_steps = max_steps
        self.robots = robots
        self._last = 0.0

    def due(self, now: float) -> bool:
        """Whether a line is due at `now` (twice a second on a terminal, else every 10 s)."""
        return self.enabled and now - self._last > (0.5 if self.tty else 10.0)

    def show(self, now: float, step: int, coverage: float, done: int, crashed: int,
             scale: float, missed: int) -> None:  # fmt: skip
        self._last = now
        line = (
            f"step {step}/{self.max_steps}  coverage {100 * coverage:5.1f}%  "
            f"finished {done}/{self.robots}  crashed {crashed}  scale {scale:.1f}x  "
            f"missed {missed}"
        )
        sys.stderr.write(("\r" + line + "  ") if self.tty else (line + "\n"))
        sys.stderr.flush()

    def end(self) -> None:
        if self.tty:
            sys.stderr.write("\n")


def summary_line(result: RunResult, out: str) -> str:
    """One line for the end of `testbed run`."""
    cov = result.coverage_final
    return (
        f"testbed run: {result.status} after {result.steps} steps, coverage "
        f"{'unknown' if cov is None else f'{100 * cov:.1f}%'}; results in {out}; replay: "
        f"testbed view {shlex.quote(out)}"
    )
