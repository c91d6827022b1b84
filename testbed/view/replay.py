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

import dataclasses
from pathlib import Path

from common import boundedfile
from testbed.files import configfile, csvfiles
from testbed.files.configfile import CONFIG_NAME
from testbed.files.csvfiles import COVERAGE_NAME, LINKS_NAME, POSITIONS_NAME
from testbed.files.resultfile import RESULT_NAME, RunResult
from testbed.view.served import in_run, snapshot, snapshot_steps

__all__ = ["NotARun", "load", "read_config", "snapshot_path", "snapshot_steps"]


MAX_STEP = csvfiles.MAX_STEP  # the last step a query may ask for


class NotARun(ValueError):
    """The directory holds no finished run the view can replay."""


def read_config(d: Path) -> dict:
    """What the view takes from config.json, checked (testbed.files.configfile): robots,
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


def _rows(d: Path, name: str, parse, required: bool = False, header=None) -> list:
    """The rows after the header of the run's CSV file `name`, each through `parse(row)`
    (which raises ValueError for a bad one), the header through `header` when given."""
    path = in_run(d, name)
    if path is None:
        if required:
            raise NotARun(f"{d}: not a run directory with {name} (runs made since 2026-11-24)")
        return []
    try:
        return csvfiles.rows(path, parse, header)
    except boundedfile.Refused as r:
        raise NotARun(f"{d}/{name}: {boundedfile.describe(r)}") from None
    except csvfiles.CsvError as e:
        raise NotARun(f"{d}/{name} line {e.line}: {e.why}") from None


def load(run_dir: str | Path) -> dict:
    d = Path(run_dir)
    config = read_config(d)
    found = in_run(d, RESULT_NAME)
    result = None if found is None else RunResult.read(found)
    status = "running" if found is None else result.status if result else "unknown"
    if len(status) > 40:
        status = "unknown"
    n = config["robots"]

    positions = _rows(d, POSITIONS_NAME, csvfiles.position_rows(n), required=True,
                      header=csvfiles.position_header(n))  # fmt: skip
    last = len(positions) - 1
    links = [list(c) for c in _rows(d, LINKS_NAME, csvfiles.link_rows(n, last))]

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
        "links": links,  # [step, added?, i, j]
        "coverage": _rows(d, COVERAGE_NAME, csvfiles.coverage_row),
        "snapshots": snapshot_steps(d),
    }


def snapshot_path(run_dir: Path, step: int) -> Path | None:
    """The display's snapshot of `step` that may be served (testbed.view.served.snapshot)."""
    return snapshot(run_dir, step)
