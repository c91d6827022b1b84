"""`testbed report RUN_DIR`: one run's metrics, without a sweep around it.

Theory of operation. A run directory (docs/run-results.md) is read once
(testbed.analysis.runs.load_run); its captures, if it has any, become routing.json
(testbed.analysis.pcapmetrics.run_metrics: the cache a sweep's report would write too, now
with delays in emulated time and what each number means), and `summary` says in a page of
Markdown what the run did: its outcome, exploration steps under both of their names (the
step the last robot finished at, and the mean of the robots' finishing steps, which is what
Fig. 2 plots), how well the host kept the time scale, and the routing metrics in wall-clock
and emulated time, with this run's own numbers in the two explanations a reader needs (PDF
against segment delivery, mean delay against median); for a run on the ns3-wifi medium, the
802.11 channel's own counters (medium.json) beside them. The page goes to RUN_DIR/summary.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from common.jsonfile import write_atomic
from testbed.analysis import capturefiles, pcapmetrics
from testbed.analysis.runs import FinishedRun
from testbed.analysis.sweepinfo import seconds
from testbed.files.resultvalues import one_line
from testbed.files.routingfile import RoutingMetrics
from topology.spec import VETH

SUMMARY_NAME = "summary.md"


def _num(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def _outcome(run: FinishedRun) -> list[str]:
    c = run.config
    mean = run.exploration_steps
    lines = [
        f"Status **{run.status}**" + (f": {run.status_detail}" if run.status_detail else "") + ".",
        f"{c.robots} robot(s), range {c.comm_range:g} m, laser {c.laser_range:g} m, routing "
        f"{c.routing}, map {c.map_name}, loss {c.loss_pct:g} %, delay {c.delay_ms:g} ms, "
        f"seed {c.seed}" + (f", medium {c.medium}." if c.medium != VETH else "."),
        f"Steps run (when the last robot finished): {_num(run.steps, 'd')}; exploration "
        f"steps (mean of the robots' finishing steps, as Fig. 2 plots): {_num(mean, '.1f')}; "
        f"coverage at the end: {_num(run.coverage_final, '.1%')}.",
    ]
    stopped = [r for r in run.robots_by_number() if not r.counted]
    if stopped:
        names = ", ".join(f"{r.name} at step {r.stopped_step}" for r in stopped)
        lines.append(
            f"Stopped on purpose (--kill): {names}; the mean counts the other "
            f"{len(run.counted_robots)} robot(s)."
        )
    for o in run.isolated:
        back = f"back at step {o.back_step}" if o.back_step is not None else "until the end"
        lines.append(f"{o.robot} out of everyone's radio range (--isolate) from step "
                     f"{o.from_step}, {back}.")  # fmt: skip
    return lines


def _timing(run: FinishedRun) -> list[str]:
    ts, got = run.time_scale_requested or run.config.time_scale, run.time_scale_achieved
    line = f"Time scale requested {_num(ts, 'g')}, achieved {_num(got, 'g')}"
    line += f"; step deadlines missed: {run.deadlines_missed} ({run.deadline_miss_fraction:.1%})"
    stalls = run.host_stalls
    if stalls.events:
        line += (f", {stalls.deadlines_missed} of them in {stalls.events} host stall(s) "
                 f"({seconds(stalls.stalled_s)} s in all)")  # fmt: skip
    out = [line + "."]
    if run.faithful is False:
        out.append(f"**Not faithful to its time scale**: {run.fidelity_reason}: its results "
                   "may differ from a slower run's.")  # fmt: skip
    return out


def _routing_table(m: RoutingMetrics) -> list[str]:
    emu = m.emulated
    scale = emu.time_scale if emu else None
    rows = [
        "| metric | wall clock | emulated"
        + (f" (x {scale:g})" if scale else " (time scale unknown)")
        + " |",
        "|---|---|---|",
        f"| routing overhead (control / all packets) | {_num(m.overhead_packets, '.3f')} | same |",
        f"| packet delivery fraction (bytes, retransmissions included) | "
        f"{_num(m.pdf, '.3f')} | same |",
        f"| segment delivery (unique segments) | {_num(m.segment_delivery, '.3f')} | same |",
    ]
    corrected = m.relay_lag is not None  # ns3-wifi: the medium's relay lag taken out
    for key, name in (("mean", "mean"), ("median", "median"), ("p95", "95th percentile")):
        for k, what in (
            (f"delay_ms_{key}", ", corrected for the relay lag" if corrected else ""),
            *([(f"delay_raw_ms_{key}", ", raw")] if corrected else []),
        ):
            rows.append(
                f"| delay, {name}{what} (ms) | {_num(m.delay(k), '.3f')} | "
                f"{_num(emu.get(k) if emu else None, '.3f')} |"
            )
    bps, emu_bps = m.throughput_bps, emu.throughput_bps if emu else None
    rows.append(
        f"| throughput (kbit/s) | {_num(bps and bps / 1000, '.2f')} | "
        f"{_num(emu_bps and emu_bps / 1000, '.2f')} |"
    )
    return rows


def _explanations(m: RoutingMetrics) -> list[str]:
    """The two explanations, with this run's numbers."""
    out = []
    pdf, seg = m.pdf, m.segment_delivery
    if pdf is not None and seg is not None:
        out.append(
            f"PDF {pdf:.3f} against segment delivery {seg:.3f}: of the "
            f"{m.tcp_segments_sent} TCP segments the robots sent, "
            f"{m.tcp_segments_delivered} reached their destination at least once, in "
            f"{m.tcp_transmissions} transmissions (retransmissions included); PDF counts "
            "every transmission's bytes, so lost or repeated transmissions lower it even when "
            "every segment arrived in the end."
        )
    lag = m.relay_lag
    if lag:
        taken = lag.subtracted_ms_mean
        out.append(
            "The delays are corrected for the ns3-wifi medium's relay lag (the wall time its "
            "relaying of each frame added, beyond the channel's emulated time): "
            f"{lag.segments_corrected} segments had the lag of their hop frames taken out"
            + (f" ({taken:.3f} ms of wall time on average)" if taken is not None else "")
            + f", {lag.segments_uncorrected} could not be matched with the channel's "
            "records and keep their raw delay; the raw delays are in the rows marked raw."
        )
    mean, median = m.delay_ms_mean, m.delay_ms_median
    if mean is not None and median is not None:
        out.append(
            f"Mean delay {mean:.3f} ms against median {median:.3f} ms (wall clock): most "
            "segments cross a link that is up at once; a few wait for a route discovery or a "
            "TCP retransmission timeout, and those waits pull the mean far above the median "
            f"(95th percentile {_num(m.delay_ms_p95, '.3f')} ms)."
        )
    return out


