"""Each robot's frames counted for the routing metrics (testbed.analysis.pcapmetrics): its
routing protocol's control traffic, and the robots' TCP segments matched from sender to
receiver into deliveries and delays.

Theory of operation. A capture on a veth does not mark direction, so a robot's own MAC
address is inferred (`own_mac`): the most common Ethernet source of frames whose IP source is
the robot's address. Frames from that MAC were *transmitted* by the robot; the rest were
received. `_robot_counts` counts one robot's frames (control packets at the transmitter, by
AODV type) and notes the TCP segments it sent as a source and received as a destination in a
`_Traffic` shared by all robots; `_deliveries` then matches each segment sent with its first
reception (exactly, or a received segment covering its first byte when GSO/GRO resegmented
it) and, given the ns3-wifi channel's relay-lag records, takes the relay lag out of each
delay. The `_..._metrics` functions turn these into the numbers routing.json holds. Pure:
frames in, counts out.
"""

from __future__ import annotations

import bisect
import statistics
from collections import Counter, defaultdict
from dataclasses import dataclass, field

from testbed.analysis import relaylag
from testbed.analysis.pcapread import Frame
from topology.protocols import AODV_PORT, REGISTRY

# Each protocol's control port (topology.protocols; none and oracle send no control traffic:
# anything on the AODV port would be counted).
CONTROL_PORTS = {p.name: p.control_port for p in REGISTRY.values()}
AODV_TYPES = {1: "RREQ", 2: "RREP", 3: "RERR", 4: "RREP-ACK"}
BROADCAST = "255.255.255.255"


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
                if port == AODV_PORT:
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
