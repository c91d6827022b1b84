"""Routing metrics of a run from its packet captures (the paper's Section 2.4).

Theory of operation. Each robot K has one capture, `pcaps/rK.pcap`, of its own `wlan0`; all
captures are stamped by the host clock. `read_pcaps` turns a run's captures into frames with a
single tshark invocation (`-T fields`, first occurrence of each field): mergecap joins them as
separate interfaces and `frame.interface_id` says whose capture each frame came from. A
capture on a veth does not mark direction, so a robot's own MAC address is inferred: the most
common Ethernet source of frames whose IP source is the robot's address. Frames from that MAC
were *transmitted* by the robot (its own traffic and what it forwards); the rest were received.

`compute` is pure (frames in, numbers out) and defines the metrics:

- routing overhead: routing control packets transmitted (UDP port 654 for AODV, 6696 for
  babel), counted once per transmission at the transmitter, so a rebroadcast RREQ counts at
  every robot that rebroadcasts it; as a fraction of all frames transmitted, and in bytes
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
"""

from __future__ import annotations

import bisect
import json
import logging
import math
import os
import statistics
import subprocess
import sys
import tempfile
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from common import boundedfile
from common.jsonfile import write_json_atomic
from node.messaging import REGISTRY as MIDDLEWARE_REGISTRY
from testbed.analysis import capturefiles, mwframing, relaylag, routingnotes, rtps, runs
from testbed.analysis.capturefiles import capture_drops, daemon_counts
from testbed.resultfile import DEFAULT_ROUTING
from topology.names import LAG_FILE

log = logging.getLogger(__name__)

# none and oracle send no control traffic: anything on the AODV port would be counted.
CONTROL_PORTS = {"aodv": 654, "babel": 6696, "batman": 4305, "none": 654, "oracle": 654}
AODV_TYPES = {1: "RREQ", 2: "RREP", 3: "RERR", 4: "RREP-ACK"}
BROADCAST = "255.255.255.255"
CACHE_NAME = "routing.json"
# 3: "emulated" and "about"; 4: "tcp_flows"; 5: relay-lag correction, or "middleware";
# 6: both; 7: the middleware's traffic for zenoh and dds, and by kind
CACHE_FORMAT = 8
# The robots' goal messages: the port every robot's messenger listens on (node.launch's
# --goal-port, which a run leaves at its default), and each middleware's framing on it
# (node.messaging's registry; testbed.analysis.mwframing, testbed.analysis.rtps parse them). A
# middleware without an entry is not counted as a class.
GOAL_PORT = 5101
MIDDLEWARE_FRAMING = {name: e.framing for name, e in MIDDLEWARE_REGISTRY.items()}
# Cyclone DDS's unicast ports with Ports/Base = the goal port (node/messaging/dds.py): the
# discovery port and the data port of participant index 0, every robot's in the testbed.
DDS_PORTS = (GOAL_PORT + 10, GOAL_PORT + 11)
DATAGRAM_FRAMINGS = {"rtps"}  # over UDP; the others over TCP
DEFAULT_MIDDLEWARE = "nanomsg"  # the only one before there was a choice

_FIELDS = (
    "frame.time_epoch",
    "frame.len",
    "eth.src",
    "eth.dst",
    "ip.src",
    "ip.dst",
    "ip.proto",
    "ip.ttl",
    "udp.srcport",
    "udp.dstport",
    "udp.length",
    "tcp.srcport",
    "tcp.dstport",
    "tcp.seq_raw",
    "tcp.len",
    "aodv.type",
    "ipv6.nxt",
    "frame.interface_id",  # in a merged capture, which input file the frame came from
    "ip.id",  # with the addresses, protocol and TCP sequence: a packet's identity across hops
    "tcp.payload",  # hex; the middleware's framing is read from it
)
# Asked for only when the middleware is DDS (its RTPS is read from it): written for every
# UDP frame, map floods included, it costs tshark a tenth more time on a large run.
_UDP_PAYLOAD = "udp.payload"


