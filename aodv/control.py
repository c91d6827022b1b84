"""The AODV daemon's control channel: RFC 3561 messages on UDP port 654, with their IP TTL.

Theory of operation
-------------------
`open_control_socket` makes the socket: bound to 0.0.0.0:654 and to the interface
(SO_BINDTODEVICE), with SO_BROADCAST and IP_RECVTTL (12, missing from Python 3.11's socket
module), and a socket filter that drops our own broadcasts by source address. The RFC
reads the IP TTL of what it receives (a HELLO is a RREP with TTL 1) and sets the TTL of
what it sends, so `ControlChannel` works in datagrams with TTLs: `receive` yields (source,
TTL, bytes) for what waits in the socket, `send` encodes a message and sends it with its
TTL (set on the socket only when it changes; unicasts use MSG_DONTROUTE, a control message
always goes to a neighbour on the link), counting it by kind. `read_icmp` counts the
messages the kernel took but never transmitted (a raw ICMP socket reads the errors, see its
docstring). Decoding and checking what was received is the daemon's (aodv.daemon).
"""

from __future__ import annotations

import logging
import socket
import struct
import time
from collections.abc import Iterator

from aodv import packet as wire
from aodv.icmp import quoted_datagram
from aodv.kernel import drop_own_datagrams
from aodv.stats import Stats

log = logging.getLogger("aodv.daemon")

IP_RECVTTL = 12  # linux/in.h; not in Python 3.11's socket module
IP_TTL_CMSG = 2  # IP_TTL: the cmsg type of a received TTL
_I32 = struct.Struct("i")  # a received TTL's cmsg data (native int)


def open_control_socket(iface: str, addr: str) -> socket.socket:
    """UDP 654 on `iface`, non-blocking, hearing the TTL of what it receives."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, iface.encode())
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.setsockopt(socket.IPPROTO_IP, IP_RECVTTL, 1)
        s.bind(("0.0.0.0", wire.AODV_PORT))
        drop_own_datagrams(s, addr)
        s.setblocking(False)
    except BaseException:
        s.close()
        raise
    return s


class ControlChannel:
    def __init__(self, sock: socket.socket, icmp: socket.socket, addr: str, stats: Stats) -> None:
        self.sock = sock  # UDP 654 (open_control_socket)
        self.icmp = icmp  # raw ICMP, non-blocking: errors about our datagrams
        self.addr = addr
        self.stats = stats
        self._ttl: int | None = None  # the IP TTL `sock` sends with now
        # When the newest RREQ of our own for each destination went to sendto().
        self.rreq_sent: dict[str, float] = {}

    def receive(self) -> Iterator[tuple[str, int, bytes]]:
        """(source, IP TTL, datagram) for up to 64 datagrams waiting in the socket."""
        for _ in range(64):
            try:
                data, anc, _flags, (src, _port) = self.sock.recvmsg(4096, socket.CMSG_SPACE(4))
            except BlockingIOError:
                return
            if src == self.addr:
                continue  # our own broadcast
            ttl = 0
            for level, ctype, cdata in anc:
                if level == socket.IPPROTO_IP and ctype == IP_TTL_CMSG and len(cdata) >= 4:
                    ttl = _I32.unpack_from(cdata)[0]
            self.stats.bytes_received += len(data)
            yield src, ttl, data

    def send(self, msg: wire.Message, dst: str, ttl: int, flags: int) -> None:
        try:
            data = wire.encode(msg)
        except ValueError as e:  # a core bug: count it, and let the route actions run
            self.stats.dropped["encode_failed"] += 1
            log.error("could not encode %s to %s: %s", msg.type_name, dst, e)
            return
        if ttl != self._ttl:
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, ttl)
            self._ttl = ttl
        if isinstance(msg, wire.Rreq) and msg.orig == self.addr:
            self.rreq_sent[msg.dest] = time.monotonic()
        try:
            self.sock.sendto(data, flags, (dst, wire.AODV_PORT))
        except OSError as e:
            self.stats.dropped["send_failed"] += 1
            log.warning("send %s to %s failed: %s", msg.type_name, dst, e)
            return
        kind = "HELLO" if wire.is_hello(msg, self.addr) else msg.type_name
        self.stats.sent[kind] += 1
        self.stats.bytes_sent += len(data)

    def read_icmp(self) -> None:
        """ICMP errors about datagrams of ours: the kernel took a message (`send` counted it
        as sent) but never transmitted it. A unicast to a neighbour whose ARP failed (the
        link broke) is dropped with an ICMP host unreachable to its sender, here through lo.
        The UDP socket cannot be told (IP_RECVERR finds no socket bound to wlan0 for an
        error that arrives on lo), so a raw ICMP socket reads them. Counted by kind as not
        transmitted: sent minus not transmitted is what went on the air, as a capture of
        wlan0 sees it."""
        for _ in range(64):
            try:
                data = self.icmp.recv(2048)
            except BlockingIOError:
                return
            quoted = quoted_datagram(data, self.addr)
            if quoted is None:
                continue
            udp_len, payload = quoted
            try:
                kind = wire.decode(payload).type_name
            except wire.MalformedPacket:
                kind = "unknown"
            self.stats.not_transmitted[kind] += 1
            self.stats.bytes_not_transmitted += udp_len - 8
            log.info("a %s of ours was not transmitted (ICMP destination unreachable)", kind)
