"""The analysis's one reader of run results: a finished run's result.json as frozen values.

Theory of operation. Every module of testbed.analysis that needs what a run did (figures,
verdicts, the ablation, the protocols comparison, the causality check, the routing metrics)
takes a `RunRecord`, made here once per run by `load_run`, instead of reading result.json
and picking keys out of nested dicts itself. The contract is docs/run-results.md; this
module is its reading side:

- A key the analysis cannot do without (the status, the team size and both ranges) missing
  or of the wrong type makes the file malformed: `load_run` raises `ResultError`, one line
  naming the file and the key. `load_runs` (a sweep directory) logs that line and leaves the
  run out, as a sweep's report counts what it could read.
- Keys that results written by older versions lack get their defaults here and only here:
  `routing` aodv, `map` none (the empty terrain), `loss_pct` and `delay_ms` 0,
  `coordination` ours and `start` corner (before those existed, they were all there was).
- Values keep the type JSON gave them (an int stays an int), so the numbers written from
  them are those the file holds.
- A run on the ns3-wifi medium also left `medium.json`, the 802.11 channel's counters
  (docs/ns3-medium.md, "Counters"): read into `RunRecord.channel` (`ChannelRecord`), None
  for a veth run or a run made before the file existed. A medium.json that is there but
  not what the channel writes makes the run malformed, as a bad result.json does; so does
  a relay-lag file (the channel's per-frame lag, testbed.analysis.relaylag) without its
  header.

Which runs count (`RunRecord.usable`): status `complete` or `step_cap`, and faithful to its
time scale (result.json's `fidelity`, testbed.fidelity; a run written before verdicts
counts) unless `load_runs(..., unfaithful=True)` keeps those too; a run that hit the step
cap counts its unfinished robots at the final step (`exploration_steps`).

Whether a run's TCP kept emulated time (`RunRecord.tcp_in_emulated_time`: at time scale 1,
or with its network verdict `fidelity.network` ok) decides whether its PDF and delay may be
set beside another time scale's; a dilated run written before the network's timers were
dilated did not keep it.
"""

from __future__ import annotations

import json
import logging
import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType

log = logging.getLogger(__name__)

RESULT_NAME = "result.json"
USABLE = ("complete", "step_cap")
DEFAULT_VARIANT = ("ours", "corner")  # (coordination, start) of runs that did not say
DEFAULT_ROUTING = "aodv"
DEFAULT_MEDIUM = "veth"
MEDIUM_NAME = "medium.json"
_EMPTY: Mapping = MappingProxyType({})


class ResultError(ValueError):
    """A result.json the analysis cannot read; str() is one line naming the file."""


@dataclass(frozen=True)
class Plan:
    """One plan generation of a robot: the step it happened at and why (start, timer,
    request; None when the record does not say)."""

    step: int
    cause: str | None


@dataclass(frozen=True)
class RobotRecord:
    """One robot's entry in result.json's `robots`."""

    name: str
    finish_step: int | None
    crashed: bool
    plans: tuple[Plan, ...]
    sent: Mapping[str, int]  # messages sent, by kind
    received: Mapping[str, int]  # messages received, by kind
    path_length_m: float | None

    @property
    def number(self) -> int:
        """K of robot "rK" (0 for a name that is not one)."""
        try:
            return int(self.name.lstrip("r"))
        except ValueError:
            return 0


@dataclass(frozen=True)
class ConfigRecord:
    """result.json's `config`: what the run was asked to do, defaults applied."""

    robots: int
    comm_range: float
    laser_range: float
    time_scale: float | None
    routing: str
    map: str | None
    loss_pct: float
    delay_ms: float
    coordination: str
    start: str
    seed: int | None = None
    capture: bool = False
    max_steps: int | None = None
    medium: str = DEFAULT_MEDIUM
    wifi_standard: str | None = None  # ns3-wifi only (None: the run did not say)
    wifi_rate: str | None = None  # ns3-wifi only; "" is the standard's fastest
    extra: Mapping = field(default_factory=lambda: _EMPTY)

    @property
    def map_name(self) -> str:
        """The map's file stem, or "empty" for the empty terrain."""
        return "empty" if not self.map else Path(self.map).stem


@dataclass(frozen=True)
class HostStalls:
    """Stalls of the whole machine during the run (testbed/stalls.py)."""

    events: int = 0
    stalled_s: float = 0.0
    deadlines_missed: int = 0


