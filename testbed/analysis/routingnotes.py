"""What routing.json's numbers mean, said in the file itself, and its delays in emulated time.

Theory of operation. The captures are stamped by the host's clock, so pcapmetrics measures
delays and throughput in wall-clock time, while the robots live in emulated time, which runs
`time_scale` times faster (docs/architecture.md: a step is 100 ms of emulated time). A delay
of d wall seconds is d x time_scale emulated seconds, and a throughput of b bits per wall
second is b / time_scale bits per emulated second. `emulated` gives those, with the time
scale the step loop achieved (the one requested where the run did not record it). `ABOUT`
explains the two pairs of numbers that look contradictory at first sight: the packet
delivery fraction against segment delivery, and the mean delay against the median.
"""

from __future__ import annotations

ABOUT = {
    "pdf": (
        "packet delivery fraction: the TCP payload bytes the destinations received over the "
        "bytes the sources transmitted, every retransmission included. A segment sent twice "
        "and received once counts as one of two delivered: this is what link loss lowers."
    ),
    "segment_delivery": (
        "unique TCP segments that reached their destination at least once, over those sent. "
        "TCP retransmits what was lost, so this stays near 1 unless a connection broke. PDF "
        "below segment_delivery (e.g. 0.957 against 1.0) means every segment arrived, but "
        "some of the transmissions were lost or sent again (tcp_transmissions against "
        "tcp_segments_sent)."
    ),
    "delay": (
        "end-to-end delay of each delivered segment: its first reception at the destination "
        "minus its first transmission at the source. Most segments cross a link that is up "
        "in microseconds, so the median is tiny (e.g. 0.010 ms); a few wait for a route "
        "discovery or a TCP retransmission timeout (tens to hundreds of ms), which pulls the "
        "mean far above the median (e.g. 11.2 ms). The median is the typical segment, the "
        "mean includes the waits, p95 is the tail."
    ),
    "time": (
        "duration_s, delay_ms_* and throughput_bps are host wall-clock, as the kernel stamped "
        "the captures. Emulated time runs time_scale times faster: under 'emulated', delays "
        "are wall x time_scale and throughput is wall / time_scale (bits per emulated second)."
    ),
}

RELAY_LAG = (
    "ns3-wifi only: delay_ms_* are corrected for the medium's relay lag. The channel relays "
    "each frame twice a hop (Linux to the simulator, the simulator to Linux) and each relay "
    "takes wall time the channel's emulated time does not account for; it recorded that lag "
    "per frame (relay-lag.bin), and each segment's delay has the lag of the hop frames its "
    "received copy travelled taken out. What is left is the channel's own delay (airtime, "
    "contention, back-off, MAC retries, route discoveries, TCP retransmissions) and the "
    "robots' kernels. delay_raw_ms_* are the uncorrected delays; relay_lag says how many "
    "segments were corrected, how many could not be matched (left uncorrected) and how much "
    "was taken out."
)

_DELAYS = ("delay_ms_mean", "delay_ms_median", "delay_ms_p95")
_RAW_DELAYS = ("delay_raw_ms_mean", "delay_raw_ms_median", "delay_raw_ms_p95")


def about(relay_lag_corrected: bool = False) -> dict:
    """ABOUT, with what the relay-lag correction means when the delays had it."""
    return {**ABOUT, "relay_lag": RELAY_LAG} if relay_lag_corrected else ABOUT


def emulated(metrics: dict, time_scale: float | None) -> dict | None:
    """Delays, duration and throughput of `metrics` in emulated time; None without a scale."""
    if not time_scale:
        return None
    out: dict = {"time_scale": time_scale}
    raw = _RAW_DELAYS if _RAW_DELAYS[0] in metrics else ()
    for key in (*_DELAYS, *raw, "duration_s"):
        value = metrics.get(key)
        out[key] = None if value is None else value * time_scale
    bps = metrics.get("throughput_bps")
    out["throughput_bps"] = None if bps is None else bps / time_scale
    return out