@dataclass(frozen=True)
class Frame:
    time: float
    length: int
    eth_src: str
    eth_dst: str
    ip_src: str = ""
    ip_dst: str = ""
    ip_proto: int | None = None
    ttl: int | None = None
    udp_sport: int | None = None
    udp_dport: int | None = None
    udp_len: int | None = None
    tcp_sport: int | None = None
    tcp_dport: int | None = None
    tcp_seq: int | None = None
    tcp_len: int | None = None
    aodv_type: int | None = None
    interface: int = 0
    ip_id: int | None = None
    tcp_payload: bytes = b""
    udp_payload: bytes = b""  # only when asked for (read_pcaps' udp_payload)


def _int(s: str, top: int = 0xFFFF) -> int | None:
    """A field tshark writes as a whole number 0..top (a port, a length: 0..65535 unless
    said), or None when empty; ValueError otherwise."""
    if not s:
        return None
    v = int(s) if len(s) <= 20 else -1  # (int() of 5000 digits is an error of its own)
    if not 0 <= v <= top:
        raise ValueError(f"{s[:20]!r} is not in 0..{top}")
    return v


_U32 = 0xFFFFFFFF


def _hex_int(s: str, top: int = 0xFFFF) -> int | None:
    """A field tshark writes in hex ("0x1a2b"; or in decimal), or None when empty;
    ValueError otherwise."""
    if not s:
        return None
    v = (int(s, 16) if s[:2].lower() == "0x" else int(s)) if len(s) <= 20 else -1
    if not 0 <= v <= top:
        raise ValueError(f"{s[:20]!r} is not in 0..{top}")
    return v


def _time(s: str) -> float:
    t = float(s)
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"time {s[:20]!r}")
    return t


def parse_fields(text: str) -> list[Frame]:
    """Frames from tshark's tab-separated `-e` output in `_FIELDS` order. A line whose
    fields are not what tshark writes (a time that is not a finite number >= 0, a number out
    of its field's range: lengths, ports and sequence numbers are unsigned of their size)
    is skipped with a warning, so that no NaN or absurd count reaches the metrics."""
    frames = []
    for line in text.splitlines():
        if not line:
            continue
        f = line.split("\t")
        f += [""] * (len(_FIELDS) + 1 - len(f))
        try:
            length = _int(f[1], _U32)
            if length is None:
                raise ValueError("no frame length")
            frames.append(
                Frame(
                    time=_time(f[0]),
                    length=length,
                    eth_src=f[2],
                    eth_dst=f[3],
                    ip_src=f[4],
                    ip_dst=f[5],
                    # IPv4 protocol or IPv6 next header
                    ip_proto=_int(f[6], 255) or _int(f[16], 255),
                    ttl=_int(f[7], 255),
                    udp_sport=_int(f[8]),
                    udp_dport=_int(f[9]),
                    udp_len=_int(f[10]),
                    tcp_sport=_int(f[11]),
                    tcp_dport=_int(f[12]),
                    tcp_seq=_int(f[13], _U32),
                    tcp_len=_int(f[14], _U32),
                    aodv_type=_int(f[15], 255),
                    interface=_int(f[17], _U32) or 0,
                    ip_id=_hex_int(f[18]),
                    tcp_payload=bytes.fromhex(f[19]),
                    udp_payload=bytes.fromhex(f[20]),
                )
            )
        except ValueError:
            log.warning("unparsable tshark line skipped: %r", line[:120])
    return frames


def _tshark_argv(path: str, udp_payload: bool = False) -> list[str]:
    argv = ["tshark", "-n", "-r", path, "-T", "fields", "-E", "separator=/t"]
    argv += ["-E", "occurrence=f"]
    for name in _FIELDS + ((_UDP_PAYLOAD,) if udp_payload else ()):
        argv += ["-e", name]
    return argv


