"""sweep.json as one type: `SweepState` (the sweep's bookkeeping) and `SweepRun` (one
planned run and its status record), which testbed.sweep.runner writes and everyone reads.

A sweep directory may come from elsewhere, and `testbed report`, `sweep --status`,
`sweep --resume` and the Slurm tasks read its sweep.json (testbed.sweep.runner writes it
with `write`, from a `SweepState`). `read(out)` reads it through the one bounded reader
(common.boundedfile: a FIFO is refused, not waited on; strict JSON, no NaN or 1e400) and
checks the shape every reader relies on:

- the document is an object of `format` STATE_FORMAT (a file without one is older, and of
  that format: another format's keys may mean other things, and are not read as this
  one's); `runs` a list of objects, each with an `id` that is a run directory's name
  (letters, digits, `.`, `_`, `-`, at most 100; no two runs of one id) and, where present, a
  string `status` and `reason`, whole numbers `index` and `pid`, and a `config` whose every
  key is a run option with a value its table allows (testbed.files.options.check_value; the
  Slurm tasks build a run's command line from it) and which passes the rule joining options
  that `testbed run` applies (testbed.files.runconfig.refusal: a laser shorter than a map cell is
  no run);
- `format`, `jobs_requested` and `jobs` whole numbers, the load and cpu limits (as asked
  and as they are now) positive numbers, `netem` true or false, `updated` a string;
- `spec` an object whose `grid` and `run` are objects and `time_scale_by_robots` maps team
  sizes (1..1000) to positive numbers; `time_scale_factor` maps team sizes to positive
  numbers; `backoffs` a list of objects; `calibration` maps team sizes to objects;
  `sweep_file` a string.

Keys that files written by older versions lack get their defaults here and only here: no
runs, an empty spec, no sweep file, no factors, calibration or back-offs; a run without a
status record has none (`status` None). Sweeps before grids were declared per option
recorded every field of the spec at the top level (`SweepState.spec_value` reads both).
`to_dict()` gives the keys in the order the runner always wrote them, so the file is what it
was before the type existed. Nobody else spells the file's name or opens it
(tests/unit/test_file_types.py holds this).

A sweep.json that fails is one line naming the file and the field (UsageError, exit 2);
None when there is none. Strings are made one line (testbed.files.resultvalues.one_line).
"""

from __future__ import annotations

import os
import re
from argparse import ArgumentTypeError
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from common import boundedfile
from common.errors import UsageError
from common.jsonfile import write_json_atomic
from testbed.files.resultvalues import one_line

STATE_NAME = "sweep.json"
STATE_FORMAT = 1
RUN_ID = re.compile(r"[A-Za-z0-9._-]{1,100}")
MAX_TEAM = 1000
_EMPTY: Mapping[str, Any] = MappingProxyType({})
# A run's keys that are not its status record (SweepRun.record holds the others, in order).
_RUN_KEYS = ("id", "index", "config")
_WHOLE = ("format", "jobs_requested", "jobs")  # whole numbers
_LIMITS = ("load_limit_requested", "load_limit", "cpu_limit_requested", "cpu_limit")  # > 0


@dataclass(frozen=True)
class SweepRun:
    """One run of the plan: its directory's name, its place in the plan, its options as
    testbed.sweep.rundir.plan_dict records them, and its status record (`status`, `attempts`,
    `pid`, `pid_start`, `reason`, `result_status`, ... in the order the runner set them)."""

    id: str
    index: int | None = None
    config: Mapping[str, Any] | None = None
    record: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)

    @property
    def status(self) -> str | None:
        return self.record.get("status")

    @property
    def reason(self) -> str | None:
        return self.record.get("reason")

    @property
    def pid(self) -> int | None:
        return self.record.get("pid")

    @property
    def pid_start(self) -> Any:
        return self.record.get("pid_start")

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id}
        if self.index is not None:
            out["index"] = self.index
        if self.config is not None:
            out["config"] = dict(self.config)
        out.update(self.record)
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SweepRun:
        """A run of a checked document (see `check`)."""
        return cls(
            id=d["id"], index=d.get("index"), config=d.get("config"),
            record={k: v for k, v in d.items() if k not in _RUN_KEYS},
        )  # fmt: skip


