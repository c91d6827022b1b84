"""result.json as one type: `RunResult`, which testbed.run.results writes and everyone reads.

Theory of operation. A run's result.json (docs/run-results.md says what every key means) is
written by one module and read by many: the run's own last line, the sweep (is a run done,
how did it fare, how much CPU did it take), Slurm tasks, the replay, the causality check,
the benchmarks and the whole analysis. All of them go through this module: testbed.run.results
builds a `RunResult` and writes `to_json()`; the readers call `RunResult.from_json(path or
dict)` (or `read`, which answers None where a reader must carry on past a bad file) and use
its fields and properties. Nobody else spells the file's name or picks its keys out of
nested dicts (tests/unit/test_result_file.py holds this).

- `to_json()` gives the keys in the order of the fields, which is the file's order, so a
  result written from a `RunResult` is what the run wrote before the type existed.
- `from_json` checks what it reads: a key the readers cannot do without (the status, the
  team size and both ranges) missing, or any key of the wrong type, is a `ResultError`, one
  line naming the file and the key.
- Keys that files written by older versions lack get their defaults here and only here:
  `routing` aodv, `map` none (the empty terrain), `loss_pct` and `delay_ms` 0,
  `coordination` ours and `start` corner (before those existed, they were all there was),
  no robot stopped (before `--kill` stopped robots, `mean_finish_step_robots` and
  `survivors_finished` are None), no radio outage, no fidelity verdict; in config's `extra`,
  middleware nanomsg, maps flood, no battery failure, a 400 x 400 map of CELL_M cells.
- Values keep the type JSON gave them (an int stays an int), so the numbers written from
  them are those the file holds. The diagnostic records that only people and the report's
  text read whole (wall_parts_s, world_timing_s, display, cpu_s, fidelity, network_timers)
  are kept as read-only mappings, with properties for what code asks of them.
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from common import boundedfile
from node import messaging
from testbed.analysis import resultcheck
from testbed.run.failures import NONE as NO_FAILURE
from topology.spec import CELL_M, VETH

RESULT_NAME = "result.json"
RESULT_FORMAT = 1
# The keys of config.json that result.json repeats under "config" (the rest: under "extra").
CONFIG_KEYS = (
    "robots", "comm_range", "laser_range", "seed", "time_scale", "routing", "map", "loss_pct",
    "delay_ms", "capture", "max_steps", "coordination", "start",
)  # fmt: skip
DEFAULT_VARIANT = ("ours", "corner")  # (coordination, start) of runs that did not say
DEFAULT_ROUTING = "aodv"
DEFAULT_MEDIUM = VETH
# The processes whose CPU seconds cpu_s holds (testbed.run.results.cpu_seconds).
CPU_PARTS = ("robots", "display", "world", "routing")
_EMPTY: Mapping[str, Any] = MappingProxyType({})
_NUM = (int, float)


class ResultError(ValueError):
    """A result.json that cannot be read as one; str() is one line (naming the file when
    it was read from one)."""


def result_path(run_dir: str | Path) -> Path:
    """Where a run directory's result.json is (the run's completion marker)."""
    return Path(run_dir) / RESULT_NAME


def has_result(run_dir: str | Path) -> bool:
    """Whether the run in `run_dir` finished (its result.json exists, whatever it says)."""
    return result_path(run_dir).is_file()


# ---------------------------------------------------------------- checked reading


def one_line(text: str, limit: int = 500) -> str:
    """`text` as one printable line: a control character (newline, ESC, ...) shown as its
    Python escape, so that neither a report's markdown nor a terminal takes it as markup;
    at most `limit` characters (an ellipsis marks the cut)."""
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return out if len(out) <= limit else out[: limit - 1] + "…"


def _one_lines(value: Any) -> Any:
    """A record's strings, nested ones included, each made one line (one_line)."""
    if isinstance(value, str):
        return one_line(value)
    if isinstance(value, Mapping):
        return {one_line(str(k)): _one_lines(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_one_lines(v) for v in value]
    return value


def _get(
    doc: Mapping[str, Any],
    key: str,
    kinds: tuple[type, ...],
    default: Any = None,
    required: bool = False,
) -> Any:
    """doc[key] checked against `kinds` (bool is not a number); default when absent or null."""
    value = doc.get(key)
    if value is None:
        if required:
            raise ResultError(f"no {key!r}")
        return default
    number = kinds in ((int,), _NUM)
    if not isinstance(value, kinds) or (number and isinstance(value, bool)):
        want = " or ".join(k.__name__ for k in kinds)
        raise ResultError(f"{key!r} is {type(value).__name__}, not {want}")
    return one_line(value) if isinstance(value, str) else value


def _mapping(doc: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    value = doc.get(key)
    if value is None:
        return _EMPTY
    if not isinstance(value, Mapping):
        raise ResultError(f"{key!r} is {type(value).__name__}, not an object")
    return MappingProxyType(_one_lines(dict(value)))


def _list(doc: Mapping[str, Any], key: str) -> list[Any]:
    value = doc.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise ResultError(f"{key!r} is {type(value).__name__}, not a list")
    return value


def _plain(value: Any) -> Any:
    """A value as JSON holds it: mappings as dicts, tuples as lists, dataclasses by to_dict."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


# ---------------------------------------------------------------- the parts


@dataclass(frozen=True)
class Plan:
    """One plan generation of a robot: the step it happened at and why (start, timer,
    request; None when the record does not say)."""

    step: int
    cause: str | None

    def to_dict(self) -> dict[str, Any]:
        return {"step": self.step, "cause": self.cause}


@dataclass(frozen=True)
class RobotResult:
    """One robot's entry in result.json's `robots`."""

    name: str  # "rK"
    finish_step: int | None
    crashed: bool
    plans: tuple[Plan, ...] = ()
    sent: Mapping[str, int] = field(default_factory=lambda: _EMPTY)  # messages, by kind
    received: Mapping[str, int] = field(default_factory=lambda: _EMPTY)
    path_length_m: float | None = None
    stopped_step: int | None = None  # the run killed it on purpose at this step (--kill)
    exit_status: int | None = None

    @property
    def number(self) -> int:
        """K of robot "rK" (0 for a name that is not one)."""
        try:
            return int(self.name.lstrip("r"))
        except ValueError:
            return 0

    @property
    def counted(self) -> bool:
        """Whether the averages over robots count it: every robot but a stopped one."""
        return self.stopped_step is None

    def to_dict(self) -> dict[str, Any]:
        return {
            "finish_step": self.finish_step,
            "crashed": self.crashed,
            "stopped_step": self.stopped_step,
            "exit_status": self.exit_status,
            "plans": [p.to_dict() for p in self.plans],
            "messages": {"sent": dict(self.sent), "received": dict(self.received)},
            "path_length_m": self.path_length_m,
        }

    @classmethod
    def from_dict(cls, name: str, doc: object) -> RobotResult:
        if not isinstance(doc, Mapping):
            raise ResultError(f"robot {name} is not an object")
        plans = doc.get("plans") or []
        if not isinstance(plans, list):
            raise ResultError(f"robot {name}: 'plans' is not a list")
        try:
            plans = tuple(Plan(_get(p, "step", _NUM, required=True), _get(p, "cause", (str,)))
                          for p in plans)  # fmt: skip
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise ResultError(f"robot {name}: a plan without a step ({e})") from None
        messages = _mapping(doc, "messages")
        return cls(
            name=name,
            finish_step=_get(doc, "finish_step", _NUM),
            crashed=bool(doc.get("crashed")),
            plans=plans,
            sent=_mapping(messages, "sent"),
            received=_mapping(messages, "received"),
            path_length_m=_get(doc, "path_length_m", _NUM),
            stopped_step=_get(doc, "stopped_step", (int,)),
            exit_status=_get(doc, "exit_status", (int,)),
        )


@dataclass(frozen=True)
class ResultConfig:
    """result.json's `config`: what the run was asked to do, defaults applied."""

    robots: int
    comm_range: float
    laser_range: float
    time_scale: float | None = None
    routing: str = DEFAULT_ROUTING
    map: str | None = None
    loss_pct: float = 0.0
    delay_ms: float = 0.0
    coordination: str = DEFAULT_VARIANT[0]
    start: str = DEFAULT_VARIANT[1]
    seed: int | None = None
    capture: bool = False
    max_steps: int | None = None
    medium: str = DEFAULT_MEDIUM  # from `extra`
    wifi_standard: str | None = None  # ns3-wifi only (None: the run did not say)
    wifi_rate: str | None = None  # ns3-wifi only; "" is the standard's fastest
    extra: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)  # the rest of config.json

    @property
    def map_name(self) -> str:
        """The map's file stem, or "empty" for the empty terrain."""
        return "empty" if not self.map else Path(self.map).stem

    def _named(self, key: str, default: str) -> str:  # `default`: runs before the option
        name = self.extra.get(key)
        return name if isinstance(name, str) else default

    @property
    def middleware(self) -> str:
        return self._named("middleware", messaging.DEFAULT)

    @property
    def maps(self) -> str:
        return self._named("maps", messaging.DEFAULT_MAPS)

    @property
    def battery_failure(self) -> str:
        return self._named("battery_failure", NO_FAILURE)

    @property
    def map_cell(self) -> Any:  # unchecked: the reader checks it
        return self.extra.get("map_cell") or CELL_M

    @property
    def map_size(self) -> Any:  # [rows, cols], unchecked
        return self.extra.get("map_size") or [400, 400]  # the empty terrain's

    def to_dict(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in CONFIG_KEYS}
        out["extra"] = _plain(self.extra)
        return out

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> ResultConfig:
        """From config.json's contents (a run's whole configuration): the contract's keys,
        and everything else under `extra`."""
        doc = {k: config[k] for k in CONFIG_KEYS}
        doc["extra"] = {k: v for k, v in config.items() if k not in CONFIG_KEYS}
        return cls.from_dict(doc)

    @classmethod
    def from_dict(cls, c: Mapping[str, Any]) -> ResultConfig:
        """From result.json's `config` (or a sweep plan's, which keeps everything at the
        top); ResultError when malformed."""
        extra = _mapping(c, "extra")
        return cls(
            robots=_get(c, "robots", (int,), required=True),
            comm_range=_get(c, "comm_range", _NUM, required=True),
            laser_range=_get(c, "laser_range", _NUM, required=True),
            time_scale=_get(c, "time_scale", _NUM),
            routing=_get(c, "routing", (str,), DEFAULT_ROUTING),
            map=_get(c, "map", (str,)),
            loss_pct=_get(c, "loss_pct", _NUM, 0.0),
            delay_ms=_get(c, "delay_ms", _NUM, 0.0),
            coordination=_get(c, "coordination", (str,))
            or _get(extra, "coordination", (str,), DEFAULT_VARIANT[0]),
            start=_get(c, "start", (str,)) or _get(extra, "start", (str,), DEFAULT_VARIANT[1]),
            seed=_get(c, "seed", (int,)),
            capture=bool(c.get("capture")),
            max_steps=_get(c, "max_steps", (int,)),
            # result.json keeps these under config.extra; a sweep's plan at the top
            medium=_get(c, "medium", (str,)) or _get(extra, "medium", (str,), DEFAULT_MEDIUM),
            wifi_standard=_get(c, "wifi_standard", (str,)) or _get(extra, "wifi_standard", (str,)),
            wifi_rate=_get(c, "wifi_rate", (str,), _get(extra, "wifi_rate", (str,))),
            extra=extra,
        )


@dataclass(frozen=True)
class HostStalls:
    """Stalls of the whole machine during the run (testbed/run/stalls.py)."""

    events: int = 0
    stalled_s: float = 0.0
    deadlines_missed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HostStalls:
        return cls(
            events=_get(d, "events", (int,), 0),
            stalled_s=_get(d, "stalled_s", _NUM, 0.0),
            deadlines_missed=_get(d, "deadlines_missed", (int,), 0),
        )


@dataclass(frozen=True)
class Isolated:
    """A radio outage the run made (--isolate, testbed.run.isolation): robot `robot` out of
    everyone's range from `from_step`, back at `back_step` (None: the run ended first)."""

    robot: str
    from_step: int
    back_step: int | None

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: object) -> Isolated:
        if not isinstance(d, Mapping):
            raise ResultError("an 'isolated' entry is not an object")
        return cls(
            robot=_get(d, "robot", (str,), required=True),
            from_step=_get(d, "from_step", (int,), required=True),
            back_step=_get(d, "back_step", (int,)),
        )


