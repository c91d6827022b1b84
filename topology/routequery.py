"""Ask a namespace's kernel where it would send a packet: one RTM_GETROUTE, read only.

`ip route get` without the process: the request is a 28-byte rtmsg with the destination
(RTA_DST), sent on a NETLINK_ROUTE socket opened once in the namespace (rtnl.open_socket); the
kernel answers with the route it would use (RTM_NEWROUTE: gateway and output interface) or an
error (no route). No packet is sent, so asking changes nothing a routing daemon sees. The view
asks it when a robot is clicked, and the oracle bench to see when routes have converged.

The request and the answer are encoded and decoded by pure functions (`request`, `parse`);
`next_hop` is the socket round trip and the medium's meaning of the answer.
"""

from __future__ import annotations

import socket
import struct
from dataclasses import dataclass

from topology import names
from topology.medium import WLAN_INDEX

RTM_NEWROUTE, RTM_GETROUTE = 24, 26
NLM_F_REQUEST = 1
RTA_DST, RTA_OIF, RTA_GATEWAY = 1, 4, 5
_HDR = struct.Struct("=LHHLL")  # nlmsghdr: length, type, flags, seq, pid
_RTMSG = struct.Struct("=BBBBBBBBI")  # family, dst_len, src_len, tos, table, proto, scope,
# type, flags
_RTA = struct.Struct("=HH")  # rtattr: length, type


@dataclass(frozen=True)
class Route:
    """The kernel's answer: the output interface and the gateway (None: on link)."""

    oif: int | None
    gateway: str | None


def request(dest: str, seq: int = 1) -> bytes:
    """An RTM_GETROUTE request for the IPv4 host `dest`."""
    body = _RTMSG.pack(socket.AF_INET, 32, 0, 0, 0, 0, 0, 0, 0)
    body += _RTA.pack(_RTA.size + 4, RTA_DST) + socket.inet_aton(dest)
    return _HDR.pack(_HDR.size + len(body), RTM_GETROUTE, NLM_F_REQUEST, seq, 0) + body


def parse(data: bytes) -> Route | None:
    """The route in the kernel's answer, or None when it answered with an error (no route)."""
    if len(data) < _HDR.size + _RTMSG.size or _HDR.unpack_from(data)[1] != RTM_NEWROUTE:
        return None
    length = min(_HDR.unpack_from(data)[0], len(data))
    off = _HDR.size + _RTMSG.size
    gateway, oif = None, None
    while off + _RTA.size <= length:
        alen, atype = _RTA.unpack_from(data, off)
        if alen < _RTA.size:
            break
        if atype == RTA_GATEWAY and alen == 8:
            gateway = socket.inet_ntoa(data[off + 4 : off + 8])
        elif atype == RTA_OIF and alen == 8:
            oif = struct.unpack_from("=I", data, off + 4)[0]
        off += (alen + 3) & ~3
    return Route(oif, gateway)


def lookup(sock: socket.socket, dest: str) -> Route | None:
    """Ask the kernel of `sock`'s namespace for its route to `dest`."""
    sock.send(request(dest))
    return parse(sock.recv(1 << 16))


def next_hop(sock: socket.socket, dest: str, radio_index: int = WLAN_INDEX) -> int | None:
    """The robot the kernel of `sock`'s namespace forwards to for `dest` through its radio
    interface (`wlan0`, ifindex `radio_index`; `dest` itself when the route is direct), or None
    without a route there (AODV's catch-all route to its TUN device means: no route yet)."""
    route = lookup(sock, dest)
    if route is None or route.oif != radio_index:
        return None
    return names.robot_of_addr(route.gateway or dest)
