"""What perfect links get wrong: the same runs on veth and on ns-3's 802.11 channel.

Theory of operation
-------------------
A media sweep (testbed/experiments/media.toml) runs every point of its grid once per medium
(`veth`, perfect links switched by range; `ns3-wifi`, one shared 802.11 channel with
contention, collisions and retries: docs/ns3-medium.md) on the same seeds. Per run
(`run_row`) it takes the measures of the paper's Section 2.4 and the exploration's cost:

- exploration steps (as Fig. 2);
- packet delivery fraction and median end-to-end delay of the robots' TCP traffic, from the
  captures (testbed.analysis.pcapmetrics); the delay in emulated ms (wall ms x the time
  scale the run achieved), so runs a sweep slowed down compare with the others. On ns3-wifi
  the delay is corrected for the medium's relay lag where the run recorded it
  (relay-lag.bin, testbed.analysis.relaylag): the channel's table gives the raw median
  beside it and how many runs were corrected;
- control overhead: routing control packets and bytes per robot per second of robot time,
  and their share of airtime, i.e. of the time the transmitters' radios spend sending. A
  frame's airtime is that of the run's 802.11 PHY (`frame_airtime_s`: preamble and header,
  then the MAC frame at the data rate); a small control frame costs far more airtime than
  its share of bytes says, because the preamble dominates at 54 Mbit/s. On veth the same
  estimate says what the run's traffic would have taken on the default 802.11a channel.
  Only transmissions seen in the captures count (no ACKs, no MAC retries): the channel's
  own counters (`channel_*`, from medium.json: retries per frame, frames lost in the MAC,
  the share of time the air was in use, the relay lag) say what the air added.

`point_rows` gives each measure's mean and 95% interval (Student t, testbed.analysis.stats)
per (routing, range, team size, medium); `section` sets veth beside ns3-wifi point by point
and says, per measure, where veth's answer is within the noise of 802.11's: the two 95%
intervals overlap (stats.separated, the rule the report uses everywhere). A point with one
run per medium has no interval: its noise is unknown and it is counted apart.
"""

from __future__ import annotations

import math
import re
import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from testbed.analysis import stats
from testbed.analysis.rows import INLINE, MeanCI, Measures
from testbed.analysis.runs import FinishedRun
from testbed.files.routingfile import RoutingMetrics
from topology.spec import NS3_WIFI as WIFI
from topology.spec import VETH

MEDIA_ORDER = (VETH, WIFI)
# (key, name in the table and sentences, format)
COMPARED = (
    ("steps", "exploration steps", ".0f"),
    ("pdf", "packet delivery fraction", ".3f"),
    ("delay_ms", "median delay (emulated ms)", ".2f"),
    ("control_pkts_per_robot_s", "control packets per robot per second", ".2f"),
    ("control_bytes_per_robot_s", "control bytes per robot per second", ".0f"),
    ("control_airtime_share", "control share of airtime", ".3f"),
)
CHANNEL = ("channel_airtime_share", "channel_retry_rate", "channel_drops",
           "channel_relay_lag_ms", "channel_relay_lag_over_1ms", "delay_raw_ms")  # fmt: skip
NOISE_RULE = (
    "veth's answer is within the noise of 802.11's at a point when the 95% intervals of the "
    "two means overlap (the report's rule for a difference beyond noise, Student t); a point "
    "with a single run on either medium has no interval and is counted apart."
)

# ---------------------------------------------------------------- airtime of a frame

# 802.11 adds to an Ethernet frame (whose length includes its 14-byte header): a 24-byte MAC
# header, an 8-byte LLC/SNAP header and a 4-byte FCS, i.e. 22 bytes more.
WIFI_OVERHEAD_BYTES = 22
# standard -> (PHY family, fastest rate in Mbit/s): what ns3-wifi uses without --wifi-rate.
STANDARDS = {"80211a": ("ofdm", 54.0), "80211g": ("erp", 54.0), "80211b": ("dsss", 11.0)}
DEFAULT_STANDARD = "80211a"
_RATE = re.compile(r"(\d+)(?:_(\d+))?Mbps$")


def phy_of(standard: str | None, rate: str | None) -> tuple[str, float]:
    """(PHY family, data rate in Mbit/s) of a run: an ns-3 WifiMode name such as
    OfdmRate12Mbps or DsssRate5_5Mbps gives its rate; none, or minstrel (whose rate varies),
    the standard's fastest. veth runs (no standard) are priced at 802.11a's."""
    family, fastest = STANDARDS.get(standard or DEFAULT_STANDARD, STANDARDS[DEFAULT_STANDARD])
    m = _RATE.search(rate or "")
    if not m or rate is None:  # (a match means a rate)
        return family, fastest
    mbps = float(m[1]) + (float(f"0.{m[2]}") if m[2] else 0.0)
    if rate.startswith("Dsss"):
        family = "dsss"
    return family, mbps


