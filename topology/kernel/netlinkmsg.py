"""Netlink messages as bytes: the one module that knows their layout.

Every netlink message is an nlmsghdr (length, type, flags, sequence number, port id)
followed by a family header (rtmsg for routes, ifinfomsg for links, nfgenmsg for
nftables) and attributes (rtattr / nlattr: length, type, value padded to 4 bytes). The
kernel answers a request with NLMSG_ERROR (error 0 is an acknowledgement), with the
objects asked for, and ends a dump with NLMSG_DONE.

Here they are packed and read with `struct`, by pure functions that take and return
bytes: no sockets, no pyroute2. The senders are the AODV daemon (aodv/kernel.py: its
routes, the nftables set it polls), the oracle (topology/oracle.py: routes in every
robot's namespace), route queries (topology/kernel/routequery.py) and the medium's link
requests (topology/kernel/rtnl.py, whose link messages pyroute2 encodes once as templates).
pyroute2's own rtmsg class encodes the same route request in ~65 us against ~1 us here,
and its import costs ~20 MB and ~0.15 s in each daemon: the daemon's route updates and
the oracle's batches would pay for both.

Byte order is the host's (netlink is not a network protocol); every structure used is
4-byte aligned, so messages and attributes follow each other with no gap but the
padding of attribute values.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Iterator
from typing import NamedTuple

# --- structures ---------------------------------------------------------------------------
NLMSGHDR = struct.Struct("=LHHLL")  # length, type, flags, seq, port id
RTMSG = struct.Struct("=BBBBBBBBI")  # family, dst_len, src_len, tos, table, protocol,
# scope, type, flags
IFINFOMSG = struct.Struct("=BxHiII")  # family, (pad), type, index, flags, change
NFGENMSG = struct.Struct("=BBH")  # family, version, resource id
ATTR = struct.Struct("=HH")  # rtattr / nlattr: length, type
_I32 = struct.Struct("=i")
_U32 = struct.Struct("=I")
_U16 = struct.Struct("=H")
_SEQ_AT = 8  # offset of the sequence number in nlmsghdr

# --- numbers (linux/netlink.h, linux/rtnetlink.h, linux/netfilter/nf_tables.h) ------------
NLMSG_ERROR, NLMSG_DONE = 2, 3
NLM_F_REQUEST, NLM_F_ACK, NLM_F_DUMP = 0x1, 0x4, 0x300
NLM_F_REPLACE, NLM_F_EXCL, NLM_F_CREATE = 0x100, 0x200, 0x400
RTM_NEWLINK, RTM_GETLINK, RTM_SETLINK = 16, 18, 19
RTM_NEWROUTE, RTM_DELROUTE, RTM_GETROUTE = 24, 25, 26
RTA_DST, RTA_OIF, RTA_GATEWAY, RTA_PRIORITY, RTA_PREFSRC = 1, 4, 5, 6, 7
RT_TABLE_MAIN = 254
RTN_UNICAST = 1
RT_SCOPE_UNIVERSE, RT_SCOPE_LINK, RT_SCOPE_NOWHERE = 0, 253, 255
RTNH_F_ONLINK = 4
NLA_F_NESTED = 0x8000
NLA_TYPE_MASK = 0x3FFF  # the type without the nested / byte-order flags
NFT_MSG_GETSETELEM = (10 << 8) | 13  # NFNL_SUBSYS_NFTABLES, NFT_MSG_GETSETELEM
NFT_MSG_NEWSETELEM = (10 << 8) | 12  # what a set element dump answers with


# --- the generic parts ----------------------------------------------------------------------
def message(msg_type: int, flags: int, body: bytes, seq: int = 0) -> bytes:
    """One netlink message: the header, then `body` (family header and attributes)."""
    return NLMSGHDR.pack(NLMSGHDR.size + len(body), msg_type, flags, seq, 0) + body


def set_seq(buf: bytearray, seq: int, at: int = 0) -> None:
    """Write the sequence number of the message at `at` of `buf` (a batch numbers its own)."""
    _U32.pack_into(buf, at + _SEQ_AT, seq)


def attr(kind: int, value: bytes) -> bytes:
    """One attribute, its value padded to 4 bytes (the length counts the value unpadded)."""
    return ATTR.pack(ATTR.size + len(value), kind) + value + b"\0" * (-len(value) % 4)


def u32_attr(kind: int, value: int) -> bytes:
    return attr(kind, _U32.pack(value))


def string_attr(kind: int, text: str) -> bytes:
    """A NUL-terminated string attribute."""
    return attr(kind, text.encode() + b"\0")


def flag_attr(buf: bytearray, at: int, flag: int) -> None:
    """Set `flag` (NLA_F_NESTED) in the type of the attribute at `at` of `buf`."""
    (kind,) = _U16.unpack_from(buf, at + 2)
    _U16.pack_into(buf, at + 2, kind | flag)


def messages(data: bytes) -> Iterator[tuple[int, int, int, int]]:
    """(type, seq, payload start, payload end) of each message in one datagram `data`.

    Stops at a header that claims to be shorter than itself; an end past the datagram is
    cut to it."""
    off = 0
    while off + NLMSGHDR.size <= len(data):
        length, msg_type, _flags, seq, _pid = NLMSGHDR.unpack_from(data, off)
        if length < NLMSGHDR.size:
            return
        yield msg_type, seq, off + NLMSGHDR.size, min(off + length, len(data))
        off += (length + 3) & ~3


def attrs(data: bytes, at: int = 0, end: int | None = None) -> Iterator[tuple[int, int, int]]:
    """(type without flags, value start, value end) of each attribute in data[at:end].

    Stops at an attribute that claims to be shorter than its header; a value is never read
    past `end`."""
    end = len(data) if end is None else min(end, len(data))
    while at + ATTR.size <= end:
        length, kind = ATTR.unpack_from(data, at)
        if length < ATTR.size:
            return
        yield kind & NLA_TYPE_MASK, at + ATTR.size, min(at + length, end)
        at += (length + 3) & ~3


def attr_values(data: bytes) -> Iterator[tuple[int, bytes]]:
    """(type without flags, value) of each attribute in `data`."""
    for kind, start, stop in attrs(data):
        yield kind, data[start:stop]


def error_code(data: bytes, at: int) -> int:
    """The errno an NLMSG_ERROR payload at `at` carries (positive), 0 for an acknowledgement."""
    return -_I32.unpack_from(data, at)[0]


# --- routes (rtmsg) -------------------------------------------------------------------------
def route_message(
    msg_type: int,
    flags: int,
    dest: str,
    *,
    plen: int = 32,
    table: int = RT_TABLE_MAIN,
    proto: int = 0,
    scope: int = RT_SCOPE_UNIVERSE,
    rtype: int = RTN_UNICAST,
    rflags: int = 0,
    oif: int | None = None,
    gateway: str | None = None,
    prefsrc: str | None = None,
    priority: int | None = None,
    seq: int = 0,
) -> bytes:
    """An IPv4 route message for DEST/PLEN, attributes in the order `ip route` sends them:
    destination, output interface, gateway, preferred source, metric."""
    body = RTMSG.pack(socket.AF_INET, plen, 0, 0, table, proto, scope, rtype, rflags)
    body += attr(RTA_DST, socket.inet_aton(dest))
    if oif is not None:
        body += u32_attr(RTA_OIF, oif)
    if gateway is not None:
        body += attr(RTA_GATEWAY, socket.inet_aton(gateway))
    if prefsrc is not None:
        body += attr(RTA_PREFSRC, socket.inet_aton(prefsrc))
    if priority is not None:
        body += u32_attr(RTA_PRIORITY, priority)
    return message(msg_type, flags, body, seq)


def route_replace(
    dest: str, next_hop: str, oif: int, proto: int, *, ack: bool, seq: int = 0
) -> bytes:
    """`ip route replace DEST/32 [via NEXT_HOP onlink] dev OIF proto PROTO`.

    A next hop equal to the destination is a neighbour on the link: scope link and no
    gateway. Any other is reached through the gateway, onlink, as robots have /32
    addresses and no subnet to find it in. `ack`: ask the kernel to acknowledge success
    too (without it, it answers only a failure)."""
    flags = NLM_F_REQUEST | NLM_F_REPLACE | NLM_F_CREATE | (NLM_F_ACK if ack else 0)
    if next_hop == dest:
        return route_message(
            RTM_NEWROUTE, flags, dest, proto=proto, scope=RT_SCOPE_LINK, oif=oif, seq=seq
        )
    return route_message(
        RTM_NEWROUTE, flags, dest, proto=proto, rflags=RTNH_F_ONLINK, oif=oif,
        gateway=next_hop, seq=seq,
    )  # fmt: skip


def route_delete(dest: str, proto: int, *, plen: int = 32, ack: bool, seq: int = 0) -> bytes:
    """`ip route del DEST/PLEN proto PROTO` (table main)."""
    flags = NLM_F_REQUEST | (NLM_F_ACK if ack else 0)
    return route_message(
        RTM_DELROUTE, flags, dest, plen=plen, proto=proto, scope=RT_SCOPE_NOWHERE, rtype=0,
        seq=seq,
    )  # fmt: skip


def route_get(dest: str, seq: int = 1) -> bytes:
    """`ip route get DEST`: which route the kernel would use for the host DEST."""
    return route_message(
        RTM_GETROUTE, NLM_F_REQUEST, dest, table=0, scope=RT_SCOPE_UNIVERSE, rtype=0, seq=seq
    )


def route_dump(seq: int) -> bytes:
    """A dump of every IPv4 route of every table."""
    body = RTMSG.pack(socket.AF_INET, 0, 0, 0, 0, 0, 0, 0, 0)
    return message(RTM_GETROUTE, NLM_F_REQUEST | NLM_F_DUMP, body, seq)


class RouteAnswer(NamedTuple):
    """What a route message (RTM_NEWROUTE) says: rtmsg fields and the attributes we read,
    None where absent."""

    dst_len: int
    proto: int
    dst: str | None
    oif: int | None
    gateway: str | None


def parse_route(data: bytes, at: int, end: int) -> RouteAnswer | None:
    """The route message whose payload (rtmsg and attributes) is data[at:end]; None if it
    is too short to hold an rtmsg. Addresses are read only from 4-byte values."""
    if end - at < RTMSG.size:
        return None
    _fam, dst_len, _s, _t, _table, proto, *_ = RTMSG.unpack_from(data, at)
    dst = oif = gateway = None
    for kind, start, stop in attrs(data, at + RTMSG.size, end):
        if stop - start != 4:
            continue
        if kind == RTA_DST:
            dst = socket.inet_ntoa(data[start:stop])
        elif kind == RTA_GATEWAY:
            gateway = socket.inet_ntoa(data[start:stop])
        elif kind == RTA_OIF:
            oif = _U32.unpack_from(data, start)[0]
    return RouteAnswer(dst_len, proto, dst, oif, gateway)


# --- links (ifinfomsg) ----------------------------------------------------------------------
def link_get(family: int, index: int, *, dump: bool, seq: int) -> bytes:
    """RTM_GETLINK for interface `index`, or a dump of every interface of `family`
    (AF_BRIDGE: the bridge ports, as `bridge link show`)."""
    flags = NLM_F_REQUEST | (NLM_F_DUMP if dump else 0)
    return message(RTM_GETLINK, flags, IFINFOMSG.pack(family, 0, index, 0, 0), seq)


def link_index(data: bytes, at: int) -> int:
    """The interface index of the link message whose payload starts at `at`."""
    return IFINFOMSG.unpack_from(data, at)[2]


# --- nftables set elements (nfgenmsg) -------------------------------------------------------
_NFTA_SET_ELEM_LIST_TABLE, _NFTA_SET_ELEM_LIST_SET, _NFTA_SET_ELEM_LIST_ELEMENTS = 1, 2, 3
_NFTA_LIST_ELEM, _NFTA_SET_ELEM_KEY, _NFTA_DATA_VALUE = 1, 1, 1


def set_elements_dump(table: str, set_name: str, seq: int) -> bytes:
    """A dump of the elements of the IPv4 nftables set TABLE SET_NAME (`nft list set`)."""
    body = (
        NFGENMSG.pack(socket.AF_INET, 0, 0)
        + string_attr(_NFTA_SET_ELEM_LIST_TABLE, table)
        + string_attr(_NFTA_SET_ELEM_LIST_SET, set_name)
    )
    return message(NFT_MSG_GETSETELEM, NLM_F_REQUEST | NLM_F_DUMP, body, seq)


def set_element_addresses(data: bytes, start: int = 0, end: int | None = None) -> list[str]:
    """The IPv4 keys of the set elements in one NFT_MSG_NEWSETELEM payload, data[start:end]
    (read in place, by offsets: a poll's answer is parsed by every daemon every period)."""
    found = []
    for kind, s, e in attrs(data, start + NFGENMSG.size, end):
        if kind != _NFTA_SET_ELEM_LIST_ELEMENTS:
            continue
        for ekind, es, ee in attrs(data, s, e):
            if ekind != _NFTA_LIST_ELEM:
                continue
            for k, ks, ke in attrs(data, es, ee):
                if k != _NFTA_SET_ELEM_KEY:
                    continue
                for dk, vs, ve in attrs(data, ks, ke):
                    if dk == _NFTA_DATA_VALUE and ve - vs == 4:
                        found.append(socket.inet_ntoa(data[vs:ve]))
    return found
