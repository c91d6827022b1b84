"""The ICMP the AODV daemon writes and reads: pure functions over IPv4 packets, no IO.

Theory of operation
-------------------
Two directions. Data of our own that waited for a route in vain (RFC 3561 6.3: "a
Destination Unreachable message SHOULD be delivered to the application") is answered with
`icmp_host_unreachable`, which the daemon writes into the TUN device as if the network had
sent it. And a control message the kernel accepted but could not transmit (ARP for the
neighbour failed) comes back as an ICMP destination unreachable quoting our datagram:
`quoted_datagram` recognises those, so the daemon can count them as not transmitted.
"""

from __future__ import annotations

import socket
import struct

from aodv import packet as wire

ICMP_DEST_UNREACH = 3


def _checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\0"
    s = sum(struct.unpack(f"!{len(data) // 2}H", data))
    s = (s >> 16) + (s & 0xFFFF)
    s += s >> 16
    return ~s & 0xFFFF


def icmp_host_unreachable(own: str, original: bytes) -> bytes:
    """An ICMP destination unreachable (type 3, code 1) about `original`, to its sender."""
    ihl = (original[0] & 0x0F) * 4
    quoted = original[: ihl + 8]
    icmp = struct.pack("!BBHI", 3, 1, 0, 0) + quoted
    icmp = icmp[:2] + struct.pack("!H", _checksum(icmp)) + icmp[4:]
    total = 20 + len(icmp)
    hdr = struct.pack(
        "!BBHHHBBH4s4s",
        0x45,
        0,
        total,
        0,
        0,
        64,
        socket.IPPROTO_ICMP,
        0,
        socket.inet_aton(own),
        original[12:16],
    )
    hdr = hdr[:10] + struct.pack("!H", _checksum(hdr)) + hdr[12:]
    return hdr + icmp


def quoted_datagram(icmp_packet: bytes, own: str) -> tuple[int, bytes] | None:
    """From an IPv4 packet carrying an ICMP destination unreachable, the AODV datagram it
    quotes if `own` sent it (UDP from port 654 to port 654): (its UDP length, the quoted
    part of its payload); None for anything else, short or malformed packets included."""
    try:
        outer = (icmp_packet[0] & 0x0F) * 4
        if icmp_packet[outer] != ICMP_DEST_UNREACH:
            return None
        inner = outer + 8
        ihl = (icmp_packet[inner] & 0x0F) * 4
        if icmp_packet[inner + 9] != socket.IPPROTO_UDP:
            return None
        if icmp_packet[inner + 12 : inner + 16] != socket.inet_aton(own):
            return None
        sport, dport, length = struct.unpack_from("!HHH", icmp_packet, inner + ihl)
    except (IndexError, struct.error):
        return None
    if sport != wire.AODV_PORT or dport != wire.AODV_PORT or length < 8:
        return None
    return length, icmp_packet[inner + ihl + 8 : inner + ihl + length]