def frame_airtime_s(eth_bytes: float, family: str, mbps: float) -> float:
    """Seconds an 802.11 PHY sends one frame carrying `eth_bytes` of Ethernet frame.

    OFDM (802.11a): a 20 us preamble and SIGNAL field, then 4 us symbols of
    4 x mbps data bits each carrying the 16-bit SERVICE field, the MAC frame and 6 tail bits;
    ERP-OFDM (802.11g) adds a 6 us signal extension; DSSS and HR/DSSS (802.11b): a 192 us
    long preamble and PLCP header, then the MAC frame at the data rate."""
    bits = 8 * (eth_bytes + WIFI_OVERHEAD_BYTES)
    if family == "dsss":
        return 192e-6 + bits / (mbps * 1e6)
    symbols = math.ceil((16 + bits + 6) / (4 * mbps))
    return 20e-6 + 4e-6 * symbols + (6e-6 if family == "erp" else 0.0)


def traffic_airtime_s(packets: float, eth_bytes: float, family: str, mbps: float) -> float:
    """Airtime of `packets` frames of `eth_bytes` in all, priced at their mean size."""
    if not packets:
        return 0.0
    return packets * frame_airtime_s(eth_bytes / packets, family, mbps)


# ---------------------------------------------------------------- rows


@dataclass(frozen=True)
class MediaRun:
    """One run's numbers for the media comparison."""

    run: str
    medium: str
    routing: str
    comm_range: float
    robots: int
    steps: float | None
    pdf: float | None
    delay_ms: float | None
    control_pkts_per_robot_s: float | None
    control_bytes_per_robot_s: float | None
    control_airtime_share: float | None
    channel_airtime_share: float | None
    channel_retry_rate: float | None
    channel_drops: int | None
    channel_relay_lag_ms: float | None
    channel_relay_lag_over_1ms: float | None
    # ns3-wifi: the median delay before the relay-lag correction (None: not corrected)
    delay_raw_ms: float | None
    delay_lag_corrected: bool


@dataclass(frozen=True)
class MediaCompared(Measures):
    """The COMPARED measures of a point: each one's mean and 95% interval."""

    steps: MeanCI
    pdf: MeanCI
    delay_ms: MeanCI
    control_pkts_per_robot_s: MeanCI
    control_bytes_per_robot_s: MeanCI
    control_airtime_share: MeanCI


@dataclass(frozen=True)
class ChannelMeans:
    """The CHANNEL measures of a point: each one's mean over its runs (None: no run had it)."""

    channel_airtime_share: float | None
    channel_retry_rate: float | None
    channel_drops: float | None
    channel_relay_lag_ms: float | None
    channel_relay_lag_over_1ms: float | None
    delay_raw_ms: float | None


@dataclass(frozen=True)
class MediaPoint:
    """Per (routing, range, team, medium): the compared measures with their intervals, the
    channel's means, and in how many runs the delay was corrected for the relay lag."""

    routing: str
    comm_range: float
    robots: int
    medium: str
    n: int
    compared: MediaCompared = field(metadata=INLINE)
    channel: ChannelMeans = field(metadata=INLINE)
    delay_lag_corrected_runs: int


COMPARED_KEYS = tuple(f.name for f in fields(MediaCompared))


def _control_airtime_share(run: FinishedRun, metrics: RoutingMetrics) -> float | None:
    tx_p, tx_b = metrics.tx_packets, metrics.tx_bytes
    ctl_p, ctl_b = metrics.control_tx_packets, metrics.control_tx_bytes
    if not tx_p or tx_b is None or ctl_p is None or ctl_b is None:
        return None
    phy = phy_of(run.config.wifi_standard, run.config.wifi_rate)
    total = traffic_airtime_s(tx_p, tx_b, *phy)
    return traffic_airtime_s(ctl_p, ctl_b, *phy) / total if total else None


