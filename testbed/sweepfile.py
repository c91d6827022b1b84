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
    runs = 1                      # runs per point (any number), default 1

    [run]
    time_scale = 5.0              # default 1.0; or per team size (every size in the grid):
    # time_scale = { 1 = 12.0, 2 = 10.0, 3 = 8.0 }
    load_limit = 60               # optional: runs share the machine while the sum of their
                                  # loads, (robots + 1) x time_scale, stays within this
    routing = "aodv"              # aodv | babel | batman | oracle | none, default aodv
    aodv_profile = "rfc"          # rfc | ns3 (AODV parameters), default rfc
    max_steps = 3000              # default 3000
    capture = true                # default false
    map = "maps/office.png"       # optional; relative paths are relative to the sweep file
    range_model = "los"           # disc | lossy | los | los-lossy, default disc
    wall_loss_pct = 30            # optional, with los: a wall costs this loss, not a block
    seed = 0                      # optional base mixed into every derived seed

Validation is strict: an unknown key, a value of the wrong type or an empty grid list is a
`UsageError` whose one-line message names the key (`grid.robots`, `run.time_scale`, ...).

Expansion (`expand`) turns the spec into `PlannedRun`s. A run's id and seed are functions of
its parameters and run index only, so they are the same every time the file is expanded
(a routing or map grid names its value in every id, `-aodv`, `-moffice`; the variants of a
point share their seeds, so protocols and maps are compared on the same draws):
that is what lets an interrupted sweep resume without redoing a finished run. Runs are
ordered run index first, so an interrupted sweep has covered every point once before it
covers any point twice.
"""

from __future__ import annotations

import hashlib
import itertools
import tomllib
from dataclasses import asdict, dataclass
from pathlib import Path

from node.coordination import DEFAULT as DEFAULT_COORDINATION
from node.coordination import MODES as COORDINATION_MODES
from testbed.errors import UsageError
from testbed.world.worldmap import START_PLACEMENTS
from topology.spec import AODV_PROFILES, LOS_MODELS, RANGE_MODELS

ROUTINGS = ("aodv", "babel", "batman", "oracle", "none")

_TOP_KEYS = {"description", "grid", "run"}
_GRID_LISTS = ("robots", "comm_range", "laser_range", "loss_pct", "delay_ms")
# Grid lists of names, with the names each allows and its default.
_GRID_CHOICES = {
    "coordination": (COORDINATION_MODES, DEFAULT_COORDINATION),
    "start": (START_PLACEMENTS, "corner"),
}
_GRID_KEYS = set(_GRID_LISTS) | set(_GRID_CHOICES) | {"runs", "routing", "map"}
_RUN_KEYS = {
    "time_scale", "routing", "aodv_profile", "max_steps", "capture", "map", "seed", "load_limit",
    "range_model", "wall_loss_pct",
}  # fmt: skip
EMPTY_MAP = "empty"  # grid.map: the paper's empty terrain


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file."""

    robots: tuple[int, ...]
    comm_range: tuple[float, ...]
    laser_range: tuple[float, ...]
    loss_pct: tuple[float, ...] = (0.0,)
    delay_ms: tuple[float, ...] = (0.0,)
    coordination: tuple[str, ...] = (DEFAULT_COORDINATION,)
    start: tuple[str, ...] = ("corner",)
    runs: int = 1
    time_scale: float = 1.0  # for team sizes without an entry in time_scale_by_robots
    time_scale_by_robots: tuple[tuple[int, float], ...] = ()
    load_limit: float | None = None
    routing: str = "aodv"
    aodv_profile: str = "rfc"
    max_steps: int = 3000
    capture: bool = False
    map: str | None = None
    routings: tuple[str, ...] = ()  # grid.routing: routing as a dimension (overrides routing)
    maps: tuple[str | None, ...] = ()  # grid.map: None is the empty terrain
    range_model: str = "disc"
    wall_loss_pct: float | None = None
    seed: int = 0
    description: str = ""

    def to_dict(self) -> dict:
        d = asdict(self)
        d["time_scale_by_robots"] = {str(n): v for n, v in self.time_scale_by_robots}
        return d

    def scale_for(self, robots: int) -> float:
        """The time scale of a run of `robots` robots."""
        return dict(self.time_scale_by_robots).get(robots, self.time_scale)