def read_pcap(path: str | Path, udp_payload: bool = False) -> list[Frame]:
    """All frames of one capture (one tshark process); with `udp_payload`, UDP's payload
    too."""
    r = subprocess.run(_tshark_argv(str(path), udp_payload), capture_output=True, text=True)
    if r.returncode != 0:
        # tshark exits 2 on a capture cut short (a run killed mid-write); keep what it read.
        log.warning("tshark on %s: status %d: %s", path, r.returncode, r.stderr.strip()[-200:])
    return parse_fields(r.stdout)


def read_pcaps(paths: dict[int, Path], udp_payload: bool = False) -> dict[int, list[Frame]]:
    """All frames of several captures, by key, with one tshark process (`udp_payload` as
    for read_pcap).

    tshark spends 0.3-0.4 s starting up (its dissectors) and a robot's capture takes it a
    tenth of that to read, so a run's captures are read together: mergecap joins them into one
    pcapng stream with each file as its own interface (`-I none`, in the order given) and
    `frame.interface_id` maps each frame back to its file. mergecap stops at the first capture
    cut short (a run killed mid-write); then each capture is read on its own, which keeps
    everything every file holds."""
    keys = sorted(paths)
    if len(keys) < 2:
        return {k: read_pcap(paths[k], udp_payload) for k in keys}
    with tempfile.TemporaryFile() as merge_err:
        merge = subprocess.Popen(
            ["mergecap", "-I", "none", "-F", "pcapng", "-w", "-", *(str(paths[k]) for k in keys)],
            stdout=subprocess.PIPE,
            stderr=merge_err,
        )
        assert merge.stdout is not None  # stdout=PIPE
        try:
            r = subprocess.run(
                _tshark_argv("-", udp_payload),
                stdin=merge.stdout,
                capture_output=True,
                text=True,
            )
        finally:
            merge.stdout.close()
            merge.wait()
        merge_err.seek(0)
        why = merge_err.read().decode(errors="replace").strip()
    if merge.returncode != 0 or r.returncode != 0:
        why = why or r.stderr.strip()
        log.warning("merged read of %d captures failed (%s); reading each", len(keys), why[-200:])
        with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
            read = pool.map(lambda k: read_pcap(paths[k], udp_payload), keys)
            return dict(zip(keys, read, strict=True))
    out: dict[int, list[Frame]] = {k: [] for k in keys}
    for f in parse_fields(r.stdout):
        out[keys[f.interface]].append(f)
    return out


def own_mac(frames: list[Frame], addr: str) -> str | None:
    """The robot's MAC: the most common Ethernet source among frames from its IP address."""
    c = Counter(f.eth_src for f in frames if f.ip_src == addr and f.eth_src)
    return c.most_common(1)[0][0] if c else None


def _is_control(f: Frame, port: int) -> bool:
    # The outer IP header must be UDP: an ICMP error quoting a UDP 654 datagram is not AODV.
    return f.ip_proto == 17 and (f.udp_sport == port or f.udp_dport == port)


def _aodv_kind(f: Frame) -> str:
    kind = AODV_TYPES.get(f.aodv_type or 0, "other")
    if kind == "RREP" and f.ip_dst == BROADCAST and f.ttl == 1:
        return "HELLO"
    return kind


def _quantile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


