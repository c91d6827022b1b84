"""An in-memory radio medium with a fake clock, for running AODV cores without IO.

Theory of operation: `Medium` holds one `AodvCore` per address, a set of directed links
and a discrete-event queue. Control messages are really encoded to bytes and decoded on
receipt (so the wire format is exercised), and take `hop_delay` seconds per hop. Each node
has a "kernel" routing table that follows the cores' Install/Delete actions, and data
packets are forwarded by it hop by hop as the Linux kernel would: a packet with no kernel
route goes to the core (`on_no_route`), each forward reports route use (like the daemon's
nftables set). Time only moves in `run_until`, jumping to the next event or core timer.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field

from aodv import packet as wire
from aodv.actions import (
    Broadcast,
    DeleteRoute,
    DiscoveryDone,
    DropPackets,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.core import AodvCore
from aodv.params import Params


@dataclass
class Sent:
    time: float
    src: str
    dst: str  # "255.255.255.255" for a broadcast
    ttl: int
    msg: wire.Message

    @property
    def kind(self) -> str:
        if wire.is_hello(self.msg, self.src):
            return "HELLO"
        return self.msg.type_name


@dataclass
class Node:
    addr: str
    core: AodvCore
    kernel: dict[str, tuple[str, int]] = field(default_factory=dict)
    delivered: list[tuple[float, str, bytes]] = field(default_factory=list)
    unreachable: list[tuple[float, str, bytes]] = field(default_factory=list)
    discoveries: list[DiscoveryDone] = field(default_factory=list)


def data_packet(src: str, dst: str, payload: bytes) -> bytes:
    return f"{src}|{dst}|".encode() + payload


def parse_data(pkt: bytes) -> tuple[str, str, bytes]:
    src, dst, payload = pkt.split(b"|", 2)
    return src.decode(), dst.decode(), payload


class Medium:
    def __init__(self, params: Params | None = None, hop_delay: float = 0.001) -> None:
        self.p = params or Params()
        self.hop_delay = hop_delay
        self.now = 0.0
        self.nodes: dict[str, Node] = {}
        self.links: set[tuple[str, str]] = set()  # directed: (from, to)
        self.log: list[Sent] = []
        self._events: list[tuple[float, int, Callable[[], None]]] = []
        self._tie = itertools.count()

    # -- building ------------------------------------------------------------------------
    def add_node(self, addr: str, rebooted: bool = False) -> Node:
        n = self.nodes[addr] = Node(addr, AodvCore(addr, self.p, self.now, rebooted))
        return n

    def link(self, a: str, b: str, both: bool = True) -> None:
        self.links.add((a, b))
        if both:
            self.links.add((b, a))

    def unlink(self, a: str, b: str, both: bool = True) -> None:
        self.links.discard((a, b))
        if both:
            self.links.discard((b, a))

    def chain(self, addrs: list[str]) -> None:
        for a in addrs:
            self.add_node(a)
        for a, b in zip(addrs, addrs[1:], strict=False):
            self.link(a, b)

    # -- running -------------------------------------------------------------------------
    def at(self, t: float, fn: Callable[[], None]) -> None:
        heapq.heappush(self._events, (t, next(self._tie), fn))

    def run_until(self, t_end: float) -> None:
        while True:
            t_ev = self._events[0][0] if self._events else float("inf")
            t_timer, node = min(
                ((n.core.next_deadline(), n) for n in self.nodes.values()),
                key=lambda x: x[0],
                default=(float("inf"), None),
            )
            t = min(t_ev, t_timer)
            if t > t_end:
                self.now = t_end
                return
            self.now = max(self.now, t)
            if t_ev <= t_timer:
                _, _, fn = heapq.heappop(self._events)
                fn()
            else:
                assert node is not None  # t_timer < t_ev: a node's deadline, not the default
                self._apply(node, node.core.on_timer(self.now))

    def send_data(self, src: str, dst: str, payload: bytes = b"x") -> None:
        """An application on `src` sends a packet to `dst` now."""
        self._route_packet(self.nodes[src], data_packet(src, dst, payload), local=True)

    # -- internals -----------------------------------------------------------------------
    def _apply(self, node: Node, actions: list) -> None:
        for a in actions:
            if isinstance(a, InstallRoute):
                node.kernel[a.dest] = (a.next_hop, a.hops)
            elif isinstance(a, DeleteRoute):
                node.kernel.pop(a.dest, None)
            elif isinstance(a, Unicast):
                self._transmit(node.addr, a.dst, a.ttl, a.msg, [a.dst])
            elif isinstance(a, Broadcast):
                nbrs = sorted(b for (x, b) in self.links if x == node.addr)
                self._transmit(node.addr, "255.255.255.255", a.ttl, a.msg, nbrs)
            elif isinstance(a, ReleasePackets):
                for pkt in a.packets:
                    self._route_packet(node, pkt, local=True)
            elif isinstance(a, DropPackets):
                node.unreachable.extend((self.now, a.dest, p) for p in a.packets)
            elif isinstance(a, DiscoveryDone):
                node.discoveries.append(a)

    def _transmit(self, src: str, dst: str, ttl: int, msg, receivers: list[str]) -> None:
        self.log.append(Sent(self.now, src, dst, ttl, msg))
        raw = wire.encode(msg)
        for r in receivers:
            if (src, r) in self.links and r in self.nodes:
                self.at(
                    self.now + self.hop_delay, functools.partial(self._receive, r, src, ttl, raw)
                )

    def _receive(self, at: str, src: str, ttl: int, raw: bytes) -> None:
        node = self.nodes[at]
        self._apply(node, node.core.on_control(self.now, src, ttl, wire.decode(raw)))

    def _route_packet(self, node: Node, pkt: bytes, local: bool) -> None:
        src, dst, _ = parse_data(pkt)
        if dst == node.addr:
            node.delivered.append((self.now, src, pkt))
            self._apply(node, node.core.on_route_used(self.now, src))
            return
        route = node.kernel.get(dst)
        if route is None:
            self._apply(node, node.core.on_no_route(self.now, src, dst, pkt))
            return
        for addr in (src, dst):
            self._apply(node, node.core.on_route_used(self.now, addr))
        nh = route[0]
        if (node.addr, nh) in self.links:
            self.at(
                self.now + self.hop_delay, lambda: self._route_packet(self.nodes[nh], pkt, False)
            )

    # -- queries -------------------------------------------------------------------------
    def sent(self, kind: str | None = None, src: str | None = None) -> list[Sent]:
        return [
            s
            for s in self.log
            if (kind is None or s.kind == kind) and (src is None or s.src == src)
        ]


def warm_up(params: Params | None = None, chains: int = 4, hops: int = 4) -> None:
    """Run discoveries over `hops` hops on throwaway in-memory chains (no IO; ~20 ms).

    The daemon calls this once at start. A fresh interpreter runs a code path several times
    slower the first few times (Python 3.11 specialises bytecode as it runs, and the
    objects and memory it touches are new): without it, every daemon paid that on the
    first discoveries of a run, the core's part of a hop's RREQ or RREP taking 70-160 us
    instead of 45-80 us on the 8-hop bench chain. Addresses are from 10.255.0.0/24 and
    nothing leaves this function. Without `params`, the RFC's defaults (what the routing fork
    server, topology.routing, warms its children with). Each discovery's chain runs for 2 s
    of the run's clock (2 / time_scale in the core's seconds), so the warm-up is the same
    events at every time scale: 2 wall seconds had it cost 17 ms at time scale 1 and
    125 ms at 30, for each daemon of a run."""
    params = params if params is not None else Params()
    span = 2.0 / params.time_scale
    # The throwaway chains' events (links lost when their nodes fall silent) are not the
    # robot's: keep them out of its log. No real core exists yet, so nothing real is hidden.
    core_log = logging.getLogger("aodv.core")
    was_disabled, core_log.disabled = core_log.disabled, True
    try:
        for _ in range(chains):
            m = Medium(params)
            addrs = [f"10.255.0.{i}" for i in range(1, hops + 2)]
            m.chain(addrs)
            for dst in addrs[1:]:
                m.send_data(addrs[0], dst)
                m.run_until(m.now + span)
    finally:
        core_log.disabled = was_disabled
