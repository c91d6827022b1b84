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
  line naming the file and the key; so is a `format` other than RESULT_FORMAT (a file
  without one is format 1, the only one so far): a later format's keys may mean other
  things, and are not read as this one's.
- Keys that files written by older versions lack get their defaults here and only here
  (the config's in its type, testbed.files.resultconfig): `routing` aodv, `map` none (the
  empty terrain), `loss_pct` and `delay_ms` 0, `coordination` ours and `start` corner
  (before those existed, they were all there was), no robot stopped (before `--kill`
  stopped robots, `mean_finish_step_robots` and `survivors_finished` are None), no radio
  outage, no fidelity verdict; in config's `extra`, middleware nanomsg, maps flood, no
  battery failure, a 400 x 400 map of CELL_M cells.
- The config's keys are run options (those testbed.files.runconfig marks in_result, held to
  testbed.files.resultconfig's keys as the table is made); the checked reading of values
  is testbed.files.resultvalues'.
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
from typing import Any

from common import boundedfile
from testbed.files import resultcheck
from testbed.files.resultconfig import ResultConfig as ResultConfig  # re-exported: its config
from testbed.files.resultvalues import EMPTY, NUM, get_list, get_mapping, get_value, plain
from testbed.files.resultvalues import ResultError as ResultError  # re-exported: its error

RESULT_NAME = "result.json"
RESULT_FORMAT = 1
# The processes whose CPU seconds cpu_s holds (testbed.run.results.cpu_seconds).
CPU_PARTS = ("robots", "display", "world", "routing")
# Which steps were missed, kept per robot (robots/rK.json) and for the world
# (world_missed_steps_ms_late): at most this many.
MAX_MISSED_STEPS_KEPT = 1000


def result_path(run_dir: str | Path) -> Path:
    """Where a run directory's result.json is (the run's completion marker)."""
    return Path(run_dir) / RESULT_NAME


def has_result(run_dir: str | Path) -> bool:
    """Whether the run in `run_dir` finished (its result.json exists, whatever it says)."""
    return result_path(run_dir).is_file()


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
    sent: Mapping[str, int] = field(default_factory=lambda: EMPTY)  # messages, by kind
    received: Mapping[str, int] = field(default_factory=lambda: EMPTY)
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
            plans = tuple(Plan(get_value(p, "step", NUM, required=True),
                               get_value(p, "cause", (str,))) for p in plans)  # fmt: skip
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise ResultError(f"robot {name}: a plan without a step ({e})") from None
        messages = get_mapping(doc, "messages")
        return cls(
            name=name,
            finish_step=get_value(doc, "finish_step", NUM),
            crashed=bool(doc.get("crashed")),
            plans=plans,
            sent=get_mapping(messages, "sent"),
            received=get_mapping(messages, "received"),
            path_length_m=get_value(doc, "path_length_m", NUM),
            stopped_step=get_value(doc, "stopped_step", (int,)),
            exit_status=get_value(doc, "exit_status", (int,)),
        )


@dataclass(frozen=True)
class HostStalls:
    """Stalls of the whole machine during the run (testbed/run/stalls.py)."""

    events: int = 0
    stalled_s: float = 0.0
    deadlines_missed: int = 0
    granted_s: float = 0.0  # wall seconds the world gave back to the robots after stalls

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HostStalls:
        return cls(
            events=get_value(d, "events", (int,), 0),
            stalled_s=get_value(d, "stalled_s", NUM, 0.0),
            deadlines_missed=get_value(d, "deadlines_missed", (int,), 0),
            granted_s=get_value(d, "granted_s", NUM, 0.0),
        )