@dataclass(frozen=True)
class ChannelRobot:
    """One robot's counters on the 802.11 channel (ns3-wifi's medium.json)."""

    name: str  # "rK"; the display robot is the last
    frames_sent: int  # frames the robot handed to the channel (from_linux)
    frames_delivered: int  # frames the channel delivered to it (to_linux)
    mac_tx: int  # MSDUs handed to its WiFi MAC
    retries: int  # data transmissions not acknowledged
    retry_drops: int  # MSDUs given up after the retry limit
    queue_drops: int  # MSDUs refused by a full MAC queue
    queue_expired: int  # MSDUs that waited longer than the queue's limit
    phy_tx_drops: int
    phy_rx_drops: int  # receptions lost: collisions, half duplex, preamble missed
    airtime_s: float  # emulated seconds its PHY spent transmitting


@dataclass(frozen=True)
class ChannelRecord:
    """The 802.11 channel's counters at the end of a run (medium.json)."""

    duration_s: float  # emulated seconds the channel ran (now_s)
    robots: tuple[ChannelRobot, ...]
    relay_lag_mean_ms: float | None = None  # emulated ms; how late frames were relayed
    relay_lag_over_1ms: float | None = None  # share of relayed frames over 1 ms late
    lateness_max_ms: float | None = None

    def total(self, key: str) -> float:
        """The sum over robots of one ChannelRobot field."""
        return sum(getattr(r, key) for r in self.robots)

    @property
    def airtime_share(self) -> float | None:
        """Transmitting time of all robots over the channel's duration: the share of the
        air in use where every robot hears every other (more than 1 is possible when robots
        out of each other's range transmit at once)."""
        return self.total("airtime_s") / self.duration_s if self.duration_s > 0 else None

    @property
    def retry_rate(self) -> float | None:
        """Unacknowledged transmissions per MSDU handed to the MACs."""
        mac_tx = self.total("mac_tx")
        return self.total("retries") / mac_tx if mac_tx else None

    @property
    def drops(self) -> int:
        """MSDUs the MACs lost: retry limit, full queue, expired in the queue."""
        return int(self.total("retry_drops") + self.total("queue_drops")
                   + self.total("queue_expired"))  # fmt: skip


@dataclass(frozen=True)
class RunRecord:
    """A finished run: its directory and what its result.json says."""

    run_id: str
    path: Path
    config: ConfigRecord
    status: str
    status_detail: str
    steps: int | None  # steps run: when the last robot finished, or the cap
    coverage_final: float | None
    time_scale_requested: float | None
    time_scale_achieved: float | None
    deadlines_missed: int
    deadline_miss_fraction: float
    deadline_miss_fraction_outside_stalls: float
    host_stalls: HostStalls
    wall_time_s: float | None
    robots: tuple[RobotRecord, ...]  # in the file's order
    channel: ChannelRecord | None = None  # medium.json: the ns3-wifi channel's counters
    faithful: bool | None = None  # its fidelity verdict (None: written before verdicts)
    fidelity_reason: str = ""  # why not, when not
    network_faithful: bool | None = None  # fidelity.network's ok (None: written before it)
    network_reason: str = ""  # why not, when not
    count_unfaithful: bool = False  # usable even if not faithful (load_runs(unfaithful=True))

    @property
    def usable(self) -> bool:
        return self.status in USABLE and (self.faithful is not False or self.count_unfaithful)

    @property
    def tcp_in_emulated_time(self) -> bool:
        """Whether TCP's timers kept emulated time: at time scale 1 they are the wall clock's,
        dilated only when the network's verdict says they were divided (a dilated run made
        before that was not)."""
        scale = self.time_scale_requested or self.config.time_scale
        return scale in (None, 1) or self.network_faithful is True

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
    def exploration_steps(self) -> float | None:
        """Mean over robots of finish_step; a robot that never finished counts the final
        step. None without robots, or with an unfinished robot and no final step."""
        if not self.robots:
            return None
        values = [r.finish_step if r.finish_step is not None else self.steps for r in self.robots]
        if any(v is None for v in values):
            return None
        return statistics.fmean(values)

    def robots_by_number(self) -> list[RobotRecord]:
        return sorted(self.robots, key=lambda r: r.number)


# ---------------------------------------------------------------- reading


def _get(doc: Mapping, key: str, kinds: tuple[type, ...], default=None, required=False):
    """doc[key] checked against `kinds` (bool is not a number); default when absent or null."""
    value = doc.get(key)
    if value is None:
        if required:
            raise ResultError(f"no {key!r}")
        return default
    number = kinds in ((int,), (int, float), (float, int))
    if not isinstance(value, kinds) or (number and isinstance(value, bool)):
        want = " or ".join(k.__name__ for k in kinds)
        raise ResultError(f"{key!r} is {type(value).__name__}, not {want}")
    return value