@dataclass(frozen=True)
class PlannedRun:
    """One run of a sweep: its stable id and the config `testbed run` gets."""

    run_id: str
    index: int  # 1-based run index within its point
    config: dict

    @property
    def point(self) -> tuple:
        """The grid point this run belongs to (what its repetitions share)."""
        c = self.config
        return (c["robots"], c["comm_range"], c["laser_range"], c["loss_pct"], c["delay_ms"],
                c["coordination"], c["start"], c["routing"], c["map"])  # fmt: skip


def _fail(path: Path | str, key: str, message: str) -> UsageError:
    return UsageError(f"sweep file {path}: {key}: {message}")


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


def _number_list(path, key: str, value, *, integer: bool, low: float, low_open: bool, high=None):
    kind = "integers" if integer else "numbers"
    if not isinstance(value, list):
        raise _fail(path, key, f"expected a list of {kind}, got {type(value).__name__}")
    if not value:
        raise _fail(path, key, "empty list: the grid needs at least one value")
    out = []
    for v in value:
        ok = _is_int(v) if integer else _is_number(v)
        if not ok:
            raise _fail(path, key, f"expected a list of {kind}, got element {v!r}")
        if v < low or (low_open and v == low) or (high is not None and v > high):
            bound = f"> {low}" if low_open else f">= {low}"
            if high is not None:
                bound += f" and <= {high}"
            raise _fail(path, key, f"value {v!r} out of range (must be {bound})")
        out.append(int(v) if integer else float(v))
    if len(set(out)) != len(out):
        raise _fail(path, key, f"duplicate values in {value!r}")
    return tuple(out)


def _positive(path, key: str, v) -> float:
    if not _is_number(v):
        raise _fail(path, key, f"expected a number, got {v!r}")
    if v <= 0:
        raise _fail(path, key, f"must be > 0, got {v}")
    return float(v)


def _count(path, key: str, v) -> int:
    """A whole number of at least 1 (runs per point, a step cap)."""
    if not _is_int(v):
        raise _fail(path, key, f"expected an integer, got {v!r}")
    if v < 1:
        raise _fail(path, key, f"must be >= 1, got {v}")
    return v


def _choice_list(path, key: str, value, allowed: tuple[str, ...]) -> tuple[str, ...]:
    """A non-empty list of distinct names, each one of `allowed`."""
    if not isinstance(value, list) or not value:
        raise _fail(path, key, f"expected a non-empty list of names, got {value!r}")
    for v in value:
        if v not in allowed:
            raise _fail(path, key, f"{v!r} is not one of {', '.join(allowed)}")
    if len(set(value)) != len(value):
        raise _fail(path, key, f"duplicate values in {value!r}")
    return tuple(value)


def _scale_table(path, table: dict, robots: tuple[int, ...]) -> tuple[tuple[int, float], ...]:
    """`time_scale = { 1 = 12.0, 2 = 10.0 }`: a time scale for each team size of the grid."""
    out = {}
    for key, v in table.items():
        if not key.isdigit() or int(key) < 1:
            raise _fail(path, f"run.time_scale.{key}", "keys are team sizes (1, 2, ...)")
        out[int(key)] = _positive(path, f"run.time_scale.{key}", v)
    missing = [n for n in robots if n not in out]
    if missing:
        raise _fail(path, "run.time_scale", f"no entry for team size {missing[0]}")
    return tuple(sorted(out.items()))