@dataclass
class _Traffic:
    """The robots' TCP traffic as compute() gathers it from every capture."""

    sources: set[str]  # only traffic whose sender was captured too
    # (src, dst, sport, dport, seq) -> [first time, length, transmissions]
    sent: dict[tuple, list] = field(default_factory=dict)
    # received segments per flow: flow -> {seq: [first time, length, receptions, IP id of
    # the first reception, seq]}
    received: dict[tuple, dict[int, list]] = field(default_factory=lambda: defaultdict(dict))
    tx_payload: int = 0  # TCP payload bytes, all transmissions
    rx_payload: int = 0  # TCP payload bytes, all receptions
    t_min: float = float("inf")
    t_max: float = float("-inf")

    def transmitted(self, f: Frame) -> bool:
        """Note a TCP segment the robot sent as its source; True when it is a new one."""
        assert f.tcp_len is not None and f.tcp_seq is not None  # the caller checks
        self.tx_payload += f.tcp_len
        key = (f.ip_src, f.ip_dst, f.tcp_sport, f.tcp_dport, f.tcp_seq)
        if key in self.sent:
            self.sent[key][2] += 1
            return False
        self.sent[key] = [f.time, f.tcp_len, 1]
        return True

    def got(self, f: Frame) -> None:
        """Note a TCP segment the robot received as its destination."""
        assert f.tcp_len is not None and f.tcp_seq is not None  # the caller checks
        self.rx_payload += f.tcp_len
        flow = (f.ip_src, f.ip_dst, f.tcp_sport, f.tcp_dport)
        seen = self.received[flow].get(f.tcp_seq)
        if seen is None:
            self.received[flow][f.tcp_seq] = [f.time, f.tcp_len, 1, f.ip_id, f.tcp_seq]
        else:
            if f.time < seen[0]:
                seen[0], seen[3] = f.time, f.ip_id
            seen[2] += 1


def _new_robot(mac: str | None, frames: int) -> dict:
    return {
        "mac": mac,
        "frames": frames,
        "tx_packets": 0,
        "tx_bytes": 0,
        "rx_packets": 0,
        "control_tx_packets": 0,
        "control_tx_bytes": 0,
        "control_tx_payload_bytes": 0,
        "control_rx_packets": 0,
        "aodv_tx_by_type": Counter(),
        "tcp_segments_sent": 0,
    }


def _robot_counts(frames: list[Frame], addr: str, port: int, traffic: _Traffic) -> dict:
    """One robot's counts from its capture; its TCP traffic goes into `traffic`."""
    r = _new_robot(own_mac(frames, addr), len(frames))
    mac = r["mac"]
    for f in frames:
        traffic.t_min, traffic.t_max = min(traffic.t_min, f.time), max(traffic.t_max, f.time)
        control = _is_control(f, port)
        if mac is not None and f.eth_src == mac:
            r["tx_packets"] += 1
            r["tx_bytes"] += f.length
            if control:
                r["control_tx_packets"] += 1
                r["control_tx_bytes"] += f.length
                r["control_tx_payload_bytes"] += max(0, (f.udp_len or 8) - 8)
                if port == CONTROL_PORTS["aodv"]:
                    r["aodv_tx_by_type"][_aodv_kind(f)] += 1
            segment = f.tcp_len and f.tcp_seq is not None and f.ip_proto == 6  # (seq: a match)
            if f.ip_src == addr and segment and f.ip_dst != addr:
                r["tcp_segments_sent"] += traffic.transmitted(f)
        else:
            r["rx_packets"] += 1
            r["control_rx_packets"] += control
            to_me = f.ip_dst == addr and f.tcp_len and f.tcp_seq is not None and f.ip_proto == 6
            if to_me and f.ip_src in traffic.sources:
                traffic.got(f)
    r["aodv_tx_by_type"] = dict(r["aodv_tx_by_type"])
    return r


@dataclass
class _Delivery:
    delays_ms: list[float]  # corrected for the relay lag where a lag index was given
    delivered: int  # segments
    delivered_bytes: int
    delivered_tx: int  # transmissions
    raw_delays_ms: list[float] = field(default_factory=list)
    lag_ms: list[float] = field(default_factory=list)  # subtracted, per corrected segment
    uncorrected: int = 0  # segments whose hops could not all be matched with lag records


