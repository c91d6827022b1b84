"""The middleware's traffic in the captures, a class of its own for the routing metrics
(testbed.analysis.pcapmetrics): what each robot transmitted on its middleware's ports, split
into the robots' messages and the middleware's own bytes.

Theory of operation. Over TCP (nanomsg, zeromq, zeromq-reqrep, zenoh: to or from the goal
port, GOAL_PORT), a robot's frames are split into TCP's own (no payload) and those with data;
the data, reassembled per connection and direction (`_stream`), is walked in the middleware's
framing (testbed.analysis.mwframing). Over UDP (dds: to or from DDS_PORTS), each datagram is
walked as RTPS (testbed.analysis.rtps). Retransmitted payload is counted apart.
`_middleware_counts` gives one robot's counts, `_middleware_totals` the team's, each with the
share of the bytes that were the robots' messages and the middleware's own bytes by kind.
Pure: frames in, counts out.
"""

from __future__ import annotations

from collections import defaultdict

from node.messaging import REGISTRY as MIDDLEWARE_REGISTRY
from testbed.analysis import mwframing, rtps
from testbed.analysis.pcapread import _U32, Frame

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
