"""routing.json, a run's routing metrics from its packet captures, as one type: `RoutingMetrics`.

testbed.analysis.pcapmetrics computes the metrics and caches them in the run directory as
routing.json (`testbed metrics DIR` writes the same, less the captures' stamp, as a captured
network's metrics.json); every reader of them, the report's tables (routing, protocols, media,
middlewares), `testbed compare` and a run's summary, takes this type's fields instead of
picking keys out of the dict. What each number means is the file's own `about`
(testbed.analysis.routingnotes).

`parse(doc)` checks what the readers use: every number a number (bool is not one), the counts
(packets, bytes, segments, flows) not negative, the shares (PDF, overhead, segment delivery)
within 0 to 1, the time scale within common.timescale's bounds, the nested records
(`daemon_comparison`, `relay_lag`, `middleware`, `emulated`, `capture_dropped`,
`captures_left_out`) objects; a key that is absent is None (a run without TCP traffic has no
delays). Anything else is a ResultError of one line naming the key; `read(path)` reads
through the one bounded reader (common.boundedfile) and names the file too. `doc` keeps the
whole record as read (read-only), for the keys no reader picks (the per-robot counts) and for
writing it out again.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from common import timescale
from testbed.files.resultvalues import EMPTY, NUM, ResultError, get_mapping, get_value, read_json_as

ROUTING_NAME = "routing.json"
_WHOLE = (int,)


def _count(doc: Mapping[str, Any], key: str) -> float | None:
    value = get_value(doc, key, NUM)
    if value is not None and value < 0:
        raise ResultError(f"{key!r} is negative ({value})")
    return value


def _share(doc: Mapping[str, Any], key: str) -> float | None:
    value = get_value(doc, key, NUM)
    if value is not None and not 0 <= value <= 1:
        raise ResultError(f"{key!r} is {value}, not a share within 0 to 1")
    return value


def _nonneg(doc: Mapping[str, Any], key: str) -> float | None:
    value = get_value(doc, key, NUM)
    if value is not None and value < 0:
        raise ResultError(f"{key!r} is negative ({value})")
    return value


def _within(name: str, read: Any) -> Any:
    """`read()`, its ResultError prefixed with the nested record's name."""
    try:
        return read()
    except ResultError as e:
        raise ResultError(f"{name!r}: {e}") from None


@dataclass(frozen=True)
class DaemonComparison:
    """The captures' AODV transmit counts against the daemons' own (`daemon_comparison`)."""

    pcap_control_tx_packets: float | None = None
    daemon_tx_packets: float | None = None
    relative_difference: float | None = None

    @classmethod
    def parse(cls, d: Mapping[str, Any]) -> DaemonComparison:
        return cls(
            pcap_control_tx_packets=_count(d, "pcap_control_tx_packets"),
            daemon_tx_packets=_count(d, "daemon_tx_packets"),
            relative_difference=_nonneg(d, "relative_difference"),
        )


@dataclass(frozen=True)
class LagCorrection:
    """What the ns3-wifi relay-lag correction did to the delays (`relay_lag`)."""

    segments_corrected: float = 0
    segments_uncorrected: float = 0
    subtracted_ms_mean: float | None = None

    @classmethod
    def parse(cls, d: Mapping[str, Any]) -> LagCorrection:
        return cls(
            segments_corrected=_count(d, "segments_corrected") or 0,
            segments_uncorrected=_count(d, "segments_uncorrected") or 0,
            subtracted_ms_mean=get_value(d, "subtracted_ms_mean", NUM),
        )


@dataclass(frozen=True)
class MiddlewareTraffic:
    """The middleware's captured traffic (`middleware`): all its bytes and its own."""

    tx_bytes: float | None = None
    protocol_bytes: float | None = None

    @classmethod
    def parse(cls, d: Mapping[str, Any]) -> MiddlewareTraffic:
        return cls(tx_bytes=_count(d, "tx_bytes"), protocol_bytes=_count(d, "protocol_bytes"))


_DELAYS = ("delay_ms_mean", "delay_ms_median", "delay_ms_p95")
_RAW_DELAYS = ("delay_raw_ms_mean", "delay_raw_ms_median", "delay_raw_ms_p95")


@dataclass(frozen=True)
class Emulated:
    """The delays, duration and throughput in emulated time (`emulated`)."""

    time_scale: float
    delay_ms_mean: float | None = None
    delay_ms_median: float | None = None
    delay_ms_p95: float | None = None
    delay_raw_ms_mean: float | None = None
    delay_raw_ms_median: float | None = None
    delay_raw_ms_p95: float | None = None
    duration_s: float | None = None
    throughput_bps: float | None = None

    def get(self, key: str) -> float | None:
        """The emulated value of one of the wall-clock metrics (a delay, the throughput)."""
        return getattr(self, key)

    @classmethod
    def parse(cls, d: Mapping[str, Any]) -> Emulated:
        scale = get_value(d, "time_scale", NUM, required=True)
        if not timescale.valid(scale):
            raise ResultError(f"'time_scale': {timescale.refusal(scale)}")
        values = {k: get_value(d, k, NUM) for k in (*_DELAYS, *_RAW_DELAYS)}
        return cls(time_scale=scale, duration_s=_nonneg(d, "duration_s"),
                   throughput_bps=_nonneg(d, "throughput_bps"), **values)  # fmt: skip