def _deliveries(
    traffic: _Traffic,
    lags: relaylag.LagIndex | None = None,
    robot_of: dict[str, int] | None = None,
) -> _Delivery:
    """Match each segment sent with its first reception: exactly (same flow and sequence
    number) or, when GSO/GRO resegmented it, a received segment covering its first byte.
    With `lags` (and `robot_of`, robot number by address), each delay has the relay lag of
    the hops of the received copy taken out (relaylag.LagIndex.path_lag)."""
    index = {flow: sorted(segs) for flow, segs in traffic.received.items()}
    out = _Delivery([], 0, 0, 0)
    for (src, dst, sport, dport, seq), (t_sent, length, n_sent) in traffic.sent.items():
        flow = (src, dst, sport, dport)
        segs = traffic.received.get(flow)
        if not segs:
            continue
        hit = segs.get(seq)
        if hit is None:  # resegmented: a received segment that covers the first byte
            starts = index[flow]
            i = bisect.bisect_right(starts, seq)
            covering = [segs[s] for s in starts[max(0, i - 8) : i] if s + segs[s][1] > seq]
            hit = min(covering, key=lambda h: h[0]) if covering else None
        if hit is None:
            continue
        out.delivered += 1
        out.delivered_tx += min(n_sent, hit[2])
        out.delivered_bytes += length
        delay_ms = 1000.0 * (hit[0] - t_sent)
        out.raw_delays_ms.append(delay_ms)
        if lags is not None:
            path = None
            if hit[3] is not None:
                assert robot_of is not None  # given with lags
                key = relaylag.packet_key(src, dst, hit[3], 6, hit[4])
                path = lags.path_lag(key, robot_of[src], robot_of[dst], t_sent, hit[0])
            if path is None:
                out.uncorrected += 1
            else:
                lag_ms = sum(r.lag_ns for r in path) / 1e6
                out.lag_ms.append(lag_ms)
                delay_ms -= lag_ms
        out.delays_ms.append(delay_ms)
    return out


def _control_totals(robots: dict[str, dict]) -> dict:
    tx_packets = sum(r["tx_packets"] for r in robots.values())
    tx_bytes = sum(r["tx_bytes"] for r in robots.values())
    ctl_packets = sum(r["control_tx_packets"] for r in robots.values())
    ctl_bytes = sum(r["control_tx_bytes"] for r in robots.values())
    by_type: Counter = Counter()
    for r in robots.values():
        by_type.update(r["aodv_tx_by_type"])
    return {
        "tx_packets": tx_packets,
        "tx_bytes": tx_bytes,
        "control_tx_packets": ctl_packets,
        "control_tx_bytes": ctl_bytes,
        "control_tx_payload_bytes": sum(r["control_tx_payload_bytes"] for r in robots.values()),
        "aodv_tx_by_type": dict(by_type),
        "overhead_packets": ctl_packets / tx_packets if tx_packets else None,
        "overhead_bytes": ctl_bytes / tx_bytes if tx_bytes else None,
    }


def _delivery_metrics(traffic: _Traffic, d: _Delivery, duration: float) -> dict:
    sent, delays_ms = traffic.sent, d.delays_ms
    return {
        "tcp_segments_sent": len(sent),
        "tcp_segments_delivered": d.delivered,
        "segment_delivery": d.delivered / len(sent) if sent else None,
        "tcp_transmissions": sum(v[2] for v in sent.values()),
        "tcp_flows": len({key[:4] for key in sent}),  # connection directions that sent data
        "tcp_transmissions_delivered": d.delivered_tx,
        "tcp_payload_bytes_transmitted": traffic.tx_payload,
        "tcp_payload_bytes_received": traffic.rx_payload,
        "pdf": traffic.rx_payload / traffic.tx_payload if traffic.tx_payload else None,
        **_delay_stats("delay_ms", delays_ms),
        "throughput_bps": 8.0 * d.delivered_bytes / duration if duration else None,
        "delivered_payload_bytes": d.delivered_bytes,
    }


def _delay_stats(prefix: str, delays_ms: list[float]) -> dict:
    return {
        f"{prefix}_mean": statistics.fmean(delays_ms) if delays_ms else None,
        f"{prefix}_median": statistics.median(delays_ms) if delays_ms else None,
        f"{prefix}_p95": _quantile(delays_ms, 0.95) if delays_ms else None,
    }