def parse(data: dict, path: Path | str = "<string>") -> SweepSpec:
    """Validate the parsed TOML `data` and return its SweepSpec (UsageError if invalid)."""
    _check_table(path, "", data, _TOP_KEYS)
    if "grid" not in data:
        raise _fail(path, "grid", "missing table [grid]")
    grid = _check_table(path, "grid", data["grid"], _GRID_KEYS)
    run = _check_table(path, "run", data.get("run", {}), _RUN_KEYS)
    kw: dict = {}

    description = data.get("description", "")
    if not isinstance(description, str):
        raise _fail(path, "description", f"expected a string, got {type(description).__name__}")
    kw["description"] = description

    for key in ("robots", "comm_range", "laser_range"):
        if key not in grid:
            raise _fail(path, f"grid.{key}", "missing (the grid needs at least one value)")
    kw["robots"] = _number_list(
        path, "grid.robots", grid["robots"], integer=True, low=1, low_open=False
    )
    for key in ("comm_range", "laser_range"):
        kw[key] = _number_list(path, f"grid.{key}", grid[key], integer=False, low=0, low_open=True)
    if "loss_pct" in grid:
        kw["loss_pct"] = _number_list(
            path, "grid.loss_pct", grid["loss_pct"], integer=False, low=0, low_open=False, high=100
        )
    if "delay_ms" in grid:
        kw["delay_ms"] = _number_list(
            path, "grid.delay_ms", grid["delay_ms"], integer=False, low=0, low_open=False
        )
    for key, (allowed, _default) in _GRID_CHOICES.items():
        if key in grid:
            kw[key] = _choice_list(path, f"grid.{key}", grid[key], allowed)
    if "runs" in grid:
        kw["runs"] = _count(path, "grid.runs", grid["runs"])
    if "routing" in grid:
        if "routing" in run:
            raise _fail(path, "run.routing", "routing is already a grid dimension (grid.routing)")
        kw["routings"] = _choice_list(path, "grid.routing", grid["routing"], ROUTINGS)
    if "map" in grid:
        if "map" in run:
            raise _fail(path, "run.map", "the map is already a grid dimension (grid.map)")
        value = grid["map"]
        if (
            not isinstance(value, list)
            or not value
            or not all(isinstance(m, str) and m for m in value)
        ):
            raise _fail(path, "grid.map", f"expected a non-empty list of paths, got {value!r}")
        if len(set(value)) != len(value):
            raise _fail(path, "grid.map", f"duplicate values in {value!r}")
        kw["maps"] = tuple(None if m == EMPTY_MAP else _map_path(path, m) for m in value)

    if "time_scale" in run:
        ts = run["time_scale"]
        if isinstance(ts, dict):
            kw["time_scale_by_robots"] = _scale_table(path, ts, kw["robots"])
        else:
            kw["time_scale"] = _positive(path, "run.time_scale", ts)
    if "load_limit" in run:
        kw["load_limit"] = _positive(path, "run.load_limit", run["load_limit"])
    for key, allowed in (
        ("routing", ROUTINGS), ("aodv_profile", AODV_PROFILES), ("range_model", RANGE_MODELS),
    ):  # fmt: skip
        if key in run:
            if run[key] not in allowed:
                raise _fail(
                    path, f"run.{key}", f"expected one of {', '.join(allowed)}, got {run[key]!r}"
                )
            kw[key] = run[key]
    if "max_steps" in run:
        kw["max_steps"] = _count(path, "run.max_steps", run["max_steps"])
    if "capture" in run:
        if not isinstance(run["capture"], bool):
            raise _fail(path, "run.capture", f"expected true or false, got {run['capture']!r}")
        kw["capture"] = run["capture"]
    if "map" in run:
        m = run["map"]
        if not isinstance(m, str) or not m:
            raise _fail(path, "run.map", f"expected a non-empty path string, got {m!r}")
        kw["map"] = _map_path(path, m)
    if "wall_loss_pct" in run:
        v = run["wall_loss_pct"]
        if not _is_number(v) or not 0 <= v <= 100:
            raise _fail(path, "run.wall_loss_pct", f"expected a number in 0..100, got {v!r}")
        if kw.get("range_model", "disc") not in LOS_MODELS:
            raise _fail(path, "run.wall_loss_pct", "needs range_model los or los-lossy")
        kw["wall_loss_pct"] = float(v)
    if "seed" in run:
        if not _is_int(run["seed"]):
            raise _fail(path, "run.seed", f"expected an integer, got {run['seed']!r}")
        kw["seed"] = run["seed"]
    return SweepSpec(**kw)


