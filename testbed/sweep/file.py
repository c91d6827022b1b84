"""Sweep files: a TOML description of a grid of runs, loaded, validated and expanded.

A sweep file has two tables. `[grid]` lists the values each varied parameter takes; every
combination is a *point*, and each point is run `runs` times. `[run]` holds what stays fixed
for every run of the sweep::

    description = "the paper's Section 5 grid"   # optional, free text

    [grid]
    robots = [1, 2, 3]            # team sizes (required)
    comm_range = [5, 20]          # metres (required)
    laser_range = [2.0]           # metres (required)
    loss_pct = [0, 10, 30]        # optional, default [0]
    delay_ms = [0, 50]            # optional, default [0]; needs sch_netem when > 0
    coordination = ["paper", "ours"]   # optional, default ["ours"] (node.coordination)
    start = ["corner", "spread"]  # optional, default ["corner"]: corner | centre | spread
    routing = ["aodv", "oracle"]  # optional: routing as a grid dimension (then not in [run])
    map = ["empty", "maps/office.png"]  # optional: maps as a grid dimension ("empty": the
                                  # paper's empty terrain; else as run.map)
    medium = ["veth", "ns3-wifi"] # optional: the radio medium as a grid dimension
    middleware = ["nanomsg", "zeromq"]  # optional: the goals' middleware as a grid dimension
    maps = ["flood", "pubsub"]    # optional: how maps are shared, as a grid dimension
    battery_failure = ["none", "midrun"]  # optional: midrun kills robot rN mid-run
                                  # (testbed.files.failures); every team size must be 2 or more
    runs = 1                      # runs per point (any number), default 1

    [run]
    time_scale = 5.0              # default 1.0; or per team size (every size in the grid):
    # time_scale = { 1 = 12.0, 2 = 10.0, 3 = 8.0 }
    load_limit = 60               # optional: runs share the machine while the sum of their
                                  # loads, (robots + 1) x time_scale, stays within this
    cpu_limit = 1.8               # optional: runs share the machine while the sum of their
                                  # estimated cores stays within this (testbed.sweep.cores;
                                  # lowered when a shared run comes out late or unfaithful)
    routing = "aodv"              # aodv | babel | batman | oracle | none, default aodv
    aodv_profile = "rfc"          # rfc | ns3 (AODV parameters), default rfc
    max_steps = 3000              # default 3000
    capture = true                # default false
    map = "maps/office.png"       # optional; relative paths are relative to the sweep file
    range_model = "los"           # disc | lossy | los | los-lossy, default disc
    wall_loss_pct = 30            # optional, with los: a wall costs this loss, not a block
    medium = "ns3-wifi"           # veth | ns3-wifi, default veth (docs/ns3-medium.md)
    wifi_standard = "80211b"      # ns3-wifi only: 80211a | 80211b | 80211g, default 80211a
    wifi_rate = "DsssRate1Mbps"   # ns3-wifi only: an ns-3 WifiMode or minstrel
    wifi_loss = "range"           # ns3-wifi only: range | logdistance
    middleware = "zeromq"         # nanomsg | zeromq | zeromq-reqrep | zenoh | dds, default
                                  # nanomsg (docs/middleware.md)
    maps = "pubsub"               # flood | pubsub, default flood; pubsub needs every
                                  # middleware of the sweep to be zenoh or dds
    battery_failure = "midrun"    # none | midrun, default none
    seed = 0                      # optional base mixed into every derived seed

The keys are the run options marked for sweeps (testbed.files.runconfig: `sweep={GRID}` may be
varied, `sweep={RUN}` fixed), and each value is checked by its option's own rules (type,
bounds, choices), the same as `testbed run` checks the flag; each point of the grid then by
the rule that joins options (testbed.files.runconfig.refusal: a laser shorter than a map cell,
`robot = "cpp"` with a middleware the C++ robot built here does not carry, ...), the same as
`testbed run` checks its options together. Two values of a dimension that a run's id shows
alike (5 and 5.0000001, both `c5`) are refused: they would be two runs of one id.
Validation is strict: an unknown key, a value of the wrong type or an empty grid list is a
`UsageError` whose one-line message names the key (`grid.robots`, `run.time_scale`, ...).

Size: a sweep has at most MAX_RUNS runs, checked from the lengths of the grid's lists and
`runs` before any run is expanded. Why 10,000: `DIR/sweep.json` holds about 380 bytes a run
and is rewritten whenever a run starts or ends (47 us a run here, so 0.5 s at 10,000 runs,
under 2% of a one-minute run), and the planned runs take about 6 kB each in memory; at
100,000 runs sweep.json was 38 MB, rewritten after every run, and a grid of a million runs
took 6.2 GB before its first run. The largest shipped sweep has 600 runs; a larger study is
several sweep files. The file itself is a regular UTF-8 file of at most MAX_FILE_BYTES.

Expansion (`expand`) turns the spec into `PlannedRun`s. A run's id and seed are functions of
its parameters and run index only, so they are the same every time the file is expanded
(a routing, map, medium or middleware grid names its value in every id, `-aodv`,
`-moffice`, `-ns3wifi`, `-zeromqreqrep`; a battery failure only when there is one,
`-midrun`; the variants of a point share their seeds, so protocols, maps, media,
middlewares and failures are compared on the same draws):
that is what lets an interrupted sweep resume without redoing a finished run. Runs are
ordered run index first, so an interrupted sweep has covered every point once before it
covers any point twice.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from common import boundedfile
from common.errors import UsageError
from node.messaging.maps import PUBSUB_MIDDLEWARES
from node.messaging.maps import refusal as maps_refusal
from node.native import TB_ROBOT
from testbed.files import failures
from testbed.files.options import CHANGED, GRID, NONZERO, RUN, VARIED, Option, check_value
from testbed.files.runconfig import BY_NAME, EMPTY_MAP, OPTIONS, RunConfig, fmt
from testbed.run.arguments import refusal
from topology.spec import LOS_MODELS

_TOP_KEYS = {"description", "grid", "run"}
# The run options a sweep file may vary or fix (RunConfig fields marked so), and its own keys:
# grid.runs, run.seed (the base of every derived seed), run.load_limit and run.cpu_limit
# (testbed.sweep.runner).
# The grid's dimensions in their order (GridDim.order): the nesting of the expansion, the
# order of a run id's parts and of a point's values.
_GRID_OPTIONS = tuple(sorted((opt for opt in OPTIONS if GRID in opt.sweep),
                             key=lambda opt: opt.grid_dim.order))  # fmt: skip
GRID_NAMES = tuple(opt.name for opt in _GRID_OPTIONS)
_RUN_OPTIONS = tuple(opt for opt in OPTIONS if RUN in opt.sweep)
_GRID_KEYS = {opt.name for opt in _GRID_OPTIONS} | {"runs"}
_RUN_KEYS = {opt.name for opt in _RUN_OPTIONS} | {"seed", "load_limit", "cpu_limit"}
_GRID_REQUIRED = ("robots", "comm_range", "laser_range")
_DEFAULT = RunConfig(robots=1, comm_range=1.0)  # the required fields always come from the grid
MAX_RUNS = 10_000
MAX_FILE_BYTES = 1 << 20


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file: the grid's dimensions with their values, and a base config
    holding [run]'s values (every run is the base with one value of each dimension)."""

    grid: tuple[tuple[str, tuple], ...]  # (RunConfig field, its values), in GRID_NAMES order
    base: RunConfig = _DEFAULT
    runs: int = 1
    time_scale_by_robots: tuple[tuple[int, float], ...] = ()  # else base.time_scale
    load_limit: float | None = None
    cpu_limit: float | None = None  # cores (testbed.sweep.cores)
    seed_base: int = 0  # [run] seed: mixed into every derived seed
    description: str = ""

    @classmethod
    def of(
        cls,
        *,
        runs: int = 1,
        time_scale_by_robots=(),
        load_limit=None,
        cpu_limit=None,
        seed: int = 0,
        description: str = "",
        **fields,
    ) -> SweepSpec:
        """A spec from keywords, as a sweep file would give them: a tuple is a grid
        dimension's values (robots, comm_range and laser_range are required), anything else
        a [run] value."""  # fmt: skip
        grid = {k: tuple(v) for k, v in fields.items() if isinstance(v, tuple | list)}
        fields = {k: v for k, v in fields.items() if not (k in grid and not grid[k])}
        grid = {k: v for k, v in grid.items() if v}  # an empty list: not a dimension
        unknown = [k for k in grid if k not in GRID_NAMES]
        if unknown:
            raise TypeError(f"{unknown[0]} is not a grid dimension")
        base = replace(_DEFAULT, **{k: v for k, v in fields.items() if k not in grid})
        return cls(tuple((k, grid[k]) for k in GRID_NAMES if k in grid), base, runs,
                   tuple(time_scale_by_robots), load_limit, cpu_limit, seed,
                   description)  # fmt: skip

    def values(self, name: str) -> tuple:
        """The values field `name` takes in this sweep: the grid's, else [run]'s one."""
        return dict(self.grid).get(name, (getattr(self.base, name),))

    def varies(self, name: str) -> bool:
        return name in dict(self.grid)

    def to_dict(self) -> dict:
        """As sweep.json records it: the grid, and every other field of the runs' config."""
        return {
            "grid": {k: list(v) for k, v in self.grid},
            "run": {k: v for k, v in self.base.to_dict().items() if not self.varies(k)},
            "runs": self.runs,
            "time_scale_by_robots": {str(n): v for n, v in self.time_scale_by_robots},
            "load_limit": self.load_limit,
            "cpu_limit": self.cpu_limit,
            "seed": self.seed_base,
            "description": self.description,
        }

    def scale_for(self, robots: int) -> float:
        """The time scale of a run of `robots` robots."""
        return dict(self.time_scale_by_robots).get(robots, self.base.time_scale)