def _lag_metrics(d: _Delivery, records: int) -> dict:
    """What the relay-lag correction did (only for a run with the channel's lag records)."""
    return {
        **_delay_stats("delay_raw_ms", d.raw_delays_ms),
        "relay_lag": {
            "records": records,
            "segments_corrected": len(d.lag_ms),
            "segments_uncorrected": d.uncorrected,
            "subtracted_ms_mean": statistics.fmean(d.lag_ms) if d.lag_ms else None,
            "subtracted_ms_median": statistics.median(d.lag_ms) if d.lag_ms else None,
        },
    }


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


# ---------------------------------------------------------------- the middleware's traffic

MIDDLEWARE_COUNTS = (
    "tx_packets", "tx_bytes", "tcp_control_packets", "tcp_control_bytes", "data_packets",
    "data_bytes", "payload_bytes", "retransmitted_payload_bytes", "messages", "message_bytes",
    "protocol_bytes", "unparsed_bytes",
)  # fmt: skip


def _stream(segments: list[tuple[int, bytes]]) -> tuple[bytes, int]:
    """One direction of a connection from its segments (raw sequence number, payload) in the
    order sent: the bytes in sequence order up to the first gap, and the bytes after it."""
    if not segments:
        return b"", 0
    first = segments[0][0]
    pieces = sorted(((seq - first) & _U32, data) for seq, data in segments)
    out = bytearray()
    for rel, data in pieces:
        if rel > len(out):  # a gap: the capture missed a segment
            break
        out += data[len(out) - rel :]
    return bytes(out), sum(len(d) for rel, d in pieces if rel > len(out))


def middleware_ports(framing: str) -> tuple[str, tuple[int, ...]]:
    """The transport and ports a framing's traffic is counted on."""
    return ("udp", DDS_PORTS) if framing in DATAGRAM_FRAMINGS else ("tcp", (GOAL_PORT,))


def _tcp_split(frames: list[Frame], r: dict, framing: str) -> mwframing.Split:
    """The robot's TCP frames on the goal port counted into `r`, their payload walked."""
    flows: dict[tuple, list[tuple[int, bytes]]] = defaultdict(list)
    seen: set[tuple] = set()
    for f in frames:
        if f.ip_proto != 6 or GOAL_PORT not in (f.tcp_sport, f.tcp_dport):
            continue
        r["tx_packets"] += 1
        r["tx_bytes"] += f.length
        if not f.tcp_len:
            r["tcp_control_packets"] += 1
            r["tcp_control_bytes"] += f.length
            continue
        r["data_packets"] += 1
        r["data_bytes"] += f.length
        r["payload_bytes"] += f.tcp_len
        flow = (f.ip_dst, f.tcp_sport, f.tcp_dport)
        if (flow, f.tcp_seq) in seen:
            r["retransmitted_payload_bytes"] += f.tcp_len
            continue
        seen.add((flow, f.tcp_seq))
        flows[flow].append((f.tcp_seq or 0, f.tcp_payload))
    whole = mwframing.Split()
    for segments in flows.values():
        stream, after_gap = _stream(segments)
        part = mwframing.split(framing, stream)
        part.unparsed += after_gap
        whole.add(part)
    return whole


def _udp_split(frames: list[Frame], r: dict) -> mwframing.Split:
    """The robot's UDP datagrams on DDS's ports counted into `r`, each one's RTPS walked."""
    whole = mwframing.Split()
    seen: set[tuple] = set()
    for f in frames:
        if f.ip_proto != 17 or not (f.udp_sport in DDS_PORTS or f.udp_dport in DDS_PORTS):
            continue
        size = max(len(f.udp_payload), (f.udp_len or 8) - 8)
        r["tx_packets"] += 1
        r["tx_bytes"] += f.length
        r["data_packets"] += 1
        r["data_bytes"] += f.length
        r["payload_bytes"] += size
        part = rtps.split(f.udp_payload, seen)
        part.unparsed += size - len(f.udp_payload)  # (UDP's payload not read)
        whole.add(part)
    r["retransmitted_payload_bytes"] += whole.retransmitted
    return whole


