"""A finished run, as the view page draws it: read from the run directory's own files.

`load(run_dir)` reads config.json/result.json (team, communication range, map size),
positions.csv (every robot at every step), links.csv (every link change) and coverage.csv,
and returns one JSON-able dict: the page replays it with a time slider. Nothing here
touches a process or a network: a run's files are its whole record (docs/run-results.md).

The files may come from anyone (docs/security.md): each is read only as testbed.view.served
allows, and every value is checked (numbers finite and within bounds, counts that agree); a
file that fails is a NotARun saying which file and line, never a traceback or a value the
page or JSON cannot hold.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

from common import boundedfile
from testbed.resultfile import RESULT_NAME, RunResult
from testbed.run import configfile
from testbed.run.configfile import CONFIG_NAME
from testbed.view.served import in_run, snapshot, snapshot_steps
from topology.spec import MAX_COORD_M

__all__ = ["NotARun", "load", "read_config", "snapshot_path", "snapshot_steps"]

MAX_STEP = 10**9


class NotARun(ValueError):
    """The directory holds no finished run the view can replay."""


def read_config(d: Path) -> dict:
    """What the view takes from config.json, checked (testbed.run.configfile): robots,
    comm_range, map_m, map_cell, display (a position or nothing) and map (what it names,
    unchecked: testbed.view.served decides whether to serve it)."""
    path = in_run(d, CONFIG_NAME)
    if path is None:
        raise NotARun(f"{d}: not a run directory with {CONFIG_NAME} (runs made since 2026-11-24)")
    try:  # a regular file only, bounded; its values are checked field by field
        config = configfile.read(path)
    except (boundedfile.Refused, configfile.ConfigError):
        raise NotARun(f"{d}/{CONFIG_NAME}: not a JSON object") from None
    try:
        return dataclasses.asdict(config.view())
    except configfile.ConfigError as e:
        raise NotARun(f"{d}/{CONFIG_NAME}: {e}") from None


def _rows(d: Path, name: str, parse, required: bool = False) -> list:
    """The rows after the header of the run's CSV file `name`, each through `parse(row)`
    (which raises ValueError for a bad one)."""
    path = in_run(d, name)
    if path is None:
        if required:
            raise NotARun(f"{d}: not a run directory with {name} (runs made since 2026-11-24)")
        return []
    try:
        f = boundedfile.open_text(path)  # checked on the descriptor: no FIFO swapped in
    except boundedfile.Refused as r:
        raise NotARun(f"{d}/{name}: {boundedfile.describe(r)}") from None
    with f:
        reader = csv.reader(f)
        try:
            next(reader, None)
            return [parse(row) for row in reader]
        except (ValueError, csv.Error) as e:  # UnicodeDecodeError is a ValueError
            why = (str(e).splitlines() or ["unreadable"])[0][:200]
            raise NotARun(f"{d}/{name} line {reader.line_num}: {why}") from None


def _finite(text: str, lo: float, hi: float) -> float:
    value = float(text)
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{text[:40]!r} is not a number in {lo:g}..{hi:g}")
    return value


def _whole(text: str, lo: int, hi: int) -> int:
    if not (text.isascii() and text.isdigit() and len(text) <= 10 and lo <= int(text) <= hi):
        raise ValueError(f"{text[:40]!r} is not a whole number in {lo}..{hi}")
    return int(text)


def load(run_dir: str | Path) -> dict:
    d = Path(run_dir)
    config = read_config(d)
    found = in_run(d, RESULT_NAME)
    result = None if found is None else RunResult.read(found)
    status = "running" if found is None else result.status if result else "unknown"
    if len(status) > 40:
        status = "unknown"
    n = config["robots"]

    seen = [0]  # rows of positions.csv read: its step column counts them

    def position_row(row: list[str]) -> list[float]:
        if len(row) != 1 + 2 * n:
            raise ValueError(f"{len(row)} columns, not {1 + 2 * n} (step, x and y of {n})")
        if _whole(row[0], 0, MAX_STEP) != seen[0]:
            raise ValueError(f"step {row[0][:20]!r}, not {seen[0]} (one row a step, in order)")
        seen[0] += 1
        return [round(_finite(v, -MAX_COORD_M, MAX_COORD_M), 3) for v in row[1:]]

    positions = _rows(d, "positions.csv", position_row, required=True)
    last = len(positions) - 1

    def link_row(row: list[str]) -> list:
        if len(row) != 4 or row[1] not in ("add", "remove"):
            raise ValueError("not step,add|remove,i,j")
        i, j = (_whole(v, 1, n + 1) for v in row[2:])  # n + 1: the display robot
        if i == j:
            raise ValueError(f"a link of robot {i} to itself")
        return [_whole(row[0], 0, max(last, 0)), row[1] == "add", i, j]

    def coverage_row(row: list[str]) -> float:
        if len(row) != 2:
            raise ValueError("not step,coverage")
        return _finite(row[1], 0.0, 1.0)

    return {
        "run": d.name,
        "robots": n,
        "comm_range": config["comm_range"],
        "map_m": config["map_m"],
        "map_cell": config["map_cell"],
        "display": config["display"],
        "status": status,
        "steps": len(positions) - 1,
        "positions": positions,  # per step: x1, y1, x2, y2, ...
        "links": _rows(d, "links.csv", link_row),  # [step, added?, i, j]
        "coverage": _rows(d, "coverage.csv", coverage_row),
        "snapshots": snapshot_steps(d),
    }


def snapshot_path(run_dir: Path, step: int) -> Path | None:
    """The display's snapshot of `step` that may be served (testbed.view.served.snapshot)."""
    return snapshot(run_dir, step)