@dataclass(frozen=True)
class PlannedRun:
    """One run of a sweep: its stable id and the config `testbed run` gets."""

    run_id: str
    index: int  # 1-based run index within its point
    config: RunConfig

    @property
    def point(self) -> tuple:
        """The grid point this run belongs to (what its repetitions share)."""
        return tuple(getattr(self.config, name) for name in GRID_NAMES)


def _fail(path: Path | str, key: str, message: str) -> UsageError:
    return UsageError(f"sweep file {path}: {_printable(key)}: {message}")


def _printable(text: str) -> str:
    """A key from the file as a message shows it: a quoted key may hold a newline or a
    terminal's escape sequence, shown escaped so that the message stays one line."""
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return (isinstance(v, int | float)) and not isinstance(v, bool)


def _check_table(path, name: str, table, allowed: set[str]) -> dict:
    if not isinstance(table, dict):
        raise _fail(path, name, f"expected a table, got {type(table).__name__}")
    for key in table:
        if key not in allowed:
            full = f"{name}.{key}" if name else key
            raise _fail(path, full, f"unknown key (allowed: {', '.join(sorted(allowed))})")
    return table


def _value(path, key: str, opt: Option, v):
    """One value of option `opt` from the file, checked by the option's own rules."""
    problem = check_value(opt, v)
    if problem:
        raise _fail(path, key, problem)
    return float(v) if opt.kind is float else v


