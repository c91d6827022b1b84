"""The ns3-wifi channel's per-frame relay lag, and what it adds to a packet's delay.

Theory of operation (docs/ns3-medium.md, "Each frame's relay lag"). The ns3-wifi channel
relays every frame twice per hop: from the sender's `rpK` into the simulator, and out of it
into the receiver's `rpJ`. Each relay takes wall time that the channel's emulated time does
not account for (a reader thread waking up, a simulator event handled late). For each frame
it delivered to a robot, tb-ns3-wifi wrote one record of that lag into `relay-lag.bin`: the
receiving and the sending robot, when it wrote the frame (CLOCK_REALTIME, the captures'
clock), the identity of the IPv4 packet it carried, and the lag in wall-clock ns on the way in
and on the way out.

A packet from robot i that robot j received after h hops crossed h relayed frames, each with
its own record: the last has receiver j, the one before it receiver = the last one's sender,
and so on back to a record whose sender is i. `path_lag` follows that chain among the records
of the same IP packet (source, destination, IP id, protocol, TCP sequence number) written
between its send and its receipt; the sum of their lags is what the relay added to its
delay, and `pcapmetrics` subtracts it. A packet whose chain cannot be followed back to i
(a record past the file's cap, a frame not IPv4) is left uncorrected and counted.

`read_records` parses the file; everything else here is pure.
"""

from __future__ import annotations

import bisect
import struct
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from common import boundedfile

MAGIC = b"TBRLAG01"
MAX_LAG_BYTES = 1 << 30  # a frame's record is tens of bytes: tens of millions of frames
# written_ns, in_ns, out_ns, receiver, sender, ethertype, ip_id, ip_src, ip_dst, tcp_seq,
# ip_proto, tcp_flags, reserved (native/ns3wifi/wifi-medium.cc, LagRecord)
RECORD = struct.Struct("<QIIHHHH4s4sIBBH")
ETH_IPV4 = 0x0800
# How far a record's write may lie outside the capture times it is matched with: the
# capture's stamp is taken in the kernel as the frame crosses wlan0, which may be a little
# before the medium reads its own clock after the write returned.
SLACK_S = 0.002


class LagFileError(ValueError):
    """A relay-lag file that is not one."""


@dataclass(frozen=True)
class LagRecord:
    """One frame the channel delivered to a robot, and its relay lag."""

    written: float  # CLOCK_REALTIME seconds: when it was written into the receiver's rpJ
    in_ns: int  # lag from its arrival on the sender's rpK to its entry into the MAC
    out_ns: int  # lag from the end of its reception to its write into rpJ
    receiver: int  # robot number
    sender: int  # robot number (0: unknown)
    ethertype: int
    ip_id: int = 0  # IPv4 only, like the fields below
    ip_src: str = ""
    ip_dst: str = ""
    tcp_seq: int = 0
    ip_proto: int = 0
    tcp_flags: int = 0

    @property
    def lag_ns(self) -> int:
        return self.in_ns + self.out_ns


def _ip(b: bytes) -> str:
    return ".".join(str(x) for x in b)


def parse_records(data: bytes) -> tuple[list[LagRecord], int]:
    """The records of a relay-lag file's contents, and the bytes of a trailing partial
    record (a file cut short) that were left out. LagFileError when it is not such a file."""
    if data[: len(MAGIC)] != MAGIC:
        raise LagFileError("not a relay-lag file (no TBRLAG01 header)")
    body = memoryview(data)[len(MAGIC) :]
    whole = len(body) - len(body) % RECORD.size
    out = []
    for fields in RECORD.iter_unpack(body[:whole]):
        written, in_ns, out_ns, rcv, snd, eth, ipid, src, dst, seq, proto, flags, _ = fields
        ipv4 = eth == ETH_IPV4 and src != b"\0\0\0\0"
        out.append(
            LagRecord(
                written=written / 1e9,
                in_ns=in_ns,
                out_ns=out_ns,
                receiver=rcv,
                sender=snd,
                ethertype=eth,
                ip_id=ipid,
                ip_src=_ip(src) if ipv4 else "",
                ip_dst=_ip(dst) if ipv4 else "",
                tcp_seq=seq,
                ip_proto=proto,
                tcp_flags=flags,
            )  # fmt: skip
        )
    return out, len(body) - whole


def read_records(path: str | Path) -> tuple[list[LagRecord], int]:
    """parse_records of a file; LagFileError naming it when it is not one."""
    try:
        return parse_records(boundedfile.read(path, MAX_LAG_BYTES))
    except boundedfile.Refused as r:
        raise LagFileError(f"{path}: {boundedfile.describe(r)}") from None
    except LagFileError as e:
        raise LagFileError(f"{path}: {e}") from None


# The identity of an IPv4 packet: the fields no hop changes (TTL and checksum do).
PacketKey = tuple[str, str, int, int, int]  # ip_src, ip_dst, ip_id, ip_proto, tcp_seq


def packet_key(src: str, dst: str, ip_id: int, proto: int, tcp_seq: int | None) -> PacketKey:
    return (src, dst, ip_id, proto, tcp_seq if proto == 6 and tcp_seq is not None else 0)


class LagIndex:
    """The records of IPv4 packets by packet and receiver, in the order they were written."""

    def __init__(self, records: list[LagRecord]):
        by: dict[tuple, list[LagRecord]] = defaultdict(list)
        for r in records:
            if r.ip_src:
                key = packet_key(r.ip_src, r.ip_dst, r.ip_id, r.ip_proto, r.tcp_seq)
                by[(key, r.receiver)].append(r)
        self._by = {k: sorted(v, key=lambda r: r.written) for k, v in by.items()}
        self._times = {k: [r.written for r in v] for k, v in self._by.items()}
        self.records = len(records)

    def _first_after(self, key: PacketKey, receiver: int, t0: float, t1: float):
        """The first record of `key` delivered to `receiver` and written in [t0, t1]."""
        times = self._times.get((key, receiver))
        if not times:
            return None
        i = bisect.bisect_left(times, t0)
        return self._by[(key, receiver)][i] if i < len(times) and times[i] <= t1 else None

    def _last_before(self, key: PacketKey, receiver: int, t0: float, t1: float):
        """The last record of `key` delivered to `receiver` and written in [t0, t1]."""
        times = self._times.get((key, receiver))
        if not times:
            return None
        i = bisect.bisect_right(times, t1) - 1
        return self._by[(key, receiver)][i] if i >= 0 and times[i] >= t0 else None

    def path_lag(
        self, key: PacketKey, source: int, dest: int, t_sent: float, t_received: float
    ) -> list[LagRecord] | None:
        """The hop records of the packet `key` that robot `source` sent at `t_sent` (its
        capture's time) and robot `dest` received at `t_received`: the first delivery to
        `dest` after the send, then back hop by hop (each the last delivery to the previous
        hop's sender before that hop was written) to a frame `source` sent. None when the
        chain breaks or loops."""
        t0, t1 = t_sent - SLACK_S, t_received + SLACK_S
        hop = self._first_after(key, dest, t0, t1)
        path, visited = [], {dest}
        while hop is not None:
            path.append(hop)
            if hop.sender == source:
                return path[::-1]
            if hop.sender == 0 or hop.sender in visited:
                return None
            visited.add(hop.sender)
            hop = self._last_before(key, hop.sender, t0, hop.written)
        return None