@dataclass(frozen=True)
class Isolated:
    """A radio outage the run made (--isolate, testbed.files.isolation): robot `robot` out of
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
            robot=get_value(d, "robot", (str,), required=True),
            from_step=get_value(d, "from_step", (int,), required=True),
            back_step=get_value(d, "back_step", (int,)),
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
    wall_parts_s: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    world_priority: str | None = None
    step_core: str | None = None
    step_loop: str | None = None  # the world's: "compiled", "python"; None: older file
    robot: str | None = None  # "cpp", "python", "mixed" (a test's team); None: older file
    robot_reason: str = ""  # why that one (testbed.run.robotchoice)
    aodv_daemon: str | None = None  # "cpp", "python"; None: no AODV daemon ran, or older file
    aodv_daemon_reason: str = ""  # why that one (testbed.run.daemonchoice)
    display: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    world_timing_s: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    world_missed_steps_ms_late: tuple[Any, ...] = ()
    robots: tuple[RobotResult, ...] = ()  # in the file's order
    cpu_s: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    messaging: Mapping[str, Any] | None = (
        None  # the goals' middleware and its counters (None: older)
    )
    maps: Mapping[str, Any] | None = None  # how maps were shared and the counters (None: older)
    fidelity: Mapping[str, Any] = field(default_factory=lambda: EMPTY)  # {} : made before verdicts
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
    def time_scale_ran(self) -> float:
        """The time scale the run kept: the achieved one, else the one asked for (1 when
        neither is known)."""
        return (
            self.time_scale_achieved or self.time_scale_requested or self.config.time_scale or 1.0
        )

    def per_robot_second(
        self, total: float | None, wall_s: float | None, robots: int
    ) -> float | None:
        """`total`, counted over `wall_s` seconds of wall time (the run's captures, say), per
        robot of `robots` per second of robot time (the wall time times the time scale the run
        kept); None when a number is missing or zero."""
        if total is None or not wall_s or not robots:
            return None
        return total / (robots * wall_s * self.time_scale_ran)

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
            f.name: plain(getattr(self, f.name))
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
        """_parse, then the values' ranges (testbed.files.resultcheck)."""
        result = cls._parse(doc)
        try:
            checked: RunResult = resultcheck.check(result)
            return checked
        except ValueError as e:
            raise ResultError(str(e)) from None

    @classmethod
    def _parse(cls, doc: object) -> RunResult:
        if not isinstance(doc, Mapping):
            raise ResultError("not a JSON object")
        c = get_mapping(doc, "config")
        if not c:
            raise ResultError("no 'config'")
        fidelity = get_mapping(doc, "fidelity")
        get_value(fidelity, "ok", (bool,))
        get_value(fidelity, "reason", (str,))
        network = get_mapping(fidelity, "network")
        get_value(network, "ok", (bool,))
        get_value(network, "reason", (str,))
        timers = doc.get("network_timers")
        fmt = get_value(doc, "format", (int,), RESULT_FORMAT)
        if fmt != RESULT_FORMAT:  # another format's keys may mean other things: not guessed
            raise ResultError(f"format {fmt}, but this testbed reads format {RESULT_FORMAT}")
        return cls(
            format=fmt,
            config=ResultConfig.from_dict(c),
            status=get_value(doc, "status", (str,), required=True),
            status_detail=get_value(doc, "status_detail", (str,), ""),
            steps=get_value(doc, "steps", NUM),
            last_finish_step=get_value(doc, "last_finish_step", NUM),
            mean_finish_step=get_value(doc, "mean_finish_step", NUM),
            mean_finish_step_robots=get_value(doc, "mean_finish_step_robots", (int,)),
            survivors_finished=get_value(doc, "survivors_finished", (bool,)),
            isolated=tuple(Isolated.from_dict(d) for d in get_list(doc, "isolated")),
            coverage_final=get_value(doc, "coverage_final", NUM),
            time_scale_requested=get_value(doc, "time_scale_requested", NUM),
            time_scale_achieved=get_value(doc, "time_scale_achieved", NUM),
            deadlines_missed=get_value(doc, "deadlines_missed", (int,), 0),
            deadline_miss_fraction=get_value(doc, "deadline_miss_fraction", NUM, 0.0),
            deadlines_missed_world=get_value(doc, "deadlines_missed_world", (int,)),
            host_stalls=HostStalls.from_dict(get_mapping(doc, "host_stalls")),
            deadline_miss_fraction_outside_stalls=get_value(
                doc, "deadline_miss_fraction_outside_stalls", NUM, 0.0
            ),
            wall_time_s=get_value(doc, "wall_time_s", NUM),
            step_loop_wall_s=get_value(doc, "step_loop_wall_s", NUM),
            wall_parts_s=get_mapping(doc, "wall_parts_s"),
            world_priority=get_value(doc, "world_priority", (str,)),
            step_core=get_value(doc, "step_core", (str,)),
            step_loop=get_value(doc, "step_loop", (str,)),
            robot=get_value(doc, "robot", (str,)),
            robot_reason=get_value(doc, "robot_reason", (str,), ""),
            aodv_daemon=get_value(doc, "aodv_daemon", (str,)),
            aodv_daemon_reason=get_value(doc, "aodv_daemon_reason", (str,), ""),
            display=get_mapping(doc, "display"),
            world_timing_s=get_mapping(doc, "world_timing_s"),
            world_missed_steps_ms_late=tuple(
                tuple(m) if isinstance(m, list) else m
                for m in get_list(doc, "world_missed_steps_ms_late")
            ),
            robots=tuple(
                RobotResult.from_dict(k, v) for k, v in get_mapping(doc, "robots").items()
            ),
            cpu_s=get_mapping(doc, "cpu_s"),
            messaging=get_mapping(doc, "messaging") if doc.get("messaging") is not None else None,
            maps=get_mapping(doc, "maps") if doc.get("maps") is not None else None,
            fidelity=fidelity,
            network_timers=None if timers is None else get_mapping(doc, "network_timers"),
        )
