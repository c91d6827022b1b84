"""A run's directory and the files its step loop writes as it goes.

Theory of operation. `claim_directory` decides, before anything of the run exists, whether
`--out DIR` may be written: a directory that holds a run (its config.json, result.json or
robots/) is refused unless the run was told to replace it, and then that run is removed
whole, so that no pcap, daemon log or snapshot of the old run lies beside the new one. A
directory that cannot be made or written is bad input too (UsageError: one line, exit 2).

`RunFiles` is the step loop's output, a context manager: entering opens links.csv,
coverage.csv and positions.csv with their headers, and events.jsonl (what the run did to its
robots on purpose: a robot stopped, a radio taken out of range and back); each step adds its
rows; leaving writes
clock.csv (when each step's frames went out) and closes everything, whatever happened, so a
failed run's files are complete up to its last step. docs/run-results.md says what each
file holds.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
from typing import TYPE_CHECKING, TextIO

from common.errors import UsageError
from testbed.files import layout
from testbed.files.configfile import CONFIG_NAME
from testbed.files.csvfiles import (
    COVERAGE_HEADER,
    COVERAGE_NAME,
    LINKS_HEADER,
    LINKS_NAME,
    POSITIONS_NAME,
    positions_header,
)
from testbed.files.resultfile import RESULT_NAME

if TYPE_CHECKING:
    import _csv

# What makes a directory a run's: written first (config.json), last (result.json), or by
# the robot processes (robots/).
RUN_MARKERS = (CONFIG_NAME, RESULT_NAME, layout.ROBOTS_DIR)


def holds_run(out: str) -> bool:
    return any(os.path.lexists(os.path.join(out, m)) for m in RUN_MARKERS)


def claim_directory(out: str, replace: bool) -> None:
    """Check that the run may write into `out` (UsageError if not; nothing touched). With
    `replace`, an earlier run there is removed; nothing is created yet."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out}: not a directory")
    if holds_run(out) and not replace:
        raise UsageError(
            f"--out {out} holds a run already: choose another directory, or add --replace "
            "to delete that run first"
        )
    parent = os.path.dirname(os.path.abspath(out))
    while not os.path.isdir(parent):
        if os.path.lexists(parent):
            raise UsageError(f"--out {out}: {parent} is not a directory")
        parent = os.path.dirname(parent)
    if not os.access(out if os.path.isdir(out) else parent, os.W_OK | os.X_OK):
        raise UsageError(f"--out {out}: cannot write there (permission denied)")


def make_directory(out: str, capture: bool, replace: bool) -> None:
    """The run directory and its sub-directories, after `claim_directory` said yes; an
    earlier run there is removed first when `replace`. UsageError if it cannot be made."""
    try:
        if replace and holds_run(out):
            shutil.rmtree(out)
        for sub in (layout.robots_dir, layout.display_dir) + (
            (layout.pcaps_dir,) if capture else ()
        ):
            os.makedirs(sub(out), exist_ok=True)
    except OSError as e:
        raise UsageError(f"--out {out}: cannot write there: {e.strerror}") from None


class RunFiles:
    """The per-step CSVs of a run in `out` (robots r1..rN); a context manager."""

    def __init__(self, out: str, robots: int) -> None:
        self.out = out
        self.robots = robots
        self._files: list = []
        self._frames: list[float] = []  # CLOCK_MONOTONIC of each step's frames (clock.csv)
        # Opened by __enter__:
        self._links: _csv.Writer
        self._coverage: _csv.Writer
        self._positions: _csv.Writer
        self._events: TextIO

    def __enter__(self) -> RunFiles:
        def writer(name: str, header: list[str]) -> _csv.Writer:
            f = open(os.path.join(self.out, name), "w", newline="")  # noqa: SIM115 (closed in __exit__)
            self._files.append(f)
            w = csv.writer(f)
            w.writerow(header)
            return w

        self._links = writer(LINKS_NAME, list(LINKS_HEADER))
        self._coverage = writer(COVERAGE_NAME, list(COVERAGE_HEADER))
        self._positions = writer(POSITIONS_NAME, positions_header(self.robots))
        self._events = open(layout.run_events(self.out), "w")  # noqa: SIM115
        self._files.append(self._events)
        return self

    def __exit__(self, *exc) -> None:
        try:
            self._write_clock()
        finally:
            for f in reversed(self._files):
                f.close()

    def links(self, step: int, added, removed=()) -> None:
        """Links that went (first) and came at `step`; step 0: the initial links."""
        for i, j in sorted(removed):
            self._links.writerow([step, "remove", i, j])
        for i, j in sorted(added):
            self._links.writerow([step, "add", i, j])

    def event(self, step: int, kind: str, robot: int) -> None:
        """Something the run did to robot `robot` at `step` (events.jsonl): `stopped`,
        `isolated`, `back_in_range`."""
        self._events.write(json.dumps({"step": step, "e": kind, "robot": f"r{robot}"}) + "\n")
        self._events.flush()

    def coverage(self, step: int, coverage: float) -> None:
        self._coverage.writerow([step, f"{coverage:.5f}"])

    def positions(self, step: int, positions) -> None:
        self._positions.writerow([step] + [f"{v:.3f}" for p in positions for v in p])

    def frames_out(self, now: float) -> None:
        """A step's frames went out at `now` (CLOCK_MONOTONIC)."""
        self._frames.append(round(now, 4))

    def _write_clock(self) -> None:
        """clock.csv: when (CLOCK_MONOTONIC, the clock robots log receipts with) each step
        began; what lets testbed.analysis.runcheck place a receipt at the world's step."""
        with open(layout.clock_path(self.out), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["step", "t"])
            w.writerows(enumerate(self._frames))