# The wall-clock metrics at the file's top level the readers use: counts, shares, the rest.
_COUNTS = ("tx_packets", "tx_bytes", "control_tx_packets", "control_tx_bytes", "tcp_flows",
           "tcp_transmissions", "tcp_segments_sent", "tcp_segments_delivered")  # fmt: skip
_SHARES = ("pdf", "segment_delivery", "overhead_packets", "overhead_bytes")
_NONNEG = ("duration_s", "throughput_bps")


@dataclass(frozen=True)
class RoutingMetrics:
    """A run's routing.json (or a captured network's metrics.json): the fields the readers
    use, checked, and the whole record (`doc`)."""

    format: int | None = None
    duration_s: float | None = None  # wall seconds the captures span
    overhead_packets: float | None = None  # control packets over all packets transmitted
    overhead_bytes: float | None = None  # control bytes over all bytes transmitted
    pdf: float | None = None  # TCP payload bytes delivered over those transmitted
    segment_delivery: float | None = None
    delay_ms_mean: float | None = None  # wall ms (corrected for the relay lag, if any)
    delay_ms_median: float | None = None
    delay_ms_p95: float | None = None
    delay_raw_ms_mean: float | None = None  # uncorrected: only where `relay_lag` is
    delay_raw_ms_median: float | None = None
    delay_raw_ms_p95: float | None = None
    throughput_bps: float | None = None
    tx_packets: float | None = None
    tx_bytes: float | None = None
    control_tx_packets: float | None = None
    control_tx_bytes: float | None = None
    tcp_flows: float | None = None
    tcp_transmissions: float | None = None
    tcp_segments_sent: float | None = None
    tcp_segments_delivered: float | None = None
    relay_lag: LagCorrection | None = None  # None: the delays were not corrected
    middleware: MiddlewareTraffic | None = None
    daemon_comparison: DaemonComparison | None = None
    capture_dropped_packets: float | None = None
    captures_left_out: Mapping[str, str] = field(default_factory=lambda: EMPTY)
    emulated: Emulated | None = None  # None: the time scale is not known
    pcaps: Mapping[str, Any] | None = None  # the captures' content stamp (the cache's key)
    doc: Mapping[str, Any] = field(default_factory=lambda: EMPTY, repr=False, compare=False)

    def delay(self, key: str) -> float | None:
        """One of the delays by name (`delay_ms_median`, `delay_raw_ms_p95`, ...), wall ms."""
        if key not in (*_DELAYS, *_RAW_DELAYS):
            raise KeyError(key)
        return getattr(self, key)

    def count(self, key: str) -> float | None:
        """One of the counts by name (`control_tx_packets`, ...), for per-robot rates."""
        if key not in _COUNTS:
            raise KeyError(key)
        return getattr(self, key)

    def to_json(self) -> dict[str, Any]:
        """The record as read, to write out again."""
        return dict(self.doc)


def parse(doc: object) -> RoutingMetrics:
    """The RoutingMetrics of a routing.json's contents; ResultError (one line) when not one."""
    if not isinstance(doc, Mapping):
        raise ResultError("not a JSON object")
    values: dict[str, Any] = {k: _count(doc, k) for k in _COUNTS}
    values |= {k: _share(doc, k) for k in _SHARES}
    values |= {k: _nonneg(doc, k) for k in _NONNEG}
    values |= {k: get_value(doc, k, NUM) for k in (*_DELAYS, *_RAW_DELAYS)}
    nested: dict[str, Any] = {}
    for name, kind in (("relay_lag", LagCorrection), ("middleware", MiddlewareTraffic),
                       ("daemon_comparison", DaemonComparison),
                       ("emulated", Emulated)):  # fmt: skip
        part = get_mapping(doc, name)  # present, even empty: the record is there
        nested[name] = (
            _within(name, lambda p=part, k=kind: k.parse(p))
            if name in doc and doc[name] is not None
            else None
        )
    dropped = get_mapping(doc, "capture_dropped")
    left_out = get_mapping(doc, "captures_left_out")
    pcaps = get_mapping(doc, "pcaps")
    return RoutingMetrics(
        format=get_value(doc, "format", _WHOLE),
        capture_dropped_packets=_within("capture_dropped", lambda: _count(dropped, "packets")),
        captures_left_out=left_out,
        pcaps=pcaps or None,
        doc=get_mapping({"d": doc}, "d"),
        **values,
        **nested,
    )


def read(path: str | os.PathLike[str]) -> RoutingMetrics:
    """The routing.json (or metrics.json) at `path`; ResultError (one line, naming the file)
    when it is missing, unreadable or not one."""
    return read_json_as(path, parse)