def run_row(run: FinishedRun, metrics: RoutingMetrics | None) -> MediaRun:
    """One run's numbers (`metrics`: its routing.json, or None without captures)."""
    c = run.config
    m = metrics or RoutingMetrics()
    scale = run.time_scale_ran
    ch = run.channel
    raw, median = m.delay_raw_ms_median, m.delay_ms_median
    return MediaRun(
        run=run.run_id,
        medium=c.medium,
        routing=c.routing,
        comm_range=c.comm_range,
        robots=c.robots,
        steps=run.exploration_steps,
        pdf=m.pdf,
        delay_ms=median * scale if median is not None else None,
        control_pkts_per_robot_s=run.captured_per_robot_s(m, "control_tx_packets"),
        control_bytes_per_robot_s=run.captured_per_robot_s(m, "control_tx_bytes"),
        control_airtime_share=_control_airtime_share(run, m) if metrics else None,
        channel_airtime_share=ch.airtime_share if ch else None,
        channel_retry_rate=ch.retry_rate if ch else None,
        channel_drops=ch.drops if ch else None,
        channel_relay_lag_ms=ch.relay_lag_mean_ms if ch else None,
        channel_relay_lag_over_1ms=ch.relay_lag_over_1ms if ch else None,
        delay_raw_ms=raw * scale if raw is not None else None,
        delay_lag_corrected=m.relay_lag is not None,
    )


def _present(items: list[MediaRun], key: str) -> list[float]:
    return [v for i in items if (v := getattr(i, key)) is not None]


def point_rows(per_run: list[MediaRun]) -> list[MediaPoint]:
    """Per (routing, range, team, medium): each measure's mean and, for the compared ones,
    its 95% interval (`KEY_ci_low`, `KEY_ci_high`; None for fewer than two runs)."""
    groups: dict[tuple[str, float, int, str], list[MediaRun]] = {}
    for r in per_run:
        key = (r.routing, r.comm_range, r.robots, r.medium)
        groups.setdefault(key, []).append(r)
    order = {m: i for i, m in enumerate(MEDIA_ORDER)}
    out = []
    for key, items in sorted(groups.items(), key=lambda kv: (*kv[0][:3], order.get(kv[0][3], 9))):
        compared = MediaCompared(**{k: MeanCI.of(_present(items, k)) for k in COMPARED_KEYS})
        means = {}
        for k in CHANNEL:
            vals = _present(items, k)
            means[k] = statistics.fmean(vals) if vals else None
        out.append(MediaPoint(*key, len(items), compared, ChannelMeans(**means),
                              sum(bool(i.delay_lag_corrected) for i in items)))  # fmt: skip
    return out


def tables(
    runs: list[FinishedRun], metrics: Mapping[str, RoutingMetrics | None]
) -> tuple[list[MediaRun], list[MediaPoint]]:
    """(per-run rows of the usable runs, point rows) of a sweep's runs; `metrics`: each run
    id's pcapmetrics (or None)."""
    per_run = [run_row(r, metrics.get(r.run_id)) for r in runs if r.usable]
    return per_run, point_rows(per_run)


def ci(row: MediaPoint, key: str) -> tuple[float, float, float] | None:
    """(mean, low, high) of a point row's measure, None without an interval."""
    return row.compared.of(key).ci


# ---------------------------------------------------------------- the section


def pairs(rows: list[MediaPoint]) -> dict[tuple, dict[str, MediaPoint]]:
    """{(routing, range, team): {medium: row}} for the points that ran both media."""
    points: dict[tuple, dict[str, MediaPoint]] = {}
    for r in rows:
        points.setdefault((r.routing, r.comm_range, r.robots), {})[r.medium] = r
    return {k: v for k, v in points.items() if VETH in v and WIFI in v}


def _label(point: tuple) -> str:
    routing, comm, robots = point
    return f"{routing}, {comm:g} m, {robots} robots"


def noise_sentence(key: str, name: str, spec: str, both: dict[tuple, dict[str, MediaPoint]]) -> str:
    """One sentence for one measure: at which points veth's answer is within the noise of
    802.11's, at which it is not (and which way), at which the noise is unknown."""
    within, beyond, unknown = [], [], []
    for point, by in both.items():
        v, w = by[VETH], by[WIFI]
        if v.compared.of(key).mean is None or w.compared.of(key).mean is None:
            continue
        cv, cw = ci(v, key), ci(w, key)
        if cv is None or cw is None:
            unknown.append(point)
        elif stats.separated(cv, cw):
            way = "above" if cv[0] > cw[0] else "below"
            beyond.append(
                f"{_label(point)}: veth {format(cv[0], spec)} {way} 802.11's {format(cw[0], spec)}"
            )
        else:
            within.append(point)
    judged = len(within) + len(beyond)
    head = f"- {name[0].upper()}{name[1:]}: "
    if not judged and not unknown:
        return head + "no point has it on both media."
    one_run = f"{len(unknown)} point(s) with one run on a medium (noise unknown)"
    if not judged:
        return head + f"not judged: {one_run}."
    text = head + f"veth is within the noise of 802.11 at {len(within)} of {judged} points"
    text += f"; beyond it at {'; '.join(beyond)}" if beyond else " (all)"
    return text + (f"; not judged: {one_run}." if unknown else ".")