_NUM = (int, float)


def _mapping(doc: Mapping, key: str) -> Mapping:
    value = doc.get(key)
    if value is None:
        return _EMPTY
    if not isinstance(value, Mapping):
        raise ResultError(f"{key!r} is {type(value).__name__}, not an object")
    return MappingProxyType(dict(value))


def _config(doc: Mapping) -> ConfigRecord:
    c = _mapping(doc, "config")
    if not c:
        raise ResultError("no 'config'")
    extra = _mapping(c, "extra")
    return ConfigRecord(
        robots=_get(c, "robots", (int,), required=True),
        comm_range=_get(c, "comm_range", _NUM, required=True),
        laser_range=_get(c, "laser_range", _NUM, required=True),
        time_scale=_get(c, "time_scale", _NUM),
        routing=_get(c, "routing", (str,), DEFAULT_ROUTING),
        map=_get(c, "map", (str,)),
        loss_pct=_get(c, "loss_pct", _NUM, 0.0),
        delay_ms=_get(c, "delay_ms", _NUM, 0.0),
        coordination=c.get("coordination", extra.get("coordination", DEFAULT_VARIANT[0])),
        start=c.get("start", extra.get("start", DEFAULT_VARIANT[1])),
        seed=_get(c, "seed", (int,)),
        capture=bool(c.get("capture")),
        max_steps=_get(c, "max_steps", (int,)),
        # result.json keeps these under config.extra; a sweep's plan at the top
        medium=_get(c, "medium", (str,)) or _get(extra, "medium", (str,), DEFAULT_MEDIUM),
        wifi_standard=_get(c, "wifi_standard", (str,)) or _get(extra, "wifi_standard", (str,)),
        wifi_rate=_get(c, "wifi_rate", (str,), _get(extra, "wifi_rate", (str,))),
        extra=extra,
    )


def _plans(doc: Mapping, robot: str) -> tuple[Plan, ...]:
    plans = doc.get("plans") or []
    if not isinstance(plans, list):
        raise ResultError(f"robot {robot}: 'plans' is not a list")
    try:
        return tuple(Plan(int(p["step"]), p.get("cause")) for p in plans)
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise ResultError(f"robot {robot}: a plan without a step ({e})") from None


def _robot(name: str, doc) -> RobotRecord:
    if not isinstance(doc, Mapping):
        raise ResultError(f"robot {name} is not an object")
    messages = _mapping(doc, "messages")
    return RobotRecord(
        name=name,
        finish_step=_get(doc, "finish_step", _NUM),
        crashed=bool(doc.get("crashed")),
        plans=_plans(doc, name),
        sent=_mapping(messages, "sent"),
        received=_mapping(messages, "received"),
        path_length_m=_get(doc, "path_length_m", _NUM),
    )


_CHANNEL_COUNTS = {
    "frames_sent": "from_linux", "frames_delivered": "to_linux", "mac_tx": "mac_tx",
    "retries": "retries", "retry_drops": "retry_drops", "queue_drops": "queue_drops",
    "queue_expired": "queue_expired", "phy_tx_drops": "phy_tx_drops",
    "phy_rx_drops": "phy_rx_drops",
}  # fmt: skip


def parse_channel(doc) -> ChannelRecord:
    """The ChannelRecord of a medium.json's contents; ResultError when malformed."""
    if not isinstance(doc, Mapping):
        raise ResultError("not a JSON object")
    robots = doc.get("robots")
    if not isinstance(robots, list):
        raise ResultError("'robots' is not a list")
    out = []
    for k, r in enumerate(robots, start=1):
        if not isinstance(r, Mapping):
            raise ResultError(f"robot {k} is not an object")
        try:
            counts = {f: _get(r, key, (int,), 0) for f, key in _CHANNEL_COUNTS.items()}
            airtime = _get(r, "airtime_s", _NUM, 0.0)
        except ResultError as e:
            raise ResultError(f"robot {k}: {e}") from None
        out.append(ChannelRobot(name=f"r{k}", airtime_s=airtime, **counts))
    lag, late = _mapping(doc, "relay_lag"), _mapping(doc, "lateness")
    frames = _get(lag, "frames", (int,), 0)
    over = _get(lag, "over_1ms", (int,), 0)
    return ChannelRecord(
        duration_s=_get(doc, "now_s", _NUM, required=True),
        robots=tuple(out),
        relay_lag_mean_ms=_get(lag, "mean_ms", _NUM),
        relay_lag_over_1ms=over / frames if frames else None,
        lateness_max_ms=_get(late, "max_ms", _NUM),
    )