def _middleware_counts(frames: list[Frame], addr: str, mac: str | None, framing: str) -> dict:
    """What one robot transmitted on the middleware's ports (see the module docstring)."""
    r = dict.fromkeys(MIDDLEWARE_COUNTS, 0)
    mine = [f for f in frames if mac is not None and f.eth_src == mac and f.ip_src == addr]
    udp = framing in DATAGRAM_FRAMINGS
    whole = _udp_split(mine, r) if udp else _tcp_split(mine, r, framing)
    r["messages"] = whole.messages
    r["message_bytes"] = whole.payload
    r["protocol_bytes"] = whole.protocol
    r["unparsed_bytes"] = whole.unparsed
    return _with_shares(r, whole.kinds)


def _with_shares(r: dict, kinds: dict[str, list[int]]) -> dict:
    """`r` with what follows from its counts: the bytes that were not the robots' messages,
    their share, and the middleware's own bytes by kind."""
    r["own_bytes"] = r["tx_bytes"] - r["message_bytes"]
    r["message_fraction_bytes"] = r["message_bytes"] / r["tx_bytes"] if r["tx_bytes"] else None
    r["protocol_by_kind"] = {k: {"count": n, "bytes": b} for k, (n, b) in sorted(kinds.items())}
    return r


def _middleware_totals(middleware: str, framing: str | None, robots: dict[str, dict]) -> dict:
    """The team's middleware traffic: the robots' counts summed, and the share of the
    middleware's bytes on the wire that were the robots' messages."""
    out: dict = {"name": middleware, "port": GOAL_PORT, "framing": framing}
    if framing is None:
        return out
    out["transport"], out["ports"] = middleware_ports(framing)
    out["ports"] = list(out["ports"])
    counted = [r["middleware"] for r in robots.values() if "middleware" in r]
    for key in MIDDLEWARE_COUNTS:
        out[key] = sum(r[key] for r in counted)
    kinds: dict[str, list[int]] = {}
    for r in counted:
        for kind, v in r["protocol_by_kind"].items():
            k = kinds.setdefault(kind, [0, 0])
            k[0] += v["count"]
            k[1] += v["bytes"]
    return _with_shares(out, kinds)


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


def robot_address(k: int) -> str:
    try:
        from topology.names import robot_addr
    except ImportError:  # the topology package is optional for reading results
        hi, lo = divmod(k - 1, 254)
        return f"10.0.{hi}.{lo + 1}"
    return robot_addr(k)


def run_metrics(
    run_dir: str | Path,
    use_cache: bool = True,
    run: runs.FinishedRun | None = None,
    network: tuple[str, float | None] | None = None,
) -> dict | None:
    """Routing metrics of one run directory (None if it has no captures), cached in its
    routing.json. `run` (its routing says whose control port to count, its time scale turns
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
            doc = boundedfile.load_json(cache)
            if doc.get("format") == CACHE_FORMAT and doc.get("pcaps") == stamp:
                why = capturefiles.cache_refusal(doc)
                if why is None:
                    return doc
                log.warning("%s: not taken (%s): computed again", cache, why)
        except (boundedfile.Refused, AttributeError):
            pass
    if run is None and network is None:
        try:
            run = runs.load_run(run_dir)
        except runs.ResultError as e:
            log.warning("%s; counting AODV's port, wall-clock time only", e)
    if run is not None:
        routing = run.config.routing
        scale = run.time_scale_achieved or run.time_scale_requested or run.config.time_scale
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
    metrics = compute(
        captures, {k: robot_address(k) for k in pcaps}, CONTROL_PORTS.get(routing, 654),
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
    return metrics


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO)
    for d in sys.argv[1:]:
        m = run_metrics(d, use_cache=False)
        if m:
            m = {k: v for k, v in m.items() if k != "robots"}
        print(json.dumps({"run": d, "metrics": m}, indent=1))