def _map_path(path, m: str) -> str:
    """A map path as given, relative paths taken relative to the sweep file."""
    mp = Path(m)
    if not mp.is_absolute() and isinstance(path, Path):
        mp = path.parent / mp
    return str(mp)


def map_label(m: str | None) -> str:
    """The name a map has in run ids: `empty`, or the file's stem (letters and digits)."""
    return EMPTY_MAP if m is None else "".join(ch for ch in Path(m).stem if ch.isalnum())


def load(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file (UsageError with one line if it is bad)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise UsageError(f"sweep file {path}: cannot read: {e.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise UsageError(f"sweep file {path}: invalid TOML: {e}") from None
    return parse(data, path)


def fmt(x: float) -> str:
    """A number as it appears in run ids: 10.0 -> '10', 1.5 -> '1.5'."""
    return f"{x:g}"


def run_id(
    robots: int,
    comm_range: float,
    laser_range: float,
    loss_pct: float,
    delay_ms: float,
    index: int,
    coordination: str = DEFAULT_COORDINATION,
    start: str = "corner",
) -> str:
    """Stable, readable id of one run; impairments appear only when non-zero, coordination
    and start placement only when not the default (so ids of older sweeps stay valid)."""
    rid = f"n{robots:02d}-c{fmt(comm_range)}-l{fmt(laser_range)}"
    if loss_pct:
        rid += f"-p{fmt(loss_pct)}"
    if delay_ms:
        rid += f"-d{fmt(delay_ms)}"
    if coordination != _GRID_CHOICES["coordination"][1]:
        rid += f"-{coordination}"
    if start != _GRID_CHOICES["start"][1]:
        rid += f"-{start}"
    return f"{rid}-k{index}"


def derive_seed(
    base: int,
    robots: int,
    comm_range: float,
    laser_range: float,
    loss_pct: float,
    delay_ms: float,
    index: int,
) -> int:
    """A seed that depends only on the point, the run index and the file's base seed."""
    key = ":".join(
        [str(base), str(robots), fmt(comm_range), fmt(laser_range), fmt(loss_pct), fmt(delay_ms)]
        + [str(index)]
    )
    return int(hashlib.sha256(key.encode()).hexdigest()[:8], 16) % (2**31 - 1) + 1


def expand(spec: SweepSpec) -> list[PlannedRun]:
    """All runs of the sweep, run index first (see the module docstring)."""
    out = []
    routings = spec.routings or (spec.routing,)
    maps = spec.maps or (spec.map,)
    for index in range(1, spec.runs + 1):
        for robots, comm, laser, loss, delay, coord, start, routing, map_ in itertools.product(
            spec.robots, spec.comm_range, spec.laser_range, spec.loss_pct, spec.delay_ms,
            spec.coordination, spec.start, routings, maps,
        ):  # fmt: skip
            # The seed leaves coordination and start out: the variants of a point share their
            # random numbers (start positions within a placement, timer phases), so they are
            # compared on the same draws.
            config = {
                "robots": robots,
                "comm_range": comm,
                "laser_range": laser,
                "seed": derive_seed(spec.seed, robots, comm, laser, loss, delay, index),
                "time_scale": spec.scale_for(robots),
                "routing": routing,
                "map": map_,
                "loss_pct": loss,
                "delay_ms": delay,
                "capture": spec.capture,
                "max_steps": spec.max_steps,
                "coordination": coord,
                "start": start,
            }
            # Only when chosen, so that the plans of older sweeps stay as they were.
            if spec.aodv_profile != "rfc":
                config["aodv_profile"] = spec.aodv_profile
            if spec.range_model != "disc":
                config["range_model"] = spec.range_model
            if spec.wall_loss_pct is not None:
                config["wall_loss_pct"] = spec.wall_loss_pct
            rid = run_id(robots, comm, laser, loss, delay, index, coord, start)
            if spec.routings or spec.maps:
                base = rid[: -len(f"-k{index}")]
                if spec.routings:
                    base += f"-{routing}"
                if spec.maps:
                    base += f"-m{map_label(map_)}"
                rid = f"{base}-k{index}"
            out.append(PlannedRun(rid, index, config))
    return out