def _load_channel(run_dir: Path) -> ChannelRecord | None:
    path = run_dir / MEDIUM_NAME
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        raise ResultError(f"{path}: unreadable ({e})") from None
    try:
        return parse_channel(doc)
    except ResultError as e:
        raise ResultError(f"{path}: {e}") from None


def parse_result(doc, run_dir: Path, channel: ChannelRecord | None = None) -> RunRecord:
    """The RunRecord of a result.json's contents (and of medium.json's, `channel`);
    ResultError when malformed."""
    if not isinstance(doc, Mapping):
        raise ResultError("not a JSON object")
    stalls = _mapping(doc, "host_stalls")
    fidelity = _mapping(doc, "fidelity")
    return RunRecord(
        run_id=run_dir.name,
        path=run_dir,
        config=_config(doc),
        status=_get(doc, "status", (str,), required=True),
        status_detail=_get(doc, "status_detail", (str,), ""),
        steps=_get(doc, "steps", _NUM),
        coverage_final=_get(doc, "coverage_final", _NUM),
        time_scale_requested=_get(doc, "time_scale_requested", _NUM),
        time_scale_achieved=_get(doc, "time_scale_achieved", _NUM),
        deadlines_missed=_get(doc, "deadlines_missed", (int,), 0),
        deadline_miss_fraction=_get(doc, "deadline_miss_fraction", _NUM, 0.0),
        deadline_miss_fraction_outside_stalls=_get(
            doc, "deadline_miss_fraction_outside_stalls", _NUM, 0.0
        ),
        host_stalls=HostStalls(
            events=_get(stalls, "events", (int,), 0),
            stalled_s=_get(stalls, "stalled_s", _NUM, 0.0),
            deadlines_missed=_get(stalls, "deadlines_missed", (int,), 0),
        ),
        wall_time_s=_get(doc, "wall_time_s", _NUM),
        robots=tuple(_robot(k, v) for k, v in _mapping(doc, "robots").items()),
        channel=channel,
        faithful=_get(fidelity, "ok", (bool,)),
        fidelity_reason=_get(fidelity, "reason", (str,), ""),
        network_faithful=_get(_mapping(fidelity, "network"), "ok", (bool,)),
        network_reason=_get(_mapping(fidelity, "network"), "reason", (str,), ""),
    )


def _check_lag_file(run_dir: Path) -> None:
    """ResultError when the run's relay-lag file is there but not one (its header)."""
    from testbed.analysis import relaylag

    path = run_dir / relaylag.LAG_NAME
    try:
        with open(path, "rb") as f:
            head = f.read(len(relaylag.MAGIC))
    except FileNotFoundError:
        return
    except OSError as e:
        raise ResultError(f"{path}: unreadable ({e})") from None
    if head != relaylag.MAGIC:
        raise ResultError(f"{path}: not a relay-lag file (no {relaylag.MAGIC.decode()} header)")


def load_run(run_dir: str | Path) -> RunRecord:
    """The finished run in `run_dir`; ResultError (one line, naming the file) when its
    result.json is missing, not JSON or lacks what the analysis needs, or its medium.json
    or relay-lag file is there but unreadable."""
    run_dir = Path(run_dir)
    channel = _load_channel(run_dir)
    _check_lag_file(run_dir)
    path = run_dir / RESULT_NAME
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ResultError(f"{path}: no such file (not a finished run)") from None
    except (OSError, ValueError) as e:
        raise ResultError(f"{path}: unreadable ({e})") from None
    try:
        return parse_result(doc, run_dir, channel)
    except ResultError as e:
        raise ResultError(f"{path}: {e}") from None


def load_runs(sweep_dir: str | Path, unfaithful: bool = False) -> list[RunRecord]:
    """Every run of a sweep directory with a readable result.json, sorted by run id; the
    others are logged and left out. `unfaithful`: runs not faithful to their time scale
    count as usable too."""
    runs = []
    for res in sorted(Path(sweep_dir).glob(f"runs/*/{RESULT_NAME}")):
        try:
            runs.append(replace(load_run(res.parent), count_unfaithful=unfaithful))
        except ResultError as e:
            log.warning("skipping %s", e)
    return runs