def left_out_text(left_out: Mapping[str, str]) -> str:
    """ "r1.pcap (empty ...), r3.pcap (missing)": the captures a run's metrics left out."""
    shown = [f"{one_line(str(k), 80)} ({one_line(str(v), 120)})" for k, v in left_out.items()]
    return ", ".join(shown[:10]) + (f" and {len(shown) - 10} more" if len(shown) > 10 else "")


def _routing(m: RoutingMetrics | None, run_dir: Path | None = None) -> list[str]:
    if not m:
        left_out = {}
        if run_dir is not None:  # captures there, but none that could be read
            left_out = capturefiles.checked(capturefiles.find(run_dir)).left_out
        if left_out:
            return [f"No capture could be read, so no routing metrics: "
                    f"{left_out_text(left_out)}."]  # fmt: skip
        return ["No packet captures in this run (`testbed run --capture`): no routing metrics."]
    out = _routing_table(m)
    if m.captures_left_out:
        out += ["", f"**Captures left out** (no frame of theirs is counted, nor credited to "
                f"another robot): {left_out_text(m.captures_left_out)}."]  # fmt: skip
    for line in _explanations(m):
        out += ["", line]
    cmp = m.daemon_comparison
    if cmp and cmp.relative_difference is not None:
        out += [
            "",
            f"AODV control packets in the captures: {cmp.pcap_control_tx_packets}; the "
            f"daemons counted {cmp.daemon_tx_packets} sent "
            f"(difference {cmp.relative_difference:.2%}).",
        ]
    return out + ["", "All numbers and what each means: `routing.json` (its `about`)."]


def _channel(run: FinishedRun, metrics: RoutingMetrics | None = None) -> list[str]:
    """The 802.11 channel's counters (medium.json), for a run on ns3-wifi."""
    ch = run.channel
    if ch is None:
        return []
    c = run.config
    lines = [
        "## The 802.11 channel (ns3-wifi, from medium.json)",
        "",
        f"{c.wifi_standard or '80211a'} at {c.wifi_rate or 'its fastest rate'}; "
        f"{ch.duration_s:.1f} s of emulated time. Air in use (all robots' sending time over "
        f"that time): {_num(ch.airtime_share, '.2%')}; unacknowledged transmissions per frame "
        f"handed to the MAC: {_num(ch.retry_rate, '.3f')}; frames the MACs lost (retry limit, "
        f"full or expired queue): {ch.drops}; receptions lost (collisions, half duplex, "
        f"preamble missed): {int(ch.total('phy_rx_drops'))}. Relay lag: mean "
        f"{_num(ch.relay_lag_mean_ms, '.2f')} ms of emulated time, "
        f"{_num(ch.relay_lag_over_1ms, '.1%')} of frames over 1 ms late (more than a few "
        "percent: the host did not keep up with the time scale). "
        + (
            "The routing delays above have each frame's relay lag taken out."
            if metrics and metrics.relay_lag is not None
            else "The routing delays include the relay lag: this run did not record it "
            "per frame (relay-lag.bin)."
        ),
        "",
        "| robot | frames sent | delivered to it | retries | MAC drops | airtime (ms) |",
        "|---|---|---|---|---|---|",
    ]
    for r in ch.robots:
        name = f"{r.name} (display)" if r.name == f"r{c.robots + 1}" else r.name
        drops = r.retry_drops + r.queue_drops + r.queue_expired
        lines.append(f"| {name} | {r.frames_sent} | {r.frames_delivered} | {r.retries} | "
                     f"{drops} | {1000 * r.airtime_s:.1f} |")  # fmt: skip
    return lines + [""]


def summary(run: FinishedRun, metrics: RoutingMetrics | None) -> str:
    out = [f"# Run {run.run_id}", ""]
    for line in _outcome(run) + _timing(run):
        out += [line, ""]
    out += ["## Routing (from the captures)", ""] + _routing(metrics, run.path)
    if run.channel:
        out += [""] + _channel(run, metrics)
    return "\n".join(out) + "\n"


def write(run: FinishedRun) -> tuple[Path, RoutingMetrics | None]:
    """routing.json (when the run has captures) and summary.md; returns the summary's path
    and the metrics."""
    metrics = pcapmetrics.run_metrics(run.path, run=run)
    path = run.path / SUMMARY_NAME
    write_atomic(path, summary(run, metrics))  # never through a link (common.jsonfile)
    return path, metrics
