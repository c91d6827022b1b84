"""Batched rtnetlink requests: pyroute2's message classes, sent many to one write.

pyroute2's IPRoute costs about 1.5 ms per request on this machine (an asyncio round trip per
call), which alone would break the bring-up and link-update budgets. The kernel needs far
less: so here pyroute2 encodes the link and address messages (ifinfmsg, ifaddrmsg, nested
attributes that are encoded once as templates) and we write a whole batch to a raw
NETLINK_ROUTE socket in one go, then read one acknowledgement per message. Headers, the
answers and the requests packed by hand (route requests, the bridge port dump) are
netlinkmsg's.

Interfaces get their ifindex chosen by us at creation (RTM_NEWLINK honours ifi_index), so no
request ever has to look a name up, and the messages that flip a link on and off can be
encoded once and resent as bytes.
"""

import os
import socket
import struct

from pyroute2.netlink.rtnl import RTM_NEWADDR
from pyroute2.netlink.rtnl.ifaddrmsg import ifaddrmsg
from pyroute2.netlink.rtnl.ifinfmsg import ifinfmsg

from topology.kernel import netlinkmsg as nl
from topology.kernel.netlinkmsg import (
    NLA_F_NESTED,
    NLM_F_ACK,
    NLM_F_CREATE,
    NLM_F_EXCL,
    NLM_F_REQUEST,
    NLMSG_DONE,
    NLMSG_ERROR,
    RTM_NEWLINK,
    RTM_SETLINK,
)

IFF_UP = 0x1
BR_STATE_DISABLED = 0
BR_STATE_FORWARDING = 3
REQUEST = NLM_F_REQUEST | NLM_F_ACK
CREATE = REQUEST | NLM_F_CREATE | NLM_F_EXCL
MAX_WRITE = 60_000
MAX_INFLIGHT = 256  # requests written before their acknowledgements are read
IFLA_IFNAME = 3
IFLA_PROTINFO = 12
IFLA_OPERSTATE = 16
IFLA_LINKINFO = 18
IFLA_INFO_SLAVE_DATA = 5
IFLA_BRPORT_STATE = 1
IF_OPER_UP = 6


class NetlinkBatchError(OSError):
    """One or more requests of a batch failed; names the first failure."""


def _encode(msg, msg_type: int, flags: int) -> bytes:
    msg["header"]["type"] = msg_type
    msg["header"]["flags"] = flags
    msg.encode()
    return bytes(msg.data)


def link(
    index: int,
    *,
    ifname: str | None = None,
    kind: str | None = None,
    master: int | None = None,
    up: bool | None = None,
    veth_peer: tuple[str, int, int | None] | None = None,
    isolated: bool | None = None,
    create: bool = False,
) -> bytes:
    """RTM_NEWLINK: create (create=True) or change interface `index`.

    veth_peer is (name, index, netns fd or None). isolated sets the bridge-port flag (the
    interface must already be a bridge port)."""
    m = ifinfmsg()
    m["index"] = index
    attrs: list = []
    if ifname:
        attrs.append(("IFLA_IFNAME", ifname))
    if master is not None:
        attrs.append(("IFLA_MASTER", master))
    if kind:
        info: list = [("IFLA_INFO_KIND", kind)]
        if veth_peer:
            name, pindex, nsfd = veth_peer
            peer_attrs: list = [("IFLA_IFNAME", name)]
            if nsfd is not None:
                peer_attrs.append(("IFLA_NET_NS_FD", nsfd))
            peer = {"attrs": peer_attrs, "index": pindex}
            info.append(("IFLA_INFO_DATA", {"attrs": [("VETH_INFO_PEER", peer)]}))
        attrs.append(("IFLA_LINKINFO", {"attrs": info}))
    if isolated is not None:
        slave = {"attrs": [("IFLA_BRPORT_ISOLATED", int(isolated))]}
        attrs.append(
            ("IFLA_LINKINFO", {"attrs": [("IFLA_INFO_SLAVE_KIND", "bridge"),
                                         ("IFLA_INFO_SLAVE_DATA", slave)]})
        )  # fmt: skip
    if up is not None:
        m["flags"] = IFF_UP if up else 0
        m["change"] = IFF_UP
    m["attrs"] = attrs
    return _encode(m, RTM_NEWLINK, CREATE if create else REQUEST)