def _grid_list(path, opt: Option, value) -> tuple:
    """grid.KEY: a non-empty list of distinct values of `opt`."""
    key = f"grid.{opt.name}"
    if not isinstance(value, list):
        raise _fail(path, key, f"expected a list, got {type(value).__name__}")
    if not value:
        raise _fail(path, key, "empty list: the grid needs at least one value")
    out = tuple(_value(path, key, opt, v) for v in value)
    if len(set(out)) != len(out):
        raise _fail(path, key, f"duplicate values in {value!r}")
    return out


def _positive(path, key: str, v) -> float:
    """A limit (load, cores): TOML's inf and nan are numbers too, but no machine has them."""
    if not _is_number(v):
        raise _fail(path, key, f"expected a number, got {v!r}")
    if not math.isfinite(v):
        raise _fail(path, key, f"expected a finite number, got {v}")
    if v <= 0:
        raise _fail(path, key, f"must be > 0, got {v}")
    return float(v)


def _scale_table(path, table: dict, robots: tuple[int, ...]) -> tuple[tuple[int, float], ...]:
    """`time_scale = { 1 = 12.0, 2 = 10.0 }`: a time scale for each team size of the grid."""
    out = {}
    for key, v in table.items():
        if not (key.isascii() and key.isdigit()) or int(key) < 1:
            raise _fail(path, f"run.time_scale.{key}", "keys are team sizes (1, 2, ...)")
        out[int(key)] = _value(path, f"run.time_scale.{key}", BY_NAME["time_scale"], v)
    missing = [n for n in robots if n not in out]
    if missing:
        raise _fail(path, "run.time_scale", f"no entry for team size {missing[0]}")
    return tuple(sorted(out.items()))