# ---------------------------------------------------------------- the file


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """A run's result.json. The fields are its keys, in its order."""

    format: int = RESULT_FORMAT
    config: ResultConfig
    status: str
    status_detail: str = ""
    steps: int | None = None  # steps run: when the last robot finished, or the cap
    last_finish_step: int | None = None
    mean_finish_step: float | None = None  # over the robots not stopped (Fig. 2)
    mean_finish_step_robots: int | None = None  # how many it counted (None: older file)
    survivors_finished: bool | None = None  # every robot not stopped nor crashed finished
    isolated: tuple[Isolated, ...] = ()
    coverage_final: float | None = None
    time_scale_requested: float | None = None
    time_scale_achieved: float | None = None
    deadlines_missed: int = 0
    deadline_miss_fraction: float = 0.0
    deadlines_missed_world: int | None = None
    host_stalls: HostStalls = HostStalls()
    deadline_miss_fraction_outside_stalls: float = 0.0
    wall_time_s: float | None = None
    step_loop_wall_s: float | None = None
    wall_parts_s: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    world_priority: str | None = None
    step_core: str | None = None
    robot: str | None = None  # "cpp", "python", "mixed" (a test's team); None: older file
    robot_reason: str = ""  # why that one (testbed.run.robotchoice)
    display: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    world_timing_s: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    world_missed_steps_ms_late: tuple[Any, ...] = ()
    robots: tuple[RobotResult, ...] = ()  # in the file's order
    cpu_s: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    messaging: Mapping[str, Any] | None = (
        None  # the goals' middleware and its counters (None: older)
    )
    maps: Mapping[str, Any] | None = None  # how maps were shared and the counters (None: older)
    fidelity: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)  # {} : made before verdicts
    network_timers: Mapping[str, Any] | None = None

    # -- what code asks of it

    @property
    def faithful(self) -> bool | None:
        """Its fidelity verdict (testbed.run.fidelity): None for a run made before verdicts."""
        return self.fidelity.get("ok")

    @property
    def fidelity_reason(self) -> str:
        reason: str = self.fidelity.get("reason", "")
        return reason

    @property
    def network_faithful(self) -> bool | None:
        """fidelity.network's ok: None for a run made before it."""
        return (self.fidelity.get("network") or {}).get("ok")

    @property
    def network_reason(self) -> str:
        reason: str = (self.fidelity.get("network") or {}).get("reason", "")
        return reason

    @property
    def tcp_in_emulated_time(self) -> bool:
        """Whether TCP's timers kept emulated time: at time scale 1 they are the wall clock's,
        dilated only when the network's verdict says they were divided (a dilated run made
        before that was not)."""
        scale = self.time_scale_requested or self.config.time_scale
        return scale in (None, 1) or self.network_faithful is True

    @property
    def cpu_per_robot_step_ms(self) -> float | None:
        ms = self.cpu_s.get("per_robot_step_ms")
        return ms if isinstance(ms, int | float) and not isinstance(ms, bool) else None

    @property
    def cores_while_stepping(self) -> float | None:
        """Cores the run kept busy while it stepped: the CPU seconds of its parts (robots,
        display, world, routing) over the wall seconds of its step loop (wall_parts_s'
        `steps`). What a sweep packs runs by (testbed.sweep.cores). None when the file
        lacks either (older runs, a run that never stepped)."""
        given = [self.cpu_s.get(part) for part in CPU_PARTS]
        cpu = [s for s in given if isinstance(s, int | float) and not isinstance(s, bool)]
        wall = self.wall_parts_s.get("steps")
        if not cpu or not isinstance(wall, int | float) or isinstance(wall, bool) or wall <= 0:
            return None
        return sum(cpu) / wall

    @property
    def unimpaired(self) -> bool:
        return not self.config.loss_pct and not self.config.delay_ms

    @property
    def variant(self) -> tuple[str, str]:
        """(coordination, start placement)."""
        return self.config.coordination, self.config.start

    @property
    def network(self) -> tuple[str, str, str]:
        """(routing, map name, medium)."""
        return self.config.routing, self.config.map_name, self.config.medium

    @property
    def counted_robots(self) -> tuple[RobotResult, ...]:
        """The robots the averages over robots count: all but those stopped on purpose."""
        return tuple(r for r in self.robots if r.counted)

    @property
    def exploration_steps(self) -> float | None:
        """Mean over the counted robots of finish_step; a robot that never finished counts
        the final step. None without such robots, or with an unfinished one and no final
        step."""
        counted = self.counted_robots
        if not counted:
            return None
        values = [r.finish_step if r.finish_step is not None else self.steps for r in counted]
        known = [v for v in values if v is not None]
        if len(known) < len(values):
            return None
        return statistics.fmean(known)

    def robots_by_number(self) -> list[RobotResult]:
        return sorted(self.robots, key=lambda r: r.number)

    # -- the file

    def to_json(self) -> dict[str, Any]:
        """The file's contents, keys in the file's order."""
        out = {
            f.name: _plain(getattr(self, f.name))
            for f in dataclasses.fields(RunResult)  # a subclass's own fields are not the file's
        }
        out["robots"] = {r.name: r.to_dict() for r in self.robots}  # by name, in order
        return out

    def write(self, run_dir: str | Path) -> None:
        """result.json in `run_dir`, atomically (a temporary file, then rename)."""
        from common.jsonfile import write_json_atomic

        write_json_atomic(str(result_path(run_dir)), self.to_json())

    @classmethod
    def from_json(cls, source: str | Path | Mapping[str, Any]) -> RunResult:
        """From result.json's contents (a mapping), or from a run directory or the file
        itself (a path); ResultError (one line, naming the file) when it is missing, not
        JSON or malformed."""
        if isinstance(source, Mapping):
            return cls._checked(source)
        path = Path(source)
        if path.is_dir() or path.name != RESULT_NAME:
            path = result_path(path)
        try:
            doc = boundedfile.load_json(path)
        except boundedfile.Refused as r:
            if r.kind == "missing":
                raise ResultError(f"{path}: no such file (not a finished run)") from None
            raise ResultError(f"{path}: {boundedfile.describe(r)}") from None
        try:
            return cls._checked(doc)
        except ResultError as e:
            raise ResultError(f"{path}: {e}") from None

    @classmethod
    def read(cls, source: str | Path) -> RunResult | None:
        """from_json, or None when there is no readable result (for readers that carry on
        past a bad file and count it as saying nothing)."""
        try:
            return cls.from_json(source)
        except ResultError:
            return None

    @classmethod
    def _checked(cls, doc: object) -> RunResult:
        """_parse, then the values' ranges (testbed.analysis.resultcheck)."""
        result = cls._parse(doc)
        try:
            return resultcheck.check(result)
        except ValueError as e:
            raise ResultError(str(e)) from None

    @classmethod
    def _parse(cls, doc: object) -> RunResult:
        if not isinstance(doc, Mapping):
            raise ResultError("not a JSON object")
        c = _mapping(doc, "config")
        if not c:
            raise ResultError("no 'config'")
        fidelity = _mapping(doc, "fidelity")
        _get(fidelity, "ok", (bool,))
        _get(fidelity, "reason", (str,))
        network = _mapping(fidelity, "network")
        _get(network, "ok", (bool,))
        _get(network, "reason", (str,))
        timers = doc.get("network_timers")
        return cls(
            format=_get(doc, "format", (int,), RESULT_FORMAT),
            config=ResultConfig.from_dict(c),
            status=_get(doc, "status", (str,), required=True),
            status_detail=_get(doc, "status_detail", (str,), ""),
            steps=_get(doc, "steps", _NUM),
            last_finish_step=_get(doc, "last_finish_step", _NUM),
            mean_finish_step=_get(doc, "mean_finish_step", _NUM),
            mean_finish_step_robots=_get(doc, "mean_finish_step_robots", (int,)),
            survivors_finished=_get(doc, "survivors_finished", (bool,)),
            isolated=tuple(Isolated.from_dict(d) for d in _list(doc, "isolated")),
            coverage_final=_get(doc, "coverage_final", _NUM),
            time_scale_requested=_get(doc, "time_scale_requested", _NUM),
            time_scale_achieved=_get(doc, "time_scale_achieved", _NUM),
            deadlines_missed=_get(doc, "deadlines_missed", (int,), 0),
            deadline_miss_fraction=_get(doc, "deadline_miss_fraction", _NUM, 0.0),
            deadlines_missed_world=_get(doc, "deadlines_missed_world", (int,)),
            host_stalls=HostStalls.from_dict(_mapping(doc, "host_stalls")),
            deadline_miss_fraction_outside_stalls=_get(
                doc, "deadline_miss_fraction_outside_stalls", _NUM, 0.0
            ),
            wall_time_s=_get(doc, "wall_time_s", _NUM),
            step_loop_wall_s=_get(doc, "step_loop_wall_s", _NUM),
            wall_parts_s=_mapping(doc, "wall_parts_s"),
            world_priority=_get(doc, "world_priority", (str,)),
            step_core=_get(doc, "step_core", (str,)),
            robot=_get(doc, "robot", (str,)),
            robot_reason=_get(doc, "robot_reason", (str,), ""),
            display=_mapping(doc, "display"),
            world_timing_s=_mapping(doc, "world_timing_s"),
            world_missed_steps_ms_late=tuple(
                tuple(m) if isinstance(m, list) else m
                for m in _list(doc, "world_missed_steps_ms_late")
            ),
            robots=tuple(RobotResult.from_dict(k, v) for k, v in _mapping(doc, "robots").items()),
            cpu_s=_mapping(doc, "cpu_s"),
            messaging=_mapping(doc, "messaging") if doc.get("messaging") is not None else None,
            maps=_mapping(doc, "maps") if doc.get("maps") is not None else None,
            fidelity=fidelity,
            network_timers=None if timers is None else _mapping(doc, "network_timers"),
        )