def port_state(index: int, state: int) -> bytes:
    """RTM_SETLINK, family AF_BRIDGE: set the STP state of bridge port `index`, as
    `bridge link set dev X state N` does. (The same attribute sent as bridge-slave data is
    accepted and ignored by this kernel.) The kernel reads IFLA_PROTINFO as nested only if
    it carries NLA_F_NESTED; pyroute2 does not set that flag, so it is set here."""
    m = ifinfmsg()
    m["family"] = socket.AF_BRIDGE
    m["index"] = index
    m["attrs"] = [("IFLA_PROTINFO", {"attrs": [("IFLA_BRPORT_STATE", state)]})]
    buf = bytearray(_encode(m, RTM_SETLINK, REQUEST))
    nl.flag_attr(buf, nl.NLMSGHDR.size + nl.IFINFOMSG.size, NLA_F_NESTED)  # the first one
    return bytes(buf)


class Template:
    """A request encoded once by pyroute2, then re-filled by patching bytes.

    pyroute2 takes ~0.5 ms to encode one message; a bring-up sends a thousand that differ
    only in interface indices and names. The template is encoded with a sentinel in each
    variable u32 field and a placeholder of the right length in each variable string, and
    remembers where they landed. `build` is called with the variable fields as keywords,
    plus `fixed`."""

    def __init__(self, build, ints=("index",), strs: dict[str, int] | None = None, **fixed):
        strs = strs or {}
        values: dict = {name: 0x7EAD0000 + n for n, name in enumerate(ints)}
        values |= {
            name: chr(ord("Q") + n) * length for n, (name, length) in enumerate(strs.items())
        }
        self.data = build(**values, **fixed)
        self.ints = {name: self._find(struct.pack("=I", values[name])) for name in ints}
        self.strs = {name: self._find(values[name].encode()) for name in strs}
        self.lengths = dict(strs)

    def _find(self, needle: bytes) -> int:
        at = self.data.find(needle)
        if at < 0 or self.data.find(needle, at + 1) >= 0:
            raise ValueError("template field not found exactly once")
        return at

    def __call__(self, **values) -> bytes:
        buf = bytearray(self.data)
        for name, value in values.items():
            if name in self.ints:
                struct.pack_into("=I", buf, self.ints[name], value)
            else:
                raw = value.encode()
                if len(raw) != self.lengths[name]:
                    raise ValueError(f"{name} {value!r} does not fit this template")
                buf[self.strs[name] : self.strs[name] + len(raw)] = raw
        return bytes(buf)


def veth(
    index: int, ifname: str, master: int, peer_name: str, peer_index: int,
    peer_nsfd: int | None = None, up: bool | None = None,
) -> bytes:  # fmt: skip
    """RTM_NEWLINK creating veth `ifname` (a port of bridge `master`) and its peer, the
    peer in the namespace of `peer_nsfd` if given."""
    return link(index, ifname=ifname, kind="veth", master=master, create=True, up=up,
                veth_peer=(peer_name, peer_index, peer_nsfd))  # fmt: skip


def bridge(index: int, ifname: str) -> bytes:
    """RTM_NEWLINK creating bridge `ifname`, up."""
    return link(index, ifname=ifname, kind="bridge", up=True, create=True)


def addr(index: int, address: str, prefixlen: int) -> bytes:
    """RTM_NEWADDR: an IPv4 address on interface `index`."""
    m = ifaddrmsg()
    m["family"] = socket.AF_INET
    m["prefixlen"] = prefixlen
    m["index"] = index
    m["attrs"] = [("IFA_LOCAL", address), ("IFA_ADDRESS", address)]
    return _encode(m, RTM_NEWADDR, CREATE)


class Batch:
    """Requests queued with a description each, sent together by `send`."""

    def __init__(self) -> None:
        self.requests: list[tuple[bytes, str]] = []

    def add(self, request: bytes, what: str) -> None:
        self.requests.append((request, what))

    def __len__(self) -> int:
        return len(self.requests)

    def send(self, sock: socket.socket) -> None:
        """Write the requests a chunk at a time, reading each chunk's acknowledgements before
        the next is written; raise on the first failure once every chunk has gone.

        The kernel queues one acknowledgement per request on the socket (a successful one is
        an NLMSG_ERROR of ~0.7 kB of buffer once the skb overhead is counted; a failed one
        quotes the request), and drops the socket with ENOBUFS when the receive buffer is
        full: a whole bring-up of 500 robots written before reading would need tens of MB.
        A chunk of at most MAX_WRITE bytes and MAX_INFLIGHT requests always fits."""
        if not self.requests:
            return
        seqs: dict[int, str] = {}
        failures: list[tuple[str, int]] = []
        chunk = bytearray()
        inflight = 0
        for n, (req, what) in enumerate(self.requests, start=1):
            buf = bytearray(req)
            nl.set_seq(buf, n)  # our own sequence numbers, 1..N
            seqs[n] = what
            if chunk and (len(chunk) + len(buf) > MAX_WRITE or inflight >= MAX_INFLIGHT):
                _exchange(sock, chunk, inflight, seqs, failures)
                chunk, inflight = bytearray(), 0
            chunk += buf
            inflight += 1
        if chunk:
            _exchange(sock, chunk, inflight, seqs, failures)
        self.requests.clear()
        if failures:
            what, code = failures[0]
            more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
            raise NetlinkBatchError(code, f"{what}: {os.strerror(code)}{more}")