def _description(path, data: dict) -> str:
    description = data.get("description", "")
    if not isinstance(description, str):
        raise _fail(path, "description", f"expected a string, got {type(description).__name__}")
    return description


def _check_size(path, grid: dict) -> None:
    """At most MAX_RUNS runs, from the lengths of the grid's lists and `runs` alone (before
    any value is checked or any run expanded)."""
    lengths = {k: len(v) for k, v in grid.items() if isinstance(v, list)}
    runs = grid.get("runs", 1)
    total = math.prod(lengths.values()) * (runs if _is_int(runs) and runs > 0 else 1)
    if total > MAX_RUNS:
        sizes = " x ".join(f"{n} {k}" for k, n in lengths.items() if n > 1)
        raise _fail(
            path, "grid", f"{total:,} runs ({sizes or 'one point'}"
            f"{f' x {runs} runs' if _is_int(runs) and runs > 1 else ''}); a sweep has at most "
            f"{MAX_RUNS:,}: split it into several sweep files",
        )  # fmt: skip


def _distinct_ids(path, opt: Option, values: tuple) -> None:
    """Two values of a grid dimension that a run's id shows alike (5 and 5.0000001 are both
    `c5`, maps/office.png and old/office.png both `moffice`) would make two runs of one id,
    the second taken for done when the first is: refused, naming both."""
    seen: dict[str, Any] = {}
    for v in values:
        label = opt.grid_dim.label(v)
        if label in seen:
            raise _fail(path, f"grid.{opt.name}", f"{seen[label]!r} and {v!r} are both "
                        f"{label!r} in a run's id: one's runs would be the other's")  # fmt: skip
        seen[label] = v


def _grid(path, grid: dict, run: dict) -> dict:
    """[grid]'s dimensions (field: values) and `runs`."""
    _check_size(path, grid)
    for key in _GRID_REQUIRED:
        if key not in grid:
            raise _fail(path, f"grid.{key}", "missing (the grid needs at least one value)")
    kw: dict = {}
    for opt in _GRID_OPTIONS:
        if opt.name not in grid:
            continue
        if opt.name in run:
            raise _fail(path, f"run.{opt.name}", f"already a grid dimension (grid.{opt.name})")
        values = _grid_list(path, opt, grid[opt.name])
        if opt.name == "map":
            values = tuple(None if m == EMPTY_MAP else _map_path(path, m) for m in values)
        _distinct_ids(path, opt, values)
        kw[opt.name] = values
    if "runs" in grid:
        runs = grid["runs"]
        if not _is_int(runs) or runs < 1:
            raise _fail(path, "grid.runs", f"expected a whole number >= 1, got {runs!r}")
        kw["runs"] = runs
    return kw


