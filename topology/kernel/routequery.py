"""Ask a namespace's kernel where it would send a packet: one RTM_GETROUTE, read only.

`ip route get` without the process: the request is an rtmsg with the destination (RTA_DST;
packed by netlinkmsg.route_get), sent on a NETLINK_ROUTE socket opened once in the namespace
(rtnl.open_socket); the kernel answers with the route it would use (RTM_NEWROUTE: gateway and
output interface) or an error (no route). No packet is sent, so asking changes nothing a
routing daemon sees. The view asks it when a robot is clicked, and the oracle bench to see when
routes have converged.

The request and the answer are encoded and decoded by pure functions (`request`, `parse`);
`next_hop` is the socket round trip and the medium's meaning of the answer.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

from topology import names
from topology.kernel import netlinkmsg as nl
from topology.radio.veth import WLAN_INDEX

RTM_NEWROUTE, RTM_GETROUTE = nl.RTM_NEWROUTE, nl.RTM_GETROUTE


@dataclass(frozen=True)
class Route:
    """The kernel's answer: the output interface and the gateway (None: on link)."""

    oif: int | None
    gateway: str | None


def request(dest: str, seq: int = 1) -> bytes:
    """An RTM_GETROUTE request for the IPv4 host `dest`."""
    return nl.route_get(dest, seq)


def parse(data: bytes) -> Route | None:
    """The route in the kernel's answer, or None when it answered with an error (no route)."""
    first = next(nl.messages(data), None)
    if first is None or first[0] != nl.RTM_NEWROUTE:
        return None
    route = nl.parse_route(data, first[2], first[3])
    return None if route is None else Route(route.oif, route.gateway)


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