@dataclass(frozen=True)
class SweepState:
    """The whole of sweep.json, its keys in the file's order (see the module's docstring)."""

    format: int | None = STATE_FORMAT
    sweep_file: str | None = None
    spec: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    jobs_requested: int | None = None  # --jobs
    jobs: int | None = None  # the concurrency now (the policy may have lowered it)
    load_limit_requested: float | None = None  # the sweep file's, and what it is now
    load_limit: float | None = None
    cpu_limit_requested: float | None = None  # cores, likewise
    cpu_limit: float | None = None
    time_scale_factor: Mapping[str, float] = field(
        default_factory=lambda: _EMPTY
    )  # team size -> factor of the file's scale
    netem: bool | None = None  # whether sch_netem was there (impairments need it)
    calibration: Mapping[str, Mapping[str, Any]] = field(
        default_factory=lambda: _EMPTY
    )  # team size -> {factor, trials}
    backoffs: tuple[Mapping[str, Any], ...] = ()
    updated: str | None = None
    runs: tuple[SweepRun, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """The document the runner writes (keys in this order; nested values as given)."""
        return {
            "format": self.format,
            "sweep_file": self.sweep_file,
            "spec": dict(self.spec),
            "jobs_requested": self.jobs_requested,
            "jobs": self.jobs,
            "load_limit_requested": self.load_limit_requested,
            "load_limit": self.load_limit,
            "cpu_limit_requested": self.cpu_limit_requested,
            "cpu_limit": self.cpu_limit,
            "time_scale_factor": dict(self.time_scale_factor),
            "netem": self.netem,
            "calibration": dict(self.calibration),
            "backoffs": list(self.backoffs),
            "updated": self.updated,
            "runs": [r.to_dict() for r in self.runs],
        }

    @classmethod
    def from_dict(cls, doc: Any) -> SweepState:
        """The document checked (`check`) with old files' defaults; ValueError naming the
        field when it is not a sweep.json."""
        d = check(doc)
        return cls(
            format=d.get("format"), sweep_file=d.get("sweep_file"),
            spec=MappingProxyType(d["spec"]), jobs_requested=d.get("jobs_requested"),
            jobs=d.get("jobs"), load_limit_requested=d.get("load_limit_requested"),
            load_limit=d.get("load_limit"), cpu_limit_requested=d.get("cpu_limit_requested"),
            cpu_limit=d.get("cpu_limit"),
            time_scale_factor=MappingProxyType(d.get("time_scale_factor") or {}),
            netem=d.get("netem"), calibration=MappingProxyType(d.get("calibration") or {}),
            backoffs=tuple(d.get("backoffs") or ()), updated=d.get("updated"),
            runs=tuple(SweepRun.from_dict(e) for e in d["runs"]),
        )  # fmt: skip

    def run(self, run_id: str) -> SweepRun | None:
        """The planned run `run_id`, None when the plan has none."""
        return next((r for r in self.runs if r.id == run_id), None)

    def spec_value(self, name: str, listed: bool = False) -> Any:
        """Field `name` of the sweep's runs as the spec records it: the grid's values, or the
        one value of [run] (in a list where `listed`). Sweeps before grids were declared per
        option recorded every field at the top level."""
        grid, run = self.spec.get("grid"), self.spec.get("run")
        if not isinstance(grid, dict) or not isinstance(run, dict):
            return self.spec.get(name)
        if name in grid:
            return grid[name]
        return [run.get(name)] if listed else run.get(name)


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
    from testbed.files.options import check_value
    from testbed.files.runconfig import BY_NAME, RunConfig, refusal

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
        run = RunConfig.from_dict(config)
    except (TypeError, ValueError, ArgumentTypeError) as e:
        raise ValueError(f"{where}.config: {one_line(str(e), 120)}") from None
    joint = refusal(run)  # the option rule (not what this machine's programs can carry)
    if joint:
        raise ValueError(f"{where}.config.{joint[0]}: {one_line(joint[1], 160)}")


def _scalars(doc: dict) -> None:
    """ValueError naming the key unless the sweep's scalars are of their kinds (or null)."""
    for key in _WHOLE:
        v = doc.get(key)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v < 0):
            raise ValueError(f"{key} is {one_line(str(v), 40)}, not a whole number")
    for key in _LIMITS:
        v = doc.get(key)
        if v is not None and not (_number(v) and v > 0):
            raise ValueError(f"{key} is {one_line(str(v), 40)}, not a positive number")
    for key, kind in (("netem", bool), ("updated", str)):
        v = doc.get(key)
        if v is not None and not isinstance(v, kind):
            raise ValueError(f"{key} is {type(v).__name__}, not {kind.__name__}")