def _run(path, run: dict, grid: dict, robots: tuple[int, ...]) -> dict:
    """[run]'s values (RunConfig fields) and the sweep's own keys."""
    kw: dict = {}
    for opt in _RUN_OPTIONS:
        if opt.name not in run:
            continue
        if opt.name == "time_scale" and isinstance(run["time_scale"], dict):
            kw["time_scale_by_robots"] = _scale_table(path, run["time_scale"], robots)
        else:
            kw[opt.name] = _value(path, f"run.{opt.name}", opt, run[opt.name])
    if "map" in kw:
        kw["map"] = _map_path(path, kw["map"])
    if "wall_loss_pct" in kw and kw.get("range_model", "disc") not in LOS_MODELS:
        raise _fail(path, "run.wall_loss_pct", "needs range_model los or los-lossy")
    wifi = [k for k in ("wifi_loss", "wifi_standard", "wifi_rate") if k in run]
    if wifi and "ns3-wifi" not in (grid.get("medium") or [run.get("medium", _DEFAULT.medium)]):
        raise _fail(path, f"run.{wifi[0]}", "needs medium ns3-wifi (in [run] or grid.medium)")
    maps = grid.get("maps") or [run.get("maps", _DEFAULT.maps)]
    if "pubsub" in maps:
        for middleware in grid.get("middleware") or [run.get("middleware", _DEFAULT.middleware)]:
            if maps_refusal("pubsub", middleware):
                where = "grid.maps" if "maps" in grid else "run.maps"
                need = " or ".join(PUBSUB_MIDDLEWARES)
                raise _fail(path, where, f"pubsub needs middleware {need} (the sweep has "
                            f"{middleware})")  # fmt: skip
    if "load_limit" in run:
        kw["load_limit"] = _positive(path, "run.load_limit", run["load_limit"])
    if "cpu_limit" in run:
        kw["cpu_limit"] = _positive(path, "run.cpu_limit", run["cpu_limit"])
    if "seed" in run:
        if not _is_int(run["seed"]):
            raise _fail(path, "run.seed", f"expected an integer, got {run['seed']!r}")
        kw["seed"] = run["seed"]
    return kw


def parse(data: dict, path: Path | str = "<string>") -> SweepSpec:
    """Validate the parsed TOML `data` and return its SweepSpec (UsageError if invalid)."""
    _check_table(path, "", data, _TOP_KEYS)
    if "grid" not in data:
        raise _fail(path, "grid", "missing table [grid]")
    grid = _check_table(path, "grid", data["grid"], _GRID_KEYS)
    run = _check_table(path, "run", data.get("run", {}), _RUN_KEYS)
    kw: dict[str, Any] = {"description": _description(path, data)}
    kw.update(_grid(path, grid, run))
    kw.update(_run(path, run, grid, kw["robots"]))
    spec = SweepSpec.of(**kw)
    for failure in spec.values("battery_failure"):
        why = failures.refusal(failure, min(spec.values("robots")))
        if why:
            where = "grid" if spec.varies("battery_failure") else "run"
            raise _fail(path, f"{where}.battery_failure", why.replace("--battery-failure ", ""))
    _check_points(path, spec)
    return spec


def _check_points(path, spec: SweepSpec) -> None:
    """Each point of the grid by the rule `testbed run` checks its options with
    (testbed.run.arguments.refusal: a laser shorter than a map cell, a robot program that
    cannot carry the run, ...), so that no run of the sweep is refused when its turn comes.
    The robot program is checked where the C++ robot is built (as the run asks it); where it
    is not, every run that asks for it is refused at its start, as a lone run is."""
    built = TB_ROBOT.is_file()
    names = [name for name, _ in spec.grid]
    for values in itertools.product(*(v for _, v in spec.grid)):
        config = replace(spec.base, **dict(zip(names, values, strict=True)))
        why = refusal(config, program=built)
        if why:
            option, line = why
            raise _fail(path, f"{'grid' if spec.varies(option) else 'run'}.{option}", line)


def _map_path(path, m: str) -> str:
    """A map path as given, relative paths taken relative to the sweep file."""
    mp = Path(m)
    if not mp.is_absolute() and isinstance(path, Path):
        mp = path.parent / mp
    return str(mp)