def _exchange(
    sock: socket.socket, chunk: bytearray, count: int, seqs: dict[int, str],
    failures: list[tuple[str, int]],
) -> None:  # fmt: skip
    """Write one chunk of `count` requests and read their `count` acknowledgements."""
    sock.send(chunk)
    acked = 0
    while acked < count:
        data = sock.recv(1 << 20)
        for mtype, seq, start, _end in nl.messages(data):
            if mtype == NLMSG_ERROR:
                code = nl.error_code(data, start)
                acked += 1
                if code:
                    failures.append((seqs.get(seq, f"request {seq}"), code))


def open_socket() -> socket.socket:
    """A NETLINK_ROUTE socket in the calling thread's network namespace."""
    sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, socket.NETLINK_ROUTE)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    sock.bind((0, 0))
    return sock


def bridge_ports(sock: socket.socket) -> dict[int, tuple[str, int, int]]:
    """Every bridge port of the socket's namespace: {ifindex: (name, STP state, operstate)},
    from one AF_BRIDGE dump (what `bridge link show` lists).

    Parsed here with struct, reading only the three attributes we need: pyroute2 decodes
    every attribute of every message, ~0.2 ms a port, which made one dump of the 5000 ports
    of a 1000-robot medium cost a second; this costs a few ms."""
    sock.send(nl.link_get(socket.AF_BRIDGE, 0, dump=True, seq=1))
    ports: dict[int, tuple[str, int, int]] = {}
    while True:
        data = sock.recv(1 << 20)
        for mtype, _seq, start, end in nl.messages(data):
            if mtype == NLMSG_DONE:
                return ports
            if mtype == NLMSG_ERROR:
                code = nl.error_code(data, start)
                if code:
                    raise NetlinkBatchError(code, f"bridge port dump: {os.strerror(code)}")
            elif mtype == RTM_NEWLINK:
                ports[nl.link_index(data, start)] = _port_attrs(data, start, end)


def port_states(sock: socket.socket, indices) -> dict[int, tuple[str, int, int]]:
    """As bridge_ports, for the given interfaces only (absent ones are left out): one
    RTM_GETLINK per interface, a chunk at a time. Cheaper than the dump when they are a
    few of the thousands of ports of a large medium (the feed's new links)."""
    indices = list(indices)
    ports: dict[int, tuple[str, int, int]] = {}
    for at in range(0, len(indices), 64):  # ~2 kB an answer: a chunk fits the buffer
        chunk = b"".join(
            nl.link_get(socket.AF_UNSPEC, index, dump=False, seq=n)
            for n, index in enumerate(indices[at : at + 64], start=1)
        )
        sock.send(chunk)
        answers = len(indices[at : at + 64])
        while answers:
            data = sock.recv(1 << 20)
            for mtype, _seq, start, end in nl.messages(data):
                if mtype in (NLMSG_ERROR, RTM_NEWLINK):
                    answers -= 1
                if mtype == RTM_NEWLINK:
                    ports[nl.link_index(data, start)] = _port_attrs(data, start, end)
    return ports


def _port_attrs(data: bytes, at: int, end: int) -> tuple[str, int, int]:
    """(IFLA_IFNAME, IFLA_BRPORT_STATE, IFLA_OPERSTATE) of the RTM_NEWLINK message whose
    payload is data[at:end]; -1 for what is absent. The port state is in IFLA_PROTINFO in an
    AF_BRIDGE dump, in IFLA_LINKINFO's bridge-slave data in an ordinary answer."""
    name, state, oper = "", -1, -1
    for kind, body, stop in nl.attrs(data, at + nl.IFINFOMSG.size, end):
        if kind == IFLA_IFNAME:
            name = data[body:stop].split(b"\0", 1)[0].decode()
        elif kind == IFLA_OPERSTATE:
            oper = data[body]
        elif kind == IFLA_PROTINFO:
            state = _brport_state(data, body, stop, state)
        elif kind == IFLA_LINKINFO:
            for sub, sbody, sstop in nl.attrs(data, body, stop):
                if sub == IFLA_INFO_SLAVE_DATA:
                    state = _brport_state(data, sbody, sstop, state)
    return name, state, oper


def _brport_state(data: bytes, at: int, end: int, default: int) -> int:
    for kind, body, _ in nl.attrs(data, at, end):
        if kind == IFLA_BRPORT_STATE:
            return data[body]
    return default
