"""sweep.json as the readers take it: checked before anything is drawn from it.

A sweep directory may come from elsewhere, and `testbed report`, `sweep --status`,
`sweep --resume` and the Slurm tasks read its sweep.json (testbed.sweep.runner writes it).
`read(out)` reads it through the one bounded reader (common.boundedfile: a FIFO is refused,
not waited on; strict JSON, no NaN or 1e400) and checks the shape every reader relies on:

- the document is an object; `runs` a list of objects, each with an `id` that is a run
  directory's name (letters, digits, `.`, `_`, `-`, at most 100) and, where present, a
  string `status` and `reason`, whole numbers `index` and `pid`, and a `config` whose every
  key is a run option with a value its table allows (testbed.run.options.check_value; the
  Slurm tasks build a run's command line from it);
- `spec` an object whose `grid` and `run` are objects and `time_scale_by_robots` maps team
  sizes (1..1000) to positive numbers; `time_scale_factor` maps team sizes to positive
  numbers; `backoffs` a list; `sweep_file` a string.

A sweep.json that fails is one line naming the file and the field (UsageError, exit 2);
None when there is none. Strings are made one line (testbed.resultfile.one_line).
"""

from __future__ import annotations

import os
import re
from argparse import ArgumentTypeError
from pathlib import Path

from common import boundedfile
from common.errors import UsageError
from testbed.resultfile import one_line

STATE_NAME = "sweep.json"
RUN_ID = re.compile(r"[A-Za-z0-9._-]{1,100}")
MAX_TEAM = 1000


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _team_map(where: str, value) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ValueError(f"{where} is not an object")
    for k, v in value.items():
        if not (k.isascii() and k.isdigit() and len(k) <= 4 and 1 <= int(k) <= MAX_TEAM):
            raise ValueError(f"{where} has key {one_line(k, 40)!r}, not a team size")
        if not _number(v) or not v > 0:
            raise ValueError(f"{where}[{k}] is {one_line(str(v), 40)}, not a positive number")
    return value


def _run(i: int, e) -> dict:
    where = f"runs[{i}]"
    if not isinstance(e, dict):
        raise ValueError(f"{where} is not an object")
    rid = e.get("id")
    if not isinstance(rid, str) or not RUN_ID.fullmatch(rid) or rid in (".", ".."):
        raise ValueError(f"{where}.id is {one_line(repr(rid), 60)}, not a run directory's name")
    for key, kinds in (("status", str), ("reason", str), ("config", dict)):
        if e.get(key) is not None and not isinstance(e[key], kinds):
            raise ValueError(f"{where}.{key} is {type(e[key]).__name__}")
    for key in ("index", "pid"):
        v = e.get(key)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v < 0):
            raise ValueError(f"{where}.{key} is not a whole number")
    if e.get("config") is not None:
        _config(where, e["config"])
    return {k: one_line(v) if isinstance(v, str) else v for k, v in e.items()}


def _config(where: str, config: dict) -> None:
    """ValueError unless every key of a run's plan is a run option with a valid value, and
    the plan makes a RunConfig (the structured options: display_pos, snapshots, kill, ...)."""
    from testbed.run.config import BY_NAME, RunConfig
    from testbed.run.options import check_value

    for key, value in config.items():
        opt = BY_NAME.get(key)
        if opt is None:
            raise ValueError(f"{where}.config has {one_line(key, 40)!r}, not a run option")
        if value is None or opt.parse is not None or opt.repeat:
            continue
        why = check_value(opt, value)
        if why:
            raise ValueError(f"{where}.config.{key}: {one_line(why, 120)}")
    try:
        RunConfig.from_dict(config)
    except (TypeError, ValueError, ArgumentTypeError) as e:
        raise ValueError(f"{where}.config: {one_line(str(e), 120)}") from None


def check(doc) -> dict:
    """The checked sweep.json document (see the module's docstring); ValueError naming the
    field otherwise."""
    if not isinstance(doc, dict):
        raise ValueError("not a JSON object")
    runs = doc.get("runs", [])
    if not isinstance(runs, list):
        raise ValueError("runs is not a list")
    out = dict(doc)
    out["runs"] = [_run(i, e) for i, e in enumerate(runs)]
    spec = doc.get("spec")
    spec = {} if spec is None else spec
    if not isinstance(spec, dict):
        raise ValueError("spec is not an object")
    for key in ("grid", "run"):
        if spec.get(key) is not None and not isinstance(spec[key], dict):
            raise ValueError(f"spec.{key} is not an object")
    _team_map("spec.time_scale_by_robots", spec.get("time_scale_by_robots"))
    _team_map("time_scale_factor", doc.get("time_scale_factor"))
    if doc.get("backoffs") is not None and not isinstance(doc["backoffs"], list):
        raise ValueError("backoffs is not a list")
    if doc.get("sweep_file") is not None:
        if not isinstance(doc["sweep_file"], str):
            raise ValueError("sweep_file is not a string")
        out["sweep_file"] = one_line(doc["sweep_file"])
    out["spec"] = spec
    return out


def read(out: Path) -> dict | None:
    """DIR/sweep.json checked (see the module's docstring); None when there is none;
    UsageError (one line naming the file and the field) when it is not one."""
    path = Path(out) / STATE_NAME
    if not os.path.lexists(path):
        return None
    try:
        return check(boundedfile.load_json(path))
    except boundedfile.Refused as r:
        raise UsageError(f"{path}: {boundedfile.describe(r)}") from None
    except ValueError as e:
        raise UsageError(f"{path}: {e}") from None
