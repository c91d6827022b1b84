"""A finished run, as the view page draws it: read from the run directory's own files.

`load(run_dir)` reads config.json/result.json (team, communication range, map size),
positions.csv (every robot at every step), links.csv (every link change) and coverage.csv,
and returns one JSON-able dict: the page replays it with a time slider. Nothing here
touches a process or a network: a run's files are its whole record (docs/run-results.md).
"""

from __future__ import annotations

import csv
from pathlib import Path

from topology.jsonfile import read_json


class NotARun(ValueError):
    """The directory holds no finished run the view can replay."""


def _rows(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))[1:]


def snapshot_steps(run_dir: Path) -> list[int]:
    """The steps at which the display robot saved its merged map (display/step-NNNNN.png)."""
    steps = []
    for p in (Path(run_dir) / "display").glob("step-*.png"):
        digits = p.stem.removeprefix("step-")
        if digits.isdigit():
            steps.append(int(digits))
    return sorted(steps)


def snapshot_path(run_dir: Path, step: int) -> Path | None:
    """The display's snapshot of `step`, if the run saved one (looked up, never built from
    what a request says)."""
    if step not in snapshot_steps(run_dir):
        return None
    return Path(run_dir) / "display" / f"step-{step:05d}.png"


def load(run_dir: str | Path) -> dict:
    d = Path(run_dir)
    config = read_json(d / "config.json")
    if config is None or not (d / "positions.csv").is_file():
        raise NotARun(f"{d}: not a run directory with positions.csv (runs made since 2026-11-24)")
    result = read_json(d / "result.json") or {}
    n = int(config["robots"])
    positions = [[round(float(v), 3) for v in row[1:]] for row in _rows(d / "positions.csv")]
    links = [[int(row[0]), row[1] == "add", int(row[2]), int(row[3])]
             for row in _rows(d / "links.csv")] if (d / "links.csv").is_file() else []  # fmt: skip
    coverage = [float(row[1]) for row in _rows(d / "coverage.csv")] if (
        d / "coverage.csv").is_file() else []  # fmt: skip
    cell = float(config.get("map_cell", 0.05))
    rows, cols = config.get("map_size") or [400, 400]
    return {
        "run": d.name,
        "robots": n,
        "comm_range": float(config["comm_range"]),
        "map_m": [cols * 0.05, rows * 0.05] if config.get("map_size") else [20.0, 20.0],
        "map_cell": cell,
        "display": list(config.get("display_pos") or []),
        "status": result.get("status", "running"),
        "steps": len(positions) - 1,
        "positions": positions,  # per step: x1, y1, x2, y2, ...
        "links": links,  # [step, added?, i, j]
        "coverage": coverage,
        "snapshots": snapshot_steps(d),
    }