def _cell(row: MediaPoint, key: str, spec: str) -> str:
    m = row.compared.of(key)
    if m.mean is None:
        return "–"
    c = m.ci
    if c is None:
        return format(m.mean, spec)
    return f"{format(c[0], spec)} [{format(c[1], spec)}, {format(c[2], spec)}]"


def _fmt(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def section(rows: list[MediaPoint]) -> list[str]:
    """The report's "What perfect links get wrong" section (empty unless the sweep ran more
    than one medium)."""
    if len({r.medium for r in rows}) < 2:
        return []
    both = pairs(rows)
    out = ["## What perfect links get wrong: veth against 802.11 (ns3-wifi)", ""]
    out += [
        "Each point ran on both media with the same seeds. Every cell: the mean over the "
        "point's runs with its 95% interval in brackets (Student t). Delay: median of the "
        "robots' TCP segments in emulated ms; on ns3-wifi, corrected for the medium's relay "
        "lag (each segment less the lag its hop frames recorded as the channel relayed them: "
        "docs/ns3-medium.md) in the runs that recorded it, which the channel's table counts. "
        "Control traffic per robot per second of robot "
        "time, from the captures; its share of airtime is the share of the radios' sending "
        "time that routing control took, each captured frame priced at the run's 802.11 PHY "
        "(veth: what 802.11a at 54 Mbit/s would have taken; no ACKs or retries counted). "
        "The paper's figures and verdicts above are drawn from the veth runs alone.",
        "",
        "| routing | range (m) | robots | medium | runs | "
        + " | ".join(name for _, name, _ in COMPARED)
        + " |",
        "|---|---|---|---|---|" + "---|" * len(COMPARED),
    ]
    for r in rows:
        cells = " | ".join(_cell(r, k, spec) for k, _, spec in COMPARED)
        out.append(
            f"| {r.routing} | {r.comm_range:g} | {r.robots} | {r.medium} | {r.n} | {cells} |"
        )
    out += ["", f"**Rule.** {NOISE_RULE}", ""]
    if not both:
        out += ["No point ran on both media: nothing to compare.", ""]
    else:
        out += [f"**Within the noise?** Over {len(both)} point(s) that ran on both media:", ""]
        out += [noise_sentence(k, name, spec, both) for k, name, spec in COMPARED] + [""]
    return out + _channel_lines(rows)


def _channel_lines(rows: list[MediaPoint]) -> list[str]:
    """What the 802.11 channel itself counted, per ns3-wifi point (medium.json)."""
    wifi = [r for r in rows if r.medium == WIFI and r.channel.channel_airtime_share is not None]
    if not wifi:
        return []
    out = [
        "The 802.11 channel's own counters (medium.json, means over the runs): the air in "
        "use (all robots' sending time over the run's emulated time), unacknowledged "
        "transmissions per frame handed to the MAC, frames the MACs lost (retry limit, full "
        "or expired queue), and how late the channel relayed frames (emulated ms; the share "
        "over 1 ms says when the host could not keep up with the time scale); then the "
        "median delay before the relay lag was taken out of it, and in how many of the "
        "point's runs it was (runs made before the channel recorded each frame's lag keep "
        "their raw delay in the table above).",
        "",
        "| routing | range (m) | robots | air in use | retries / frame | MAC drops | "
        "relay lag (ms) | relayed > 1 ms late | median delay, raw (emulated ms) | "
        "delay corrected for the lag |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in wifi:
        ch = r.channel
        out.append(
            f"| {r.routing} | {r.comm_range:g} | {r.robots} | "
            f"{_fmt(ch.channel_airtime_share, '.3f')} | "
            f"{_fmt(ch.channel_retry_rate, '.3f')} | {_fmt(ch.channel_drops, '.1f')} | "
            f"{_fmt(ch.channel_relay_lag_ms, '.2f')} | "
            f"{_fmt(ch.channel_relay_lag_over_1ms, '.1%')} | "
            f"{_fmt(ch.delay_raw_ms, '.2f')} | {r.delay_lag_corrected_runs} of {r.n} |"
        )
    return out + [""]
