"""Routing metrics of a run from its packet captures (the paper's Section 2.4).

Theory of operation. Each robot K has one capture, `pcaps/rK.pcap`, of its own `wlan0`; all
captures are stamped by the host clock. `read_pcaps` turns a run's captures into frames with a
single tshark invocation (`-T fields`, first occurrence of each field): mergecap joins them as
separate interfaces and `frame.interface_id` says whose capture each frame came from. A
capture on a veth does not mark direction, so a robot's own MAC address is inferred: the most
common Ethernet source of frames whose IP source is the robot's address. Frames from that MAC
were *transmitted* by the robot (its own traffic and what it forwards); the rest were received.

`compute` is pure (frames in, numbers out) and defines the metrics:

- routing overhead: routing control packets transmitted (on the protocol's UDP port in
  topology.protocols: 654 for AODV, 6696 for babel, 4305 for batman), counted once per
  transmission at the transmitter, so a rebroadcast RREQ counts at every robot that
  rebroadcasts it; as a fraction of all frames transmitted, and in bytes
  (frame bytes against all frame bytes). AODV messages are also counted by type (RREQ, RREP,
  HELLO = RREP broadcast with IP TTL 1, RERR, RREP-ACK) and in UDP payload bytes, the unit
  the daemon's own counters use.
- packet delivery fraction (`pdf`): of the TCP payload the robots transmitted as sources
  (every transmission, retransmissions included), the fraction their destinations received:
  a segment sent twice and received once is one of two delivered. This is what link loss
  lowers. It is counted in bytes, not frames, so it stays right when GSO/GRO merge or split
  segments between the two captures. `segment_delivery` counts unique segments instead,
  matched by (src, dst, ports, raw sequence number): a segment is delivered when j received
  one covering its first byte; TCP's retransmissions keep it near 1 unless connections break.
- end-to-end delay: first reception in j's capture minus first transmission in i's. On the
  ns3-wifi medium, when the run kept the channel's per-frame relay lag (relay-lag.bin,
  testbed.analysis.relaylag), `delay_ms_*` are corrected: each segment's delay less the lag
  of the hop frames its first received copy travelled (what the medium's relaying added in
  wall time, beyond the channel's airtime, contention and retries); `delay_raw_ms_*` keep
  the uncorrected values, and segments whose hops could not all be matched stay
  uncorrected and are counted (`relay_lag`). A run without that file (veth, or older
  ns3-wifi runs) has the raw delays under `delay_ms_*` and none of these keys.
- throughput: delivered TCP payload bytes over the span of the captures, in bit/s.
- the middleware's traffic (`middleware`), a class of its own: the frames each robot
  transmitted on the middleware's ports. Over TCP (nanomsg, zeromq, zeromq-reqrep, zenoh:
  to or from the goal port, GOAL_PORT), split into TCP's own (no payload: handshakes, ACKs,
  FIN/RST) and those with data; the data, reassembled per connection and direction, is
  walked in the middleware's framing (testbed.analysis.mwframing) into the robots' messages
  (`message_bytes`) and the middleware's own bytes (`protocol_bytes`: nanomsg's SP headers
  and length prefixes, ZeroMQ's greetings, commands, frame headers and REQ/REP's delimiters
  and empty replies, Zenoh's batch lengths, handshakes, keep-alives, declarations and the
  headers around each message). Retransmitted payload is counted apart. Over UDP (dds: to or
  from DDS_PORTS), each datagram's RTPS (testbed.analysis.rtps) into the messages and
  Cyclone's own: discovery, reliability, headers; a DATA that DDS retransmitted is counted
  apart. `protocol_by_kind` breaks the own bytes down. The metrics above still count all
  TCP, as before.

Times are host wall-clock: with a time scale K, emulated time runs K times faster, so delays
and throughput are those the kernel saw. `run_metrics` applies this to a run directory,
compares the AODV counts with the daemons' own counters (aodv/rK.json, where present), adds
the delays and throughput in emulated time and what each number means
(testbed.analysis.routingnotes) and caches the result in the run directory as routing.json.

The parts: testbed.analysis.pcapread reads the captures into frames,
testbed.analysis.framecounts counts each robot's frames (control traffic, TCP deliveries and
delays), testbed.analysis.mwtraffic the middleware's traffic; `compute` puts them together.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from common import boundedfile
from common.jsonfile import write_json_atomic
from testbed.analysis import capturefiles, relaylag, routingnotes, runs
from testbed.analysis.capturefiles import capture_drops, daemon_counts
from testbed.analysis.framecounts import (
    CONTROL_PORTS,
    _control_totals,
    _deliveries,
    _delivery_metrics,
    _lag_metrics,
    _robot_counts,
    _Traffic,
)
from testbed.analysis.mwtraffic import (
    DATAGRAM_FRAMINGS,
    MIDDLEWARE_FRAMING,
    _middleware_counts,
    _middleware_totals,
)
from testbed.analysis.mwtraffic import DDS_PORTS as DDS_PORTS
from testbed.analysis.mwtraffic import GOAL_PORT as GOAL_PORT
from testbed.analysis.pcapread import _FIELDS as _FIELDS
from testbed.analysis.pcapread import Frame, read_pcaps
from testbed.analysis.pcapread import _int as _int
from testbed.analysis.pcapread import _tshark_argv as _tshark_argv
from testbed.analysis.pcapread import parse_fields as parse_fields
from testbed.analysis.pcapread import read_pcap as read_pcap
from testbed.files import routingfile
from testbed.files.resultconfig import DEFAULT_ROUTING
from testbed.files.routingfile import RoutingMetrics
from topology.names import LAG_FILE, robot_addr

log = logging.getLogger(__name__)

CACHE_NAME = routingfile.ROUTING_NAME
# 3: "emulated" and "about"; 4: "tcp_flows"; 5: relay-lag correction, or "middleware";
# 6: both; 7: the middleware's traffic for zenoh and dds, and by kind
CACHE_FORMAT = 8
DEFAULT_MIDDLEWARE = "nanomsg"  # the only one before there was a choice


def compute(
    captures: dict[int, list[Frame]],
    addrs: dict[int, str],
    port: int = 654,
    *,
    lags: list[relaylag.LagRecord] | None = None,
    middleware: str = DEFAULT_MIDDLEWARE,
) -> dict:
    """Routing metrics of one run from each robot's frames (see the module docstring); with
    `lags`, the ns3-wifi channel's relay-lag records, delays are corrected for them; the
    goal messages' port is counted as `middleware`'s traffic."""
    traffic = _Traffic(sources=set(addrs.values()))
    robots = {
        f"r{k}": _robot_counts(frames, addrs[k], port, traffic)
        for k, frames in sorted(captures.items())
    }
    duration = (traffic.t_max - traffic.t_min) if traffic.t_max > traffic.t_min else 0.0
    index = relaylag.LagIndex(lags) if lags is not None else None
    delivery = _deliveries(traffic, index, {a: k for k, a in addrs.items()})
    framing = MIDDLEWARE_FRAMING.get(middleware)  # rtps: the frames need UDP's payload
    if framing is not None:
        for k, frames in captures.items():
            r = robots[f"r{k}"]
            r["middleware"] = _middleware_counts(frames, addrs[k], r["mac"], framing)
    return {
        "format": CACHE_FORMAT,
        "control_port": port,
        "duration_s": duration,
        **_control_totals(robots),
        **_delivery_metrics(traffic, delivery, duration),
        **(_lag_metrics(delivery, len(lags)) if lags is not None else {}),
        "middleware": _middleware_totals(middleware, framing, robots),
        "robots": robots,
    }


# ---------------------------------------------------------------- the AODV daemons' counters


def _rel(a: float, b: float) -> float | None:
    return abs(a - b) / b if b else (0.0 if a == b else None)


def compare_with_daemons(metrics: dict, daemons: dict[str, dict] | None) -> dict | None:
    """The captures' AODV transmit counts against the daemons' own (robots with both)."""
    if not daemons or not metrics.get("robots"):
        return None
    robots = metrics["robots"]
    both = [k for k in daemons if k in robots]
    pcap_pkts = sum(robots[k]["control_tx_packets"] for k in both)
    pcap_bytes = sum(robots[k]["control_tx_payload_bytes"] for k in both)
    d_pkts = sum(daemons[k]["packets"] for k in both)
    d_bytes = sum(daemons[k]["bytes"] for k in both)
    by_type: dict[str, dict] = {}
    for k in both:
        for kind, n in daemons[k]["by_type"].items():
            by_type.setdefault(kind, {"pcap": 0, "daemon": 0})["daemon"] += n
        for kind, n in robots[k].get("aodv_tx_by_type", {}).items():
            by_type.setdefault(kind, {"pcap": 0, "daemon": 0})["pcap"] += n
    return {
        "robots": both,
        "pcap_control_tx_packets": pcap_pkts,
        "daemon_tx_packets": d_pkts,
        "relative_difference": _rel(pcap_pkts, d_pkts),
        "pcap_control_tx_payload_bytes": pcap_bytes,
        "daemon_tx_bytes": d_bytes,
        "relative_difference_bytes": _rel(pcap_bytes, d_bytes),
        "by_type": by_type,
        "per_robot": {
            k: {"pcap": robots[k]["control_tx_packets"], "daemon": daemons[k]["packets"]}
            for k in both
        },
    }


# ---------------------------------------------------------------- a run directory


def run_metrics(
    run_dir: str | Path,
    use_cache: bool = True,
    run: runs.FinishedRun | None = None,
    network: tuple[str, float | None] | None = None,
) -> RoutingMetrics | None:
    """Routing metrics of one run directory (None if it has no captures), cached in its
    routing.json (its type: testbed.files.routingfile; a cache that is not one is computed
    again). `run` (its routing says whose control port to count, its time scale turns
    delays into emulated time) is read from the directory when not given; `network`, the
    (routing, time scale) of a `net up --capture` network, stands in for a run that has none."""
    run_dir = Path(run_dir)
    found = capturefiles.find(run_dir)
    pcaps = found.paths
    if not pcaps:
        return None
    cache = run_dir / CACHE_NAME
    lag_path = run_dir / LAG_FILE
    stamped = [*pcaps.values(), *([lag_path] if boundedfile.regular(lag_path) else [])]
    stamp = capturefiles.content_stamp(stamped)  # content, not sizes and mtimes
    if use_cache:
        try:
            cached = routingfile.read(cache) if boundedfile.regular(cache) else None
        except routingfile.ResultError as e:
            log.warning("%s: computed again", e)
            cached = None
        if (cached is not None and cached.format == CACHE_FORMAT
                and dict(cached.pcaps or {}) == stamp):  # fmt: skip
            why = capturefiles.cache_refusal(dict(cached.doc))
            if why is None:
                return cached
            log.warning("%s: not taken (%s): computed again", cache, why)
    found = capturefiles.checked(found)  # what tshark is given: whose each is, bounded
    pcaps = found.paths
    if not pcaps:
        return None
    if run is None and network is None:
        try:
            run = runs.load_run(run_dir)
        except runs.ResultError as e:
            log.warning("%s; counting AODV's port, wall-clock time only", e)
    scale: float | None
    if run is not None:
        routing = run.config.routing
        scale = run.time_scale_ran
    else:
        routing, scale = network or (DEFAULT_ROUTING, None)
    lags = None
    if lag_path.is_file():
        try:
            lags, partial = relaylag.read_records(lag_path)
        except (OSError, relaylag.LagFileError) as e:
            raise runs.ResultError(str(e)) from None
        if partial:
            log.warning("%s: a record cut short at its end (%d bytes) left out", lag_path, partial)
    middleware = run.config.middleware if run is not None else DEFAULT_MIDDLEWARE
    rtps_read = MIDDLEWARE_FRAMING.get(middleware) in DATAGRAM_FRAMINGS
    captures = read_pcaps(pcaps, udp_payload=True) if rtps_read else read_pcaps(pcaps)
    port = CONTROL_PORTS.get(routing)
    if port is None:  # not AODV's port in silence: a routing no entry of topology.protocols has
        log.warning("%s: routing %r is not a registered protocol: no control traffic counted",
                    run_dir, routing)  # fmt: skip
    metrics = compute(
        captures, {k: robot_addr(k) for k in pcaps}, port or 0,
        lags=lags, middleware=middleware,
    )  # fmt: skip
    metrics["pcaps"] = stamp
    metrics["captures_left_out"] = found.left_out
    metrics["daemon_comparison"] = compare_with_daemons(metrics, daemon_counts(run_dir))
    drops = capture_drops(run_dir)
    metrics["capture_dropped"] = {"packets": sum(drops.values()), "per_robot": drops}
    metrics["emulated"] = routingnotes.emulated(metrics, scale)
    metrics["about"] = routingnotes.about(lags is not None)
    try:
        write_json_atomic(cache, metrics)
    except OSError as e:
        log.warning("cannot cache routing metrics in %s: %s", run_dir, e)
    try:
        return routingfile.parse(metrics)
    except routingfile.ResultError as e:
        raise runs.ResultError(f"{run_dir}: routing metrics: {e}") from None


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO)
    for d in sys.argv[1:]:
        m = run_metrics(d, use_cache=False)
        shown = {k: v for k, v in m.to_json().items() if k != "robots"} if m else None
        print(json.dumps({"run": d, "metrics": shown}, indent=1))