def load(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file (UsageError with one line if it is bad)."""
    path = Path(path)
    text = _read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise UsageError(f"sweep file {path}: invalid TOML: {e}") from None
    except RecursionError:
        raise UsageError(f"sweep file {path}: invalid TOML: nested too deeply") from None
    return parse(data, path)


def _read_text(path: Path) -> str:
    """The file's text: a regular UTF-8 file of at most MAX_FILE_BYTES (a FIFO or a device
    is refused without waiting on it)."""
    try:
        data = boundedfile.read(path, MAX_FILE_BYTES)
    except boundedfile.Refused as r:
        if r.kind == "directory":
            raise UsageError(f"sweep file {path}: is a directory") from None
        if r.kind in ("special", "too_big"):
            raise UsageError(f"sweep file {path}: not a regular file of at most "
                             f"{MAX_FILE_BYTES >> 20} MiB") from None  # fmt: skip
        why = r.detail if r.kind == "unreadable" else "No such file or directory"
        raise UsageError(f"sweep file {path}: cannot read: {why}") from None
    try:
        text = data.decode()
    except UnicodeDecodeError as e:
        raise UsageError(f"sweep file {path}: not a text file (UTF-8 TOML): byte "
                         f"{e.start} is 0x{data[e.start]:02x}") from None  # fmt: skip
    if text.startswith("\ufeff"):
        raise UsageError(f"sweep file {path}: starts with a byte-order mark (BOM), which TOML "
                         "does not allow: save it as UTF-8 without one")  # fmt: skip
    return text


def run_id(config: RunConfig, index: int, varied=frozenset()) -> str:
    """Stable, readable id of one run, from the grid's dimensions in their order (each
    option's GridDim): impairments appear only when non-zero, coordination and start
    placement only when not the default, routing, map and medium only where the sweep
    varies them (`varied`); so ids of older sweeps stay valid."""
    parts = []
    for opt in _GRID_OPTIONS:
        value, dim = getattr(config, opt.name), opt.grid_dim
        if ((dim.shown == NONZERO and not value) or (dim.shown == CHANGED and value == opt.default)
                or (dim.shown == VARIED and opt.name not in varied)):  # fmt: skip
            continue
        parts.append(dim.label(value))
    return "-".join([*parts, f"k{index}"])


def derive_seed(base: int, config: RunConfig, index: int) -> int:
    """A seed that depends only on the point's seeded dimensions (GridDim.seeded), the run
    index and the file's base seed: the variants of a point (coordination, start, routing,
    map, medium) share their random numbers, so they are compared on the same draws."""
    words = [str(base)]
    for opt in _GRID_OPTIONS:
        if opt.grid_dim.seeded:
            value = getattr(config, opt.name)
            words.append(fmt(value) if isinstance(value, float) else str(value))
    key = ":".join([*words, str(index)])
    return int(hashlib.sha256(key.encode()).hexdigest()[:8], 16) % (2**31 - 1) + 1


_WIFI = ("wifi_loss", "wifi_standard", "wifi_rate")


def expand(spec: SweepSpec) -> list[PlannedRun]:
    """All runs of the sweep, run index first (see the module docstring): each the base
    config with one value of every dimension, its seed and its time scale."""
    varied = {name for name, _ in spec.grid}
    # On veth, which has no 802.11, the wifi options stay the defaults (config.json does not
    # claim one); on ns3-wifi they are the file's.
    veth_wifi = {k: getattr(_DEFAULT, k) for k in _WIFI}
    out = []
    for index in range(1, spec.runs + 1):
        for values in itertools.product(*(spec.values(name) for name in GRID_NAMES)):
            config = replace(spec.base, **dict(zip(GRID_NAMES, values, strict=True)))
            if config.medium != "ns3-wifi":
                config = replace(config, **veth_wifi)
            config = replace(config, seed=derive_seed(spec.seed_base, config, index),
                             time_scale=spec.scale_for(config.robots))  # fmt: skip
            out.append(PlannedRun(run_id(config, index, varied), index, config))
    return out
