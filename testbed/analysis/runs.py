"""The analysis's runs: each finished run of a sweep as a `FinishedRun`, its result.json
(testbed.resultfile's `RunResult`) with where it lies and its channel's counters.

Theory of operation. Every module of testbed.analysis that needs what a run did (figures,
verdicts, the ablation, the protocols comparison, the causality check, the routing metrics)
takes a `FinishedRun`, made here once per run by `load_run`, instead of reading result.json
itself. A `FinishedRun` is a `RunResult` (so `run.status`, `run.config.robots`,
`run.exploration_steps` are the file's, read and checked by testbed.resultfile, with the
defaults of older files applied there) plus its run id and directory:

- A result.json the analysis cannot read (testbed.resultfile's `ResultError`: one line
  naming the file and the key) makes `load_run` raise; `load_runs` (a sweep directory) logs
  that line and leaves the run out, as a sweep's report counts what it could read.
- A run on the ns3-wifi medium also left `medium.json`, the 802.11 channel's counters
  (docs/ns3-medium.md, "Counters"): read into `FinishedRun.channel` (`ChannelRecord`), None
  for a veth run or a run made before the file existed. A medium.json that is there but
  not what the channel writes makes the run malformed, as a bad result.json does; so does
  a relay-lag file (the channel's per-frame lag, testbed.analysis.relaylag) without its
  header.

Which runs count (`FinishedRun.usable`): status `complete` or `step_cap`, and faithful to
its time scale (result.json's `fidelity`, testbed.run.fidelity; a run written before verdicts
counts) unless `load_runs(..., unfaithful=True)` keeps those too; a run that hit the step
cap counts its unfinished robots at the final step (`exploration_steps`), and a robot
stopped on purpose (`--kill`) is not counted at all.

Whether a run's TCP kept emulated time (`tcp_in_emulated_time`: at time scale 1, or with
its network verdict `fidelity.network` ok) decides whether its PDF and delay may be set
beside another time scale's; a dilated run written before the network's timers were
dilated did not keep it.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from common import boundedfile
from testbed.resultfile import RESULT_NAME, ResultError, RunResult
from testbed.run.resultconfig import DEFAULT_VARIANT
from testbed.run.resultvalues import get_mapping, get_value, one_line

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_VARIANT", "FinishedRun", "ResultError", "load_run", "load_runs"]

USABLE = ("complete", "step_cap")
MEDIUM_NAME = "medium.json"
_NUM = (int, float)


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


@dataclass(frozen=True, kw_only=True)
class FinishedRun(RunResult):
    """A finished run of a sweep: its result.json, its directory and its channel's counters."""

    run_id: str
    path: Path
    channel: ChannelRecord | None = None  # medium.json: the ns3-wifi channel's counters
    count_unfaithful: bool = False  # usable even if not faithful (load_runs(unfaithful=True))

    @property
    def usable(self) -> bool:
        return self.status in USABLE and (self.faithful is not False or self.count_unfaithful)

    def captured_per_robot_s(self, metrics: Mapping, key: str) -> float | None:
        """A count of the run's capture metrics (pcapmetrics' `key`) per transmitting robot
        (the display robot transmits too) per second of robot time; None when missing."""
        total, wall = metrics.get(key), metrics.get("duration_s")
        return self.per_robot_second(total, wall, self.config.robots + 1)

    @classmethod
    def of(cls, result: RunResult, run_dir: Path, channel: ChannelRecord | None = None):
        fields = {f.name: getattr(result, f.name) for f in dataclasses.fields(RunResult)}
        return cls(**fields, run_id=one_line(run_dir.name), path=run_dir, channel=channel)


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
            counts = {f: get_value(r, key, (int,), 0) for f, key in _CHANNEL_COUNTS.items()}
            airtime = get_value(r, "airtime_s", _NUM, 0.0)
        except ResultError as e:
            raise ResultError(f"robot {k}: {e}") from None
        out.append(ChannelRobot(name=f"r{k}", airtime_s=airtime, **counts))
    lag, late = get_mapping(doc, "relay_lag"), get_mapping(doc, "lateness")
    frames = get_value(lag, "frames", (int,), 0)
    over = get_value(lag, "over_1ms", (int,), 0)
    return ChannelRecord(
        duration_s=get_value(doc, "now_s", _NUM, required=True),
        robots=tuple(out),
        relay_lag_mean_ms=get_value(lag, "mean_ms", _NUM),
        relay_lag_over_1ms=over / frames if frames else None,
        lateness_max_ms=get_value(late, "max_ms", _NUM),
    )


def _load_channel(run_dir: Path) -> ChannelRecord | None:
    path = run_dir / MEDIUM_NAME
    if not os.path.lexists(path):
        return None
    try:
        doc = boundedfile.load_json(path)
    except boundedfile.Refused as r:
        raise ResultError(f"{path}: {boundedfile.describe(r)}") from None
    try:
        return parse_channel(doc)
    except ResultError as e:
        raise ResultError(f"{path}: {e}") from None


def _check_lag_file(run_dir: Path) -> None:
    """ResultError when the run's relay-lag file is there but not one (its header)."""
    from testbed.analysis import relaylag
    from topology.names import LAG_FILE

    path = run_dir / LAG_FILE
    if not os.path.lexists(path):
        return
    try:
        head = boundedfile.read(path, relaylag.MAX_LAG_BYTES)[: len(relaylag.MAGIC)]
    except boundedfile.Refused as r:
        raise ResultError(f"{path}: {boundedfile.describe(r)}") from None
    if head != relaylag.MAGIC:
        raise ResultError(f"{path}: not a relay-lag file (no {relaylag.MAGIC.decode()} header)")


def load_run(run_dir: str | Path) -> FinishedRun:
    """The finished run in `run_dir`; ResultError (one line, naming the file) when its
    result.json is missing, not JSON or lacks what the analysis needs, or its medium.json
    or relay-lag file is there but unreadable."""
    run_dir = Path(run_dir)
    channel = _load_channel(run_dir)
    _check_lag_file(run_dir)
    return FinishedRun.of(RunResult.from_json(run_dir), run_dir, channel)


def load_runs(
    sweep_dir: str | Path, unfaithful: bool = False, left_out: list[str] | None = None
) -> list[FinishedRun]:
    """Every run of a sweep directory with a readable result.json, sorted by run id; the
    others are logged and left out (and why appended to `left_out`, one line each).
    `unfaithful`: runs not faithful to their time scale count as usable too."""
    runs = []
    why = [] if left_out is None else left_out
    for run_dir in sorted(p.parent for p in Path(sweep_dir).glob(f"runs/*/{RESULT_NAME}")):
        if run_dir.is_symlink():  # its files (routing.json) would be written elsewhere
            why.append(f"{one_line(str(run_dir))}: a symbolic link, not a run directory")
            log.warning("skipping %s", why[-1])
            continue
        try:
            runs.append(replace(load_run(run_dir), count_unfaithful=unfaithful))
        except ResultError as e:
            why.append(one_line(str(e)))
            log.warning("skipping %s", why[-1])
    return runs
