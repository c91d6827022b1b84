"""A run's medium.json as one type: `ChannelRecord`, the ns3-wifi channel's counters at the
end of the run (docs/ns3-medium.md, "Counters"), which the channel writes and the analysis
reads (testbed.analysis.runs: `FinishedRun.channel`).

`read(run_dir)` takes the file through the one bounded reader (common.boundedfile): None
when the run has none (a veth run, or one made before the file existed); a file that is
there but not what the channel writes is a ResultError of one line naming the file and the
key, as a bad result.json is. Each robot's counters are whole numbers (0 when absent), its
airtime a number; `now_s`, the channel's emulated seconds, is required. `relay_lag` (how late
the channel relayed frames: `RelayLag`, which the run's fidelity verdict judges,
testbed.run.results) has whole, non-negative counts, no more frames over 1 ms than frames,
and a non-negative mean.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from testbed.files import layout
from testbed.files.resultvalues import ResultError, get_mapping, get_value, read_json_as

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
class RelayLag:
    """medium.json's `relay_lag`: how late (emulated ms) the channel relayed frames."""

    frames: int  # frames relayed
    mean_ms: float | None  # None: the file has no mean
    over_1ms: int = 0  # frames relayed more than 1 ms late
    max_ms: float | None = None

    @property
    def over_1ms_share(self) -> float | None:
        """The share of relayed frames over 1 ms late (None when none was relayed)."""
        return self.over_1ms / self.frames if self.frames else None


def parse_relay_lag(doc: Mapping[str, object]) -> RelayLag | None:
    """medium.json's `relay_lag` (None when absent); ResultError when malformed."""
    lag = get_mapping(doc, "relay_lag")
    if not lag:
        return None
    out = RelayLag(
        frames=get_value(lag, "frames", (int,), 0),
        mean_ms=get_value(lag, "mean_ms", _NUM),
        over_1ms=get_value(lag, "over_1ms", (int,), 0),
        max_ms=get_value(lag, "max_ms", _NUM),
    )
    for key in ("frames", "mean_ms", "over_1ms", "max_ms"):
        value = getattr(out, key)
        if value is not None and value < 0:
            raise ResultError(f"'relay_lag': {key!r} is negative ({value})")
    if out.over_1ms > out.frames:
        raise ResultError(f"'relay_lag': more frames over 1 ms ({out.over_1ms}) than relayed "
                          f"({out.frames})")  # fmt: skip
    return out


@dataclass(frozen=True)
class ChannelRecord:
    """The 802.11 channel's counters at the end of a run (medium.json)."""

    duration_s: float  # emulated seconds the channel ran (now_s)
    robots: tuple[ChannelRobot, ...]
    relay_lag_mean_ms: float | None = None  # emulated ms; how late frames were relayed
    relay_lag_over_1ms: float | None = None  # share of relayed frames over 1 ms late
    lateness_max_ms: float | None = None
    relay_lag: RelayLag | None = None

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


_CHANNEL_COUNTS = {
    "frames_sent": "from_linux", "frames_delivered": "to_linux", "mac_tx": "mac_tx",
    "retries": "retries", "retry_drops": "retry_drops", "queue_drops": "queue_drops",
    "queue_expired": "queue_expired", "phy_tx_drops": "phy_tx_drops",
    "phy_rx_drops": "phy_rx_drops",
}  # fmt: skip


def parse_channel(doc: object) -> ChannelRecord:
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
    lag = parse_relay_lag(doc)
    return ChannelRecord(
        duration_s=get_value(doc, "now_s", _NUM, required=True),
        robots=tuple(out),
        relay_lag_mean_ms=lag.mean_ms if lag else None,
        relay_lag_over_1ms=lag.over_1ms_share if lag else None,
        lateness_max_ms=get_value(get_mapping(doc, "lateness"), "max_ms", _NUM),
        relay_lag=lag,
    )


def read(run_dir: str | os.PathLike[str]) -> ChannelRecord | None:
    """The run's medium.json as a ChannelRecord; None when there is none (a veth run, or one
    made before the file); ResultError (one line, naming the file) when it is there but
    unreadable or not what the channel writes."""
    path = Path(layout.medium_path(run_dir))
    if not os.path.lexists(path):
        return None
    return read_json_as(path, parse_channel)