def check(doc) -> dict:
    """The checked sweep.json document (see the module's docstring); ValueError naming the
    field otherwise."""
    if not isinstance(doc, dict):
        raise ValueError("not a JSON object")
    _scalars(doc)
    fmt = doc.get("format")
    if fmt is not None and fmt != STATE_FORMAT:  # another format's keys: not guessed at
        raise ValueError(f"format {fmt}, but this testbed reads format {STATE_FORMAT}")
    runs = doc.get("runs", [])
    if not isinstance(runs, list):
        raise ValueError("runs is not a list")
    out = dict(doc)
    out["runs"] = []
    first: dict[str, int] = {}  # run id: where the plan has it
    for i, e in enumerate(runs):
        run = _run(i, e)
        if first.setdefault(run["id"], i) != i:
            raise ValueError(f"runs[{i}] names run {run['id']} twice (runs[{first[run['id']]}] "
                             "too): a plan's runs are distinct")  # fmt: skip
        out["runs"].append(run)
    spec = doc.get("spec")
    spec = {} if spec is None else spec
    if not isinstance(spec, dict):
        raise ValueError("spec is not an object")
    for key in ("grid", "run"):
        if spec.get(key) is not None and not isinstance(spec[key], dict):
            raise ValueError(f"spec.{key} is not an object")
    _team_map("spec.time_scale_by_robots", spec.get("time_scale_by_robots"))
    _team_map("time_scale_factor", doc.get("time_scale_factor"))
    backoffs = doc.get("backoffs")
    if backoffs is not None and (
        not isinstance(backoffs, list) or not all(isinstance(b, dict) for b in backoffs)
    ):
        raise ValueError("backoffs is not a list of objects")
    calibration = doc.get("calibration")
    if calibration is not None and (
        not isinstance(calibration, dict)
        or not all(isinstance(c, dict) for c in calibration.values())
    ):
        raise ValueError("calibration is not an object of objects")
    if doc.get("sweep_file") is not None:
        if not isinstance(doc["sweep_file"], str):
            raise ValueError("sweep_file is not a string")
        out["sweep_file"] = one_line(doc["sweep_file"])
    out["spec"] = spec
    return out


def state_path(out: str | Path) -> Path:
    """Where a sweep directory's sweep.json is."""
    return Path(out) / STATE_NAME


def read(out: str | Path) -> SweepState | None:
    """DIR/sweep.json checked (see the module's docstring); None when there is none;
    UsageError (one line naming the file and the field) when it is not one."""
    path = state_path(out)
    if not os.path.lexists(path):
        return None
    try:
        return SweepState.from_dict(boundedfile.load_json(path))
    except boundedfile.Refused as r:
        raise UsageError(f"{path}: {boundedfile.describe(r)}") from None
    except ValueError as e:
        raise UsageError(f"{path}: {e}") from None


def write(out: str | Path, state: SweepState) -> None:
    """DIR/sweep.json holds `state` (atomically: the old file or the new one, never a part)."""
    write_json_atomic(state_path(out), state.to_dict())
