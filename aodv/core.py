"""Sans-IO AODV protocol core (RFC 3561): the events of one node, dispatched.

Theory of operation
-------------------
`AodvCore` is the whole protocol of one node and nothing else: it never opens a socket and
never reads a clock. The daemon (or a test) feeds it events, each with `now` (seconds of any
monotonic clock), and executes the actions it returns, in order:

    events                                   actions
    on_control(now, src, ttl, msg)           Unicast(msg, dst, ttl), Broadcast(msg, ttl)
    on_no_route(now, src, dst, packet)       InstallRoute(dest, next_hop, hops)
    on_route_used(now, addr)                 DeleteRoute(dest)
    on_link_lost(now, neighbor)              ReleasePackets(dest, packets)
    on_timer(now)                            DropPackets(dest, packets)  (ICMP unreachable)
    on_routes_used(now, addrs)               DiscoveryDone(dest, ok, latency, round_latency)

After every call `next_deadline()` says when `on_timer` must run next. Route actions are
a diff of the valid routing-table entries against what was already installed. Every
returned list is ordered for the discovery's critical path (see `_finish`): RREQs, RREPs
and RERRs first, then route actions, then releases, drops and DiscoveryDone (a Release
always follows the Install it needs), and RREP-ACKs last.

The protocol is split by the RFC's sections into collaborating classes that share one
explicit state object (aodv.state.NodeState: address, counters, routing table, neighbours,
queues); `AodvCore` makes them, routes each event to the one whose job it is, and orders
what they return:

    aodv/discovery.py    RouteDiscovery     RREQ origination, ring search, queue (6.3-6.5)
    aodv/replies.py      Replies            RREP generation and processing, RREP-ACK (6.6-6.8)
    aodv/hello.py        Hellos             HELLOs and neighbour liveness (6.9-6.10)
    aodv/maintenance.py  RouteMaintenance   RERR, local repair, route expiry (6.11-6.12)
    aodv/datapath.py     DataPath           route use (6.2), the kernel's copy of the table
    aodv/actions.py      the actions above

Each part holds the state only its section touches (the rate limits, the kernel's copy
of the table) and is handed the collaborators it calls: discovery answers a RREQ through
the replies, maintenance repairs a route through discovery. Where a discovery's outcome
concerns maintenance (a local repair that ended), the core passes it on. The state's
attributes (seq, table, neighbors, ...) read and write through the core as before the
split.

Where the RFC leaves a choice, the decision is written next to the rule as "Decision:", in
the module of its section. The main ones, for a reader in a hurry:

- Parameters: section 10 with its notes (MY_ROUTE_TIMEOUT 11.2 s, TTL_START 2,
  BLACKLIST_TIMEOUT for the ring search, DELETE_PERIOD 5 * max(ACTIVE_ROUTE_TIMEOUT,
  HELLO_INTERVAL)), or ns-3's defaults: see params.py and docs/aodv.md.
- HELLO extension type 1 (RFC 9.1, IANA); Wireshark's 2 accepted on receipt: packet.py.
- RREP IP TTL 64 (unicast to the next hop, which re-originates it); HELLO and multi-
  precursor RERR use IP TTL 1 to 255.255.255.255, the limited broadcast (robots have /32
  addresses, there is no subnet broadcast).
- Destination sequence number in a RREP: max(own, RREQ's) as RFC 6.1 says (6.6.1's
  "increment if equal" is a special case of it).
- G flag set on every RREQ (our traffic is bidirectional), D flag off unless configured.
- A flag (RREP-ACK request) on a RREP to a neighbour not yet shown to hear us; a late
  RREP-ACK lifts the blacklisting.
- RERR for a forwarded packet with no route and no known precursor: broadcast, TTL 1.
- HELLOs only from nodes on an active route (set up by a reply or used by data), and at
  most HELLO_INTERVAL after the node's last broadcast.
- Reboot rule (6.13): applied whenever the daemon starts again in a running network (it
  finds its predecessor's saved counters, or its routes in the kernel); for DELETE_PERIOD
  the node learns routes but originates no RREQ (data waits), sends no RREP and forwards no
  control message; its sequence number and RREQ ID resume above any it used before.
- RREQs over RREQ_RATELIMIT are delayed; RERRs over RERR_RATELIMIT are dropped; forwarded
  RREQs over `rreq_forward_ratelimit` are dropped (not an RFC limit: a flood guard).
- Sequence numbers never go backwards (6.1): a RERR with an older number than the entry's
  still invalidates the route (its sender cannot deliver) but leaves the number alone.
- Local repair (6.12) on a link break of a route with precursors, one RREQ, as the RFC
  describes it (Params.local_repair; off in the ns3 profile). RERRs with N set are passed on.
- Every value read from a peer is bounded before it is used: hop counts of NET_DIAMETER or
  more are dropped, lifetimes and Hello Intervals are clamped (counted in `dropped`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any, Generic, TypeVar

from aodv.actions import (
    LOCAL_TTL,
    UNICAST_TTL,
    Action,
    Broadcast,
    DeleteRoute,
    DiscoveryDone,
    DropPackets,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.datapath import DataPath
from aodv.discovery import RouteDiscovery
from aodv.hello import Hellos
from aodv.maintenance import RouteMaintenance
from aodv.neighbors import Neighbors
from aodv.packet import Message, Rerr, Rrep, RrepAck, Rreq, is_hello
from aodv.params import Params
from aodv.replies import Replies
from aodv.request_queue import RequestQueue
from aodv.routes import RoutingTable
from aodv.rreq_cache import RreqCache
from aodv.state import Discovery, NodeState

# The actions are defined in aodv.actions; callers may import them from here.
__all__ = [
    "LOCAL_TTL",
    "UNICAST_TTL",
    "Action",
    "AodvCore",
    "Broadcast",
    "DeleteRoute",
    "DiscoveryDone",
    "DropPackets",
    "InstallRoute",
    "ReleasePackets",
    "Unicast",
]

T = TypeVar("T")


class _Shared(Generic[T]):
    """An attribute of the node's state, read and written through the core."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, core: AodvCore, owner: Any = None) -> T:
        return getattr(core.state, self.name)

    def __set__(self, core: AodvCore, value: T) -> None:
        setattr(core.state, self.name, value)


class AodvCore:
    addr = _Shared[str]()
    p = _Shared[Params]()
    seq = _Shared[int]()
    rreq_id = _Shared[int]()
    table = _Shared[RoutingTable]()
    rreq_cache = _Shared[RreqCache]()
    neighbors = _Shared[Neighbors]()
    queue = _Shared[RequestQueue]()
    discoveries = _Shared[dict[str, Discovery]]()
    pending_acks = _Shared[dict[str, float]]()
    bidirectional = _Shared[dict[str, float]]()
    next_hello = _Shared[float]()
    dropped = _Shared[Counter[str]]()
    reboot_until = _Shared[float | None]()

    def __init__(
        self,
        addr: str,
        params: Params,
        now: float,
        rebooted: bool = False,
        seq: int = 0,
        rreq_id: int = 0,
    ) -> None:
        """`seq` and `rreq_id`: where a restarted node resumes (above all it used before)."""
        self.state = NodeState(addr, params, now, rebooted, seq, rreq_id)
        self.replies = Replies(self.state)
        self.discovery = RouteDiscovery(self.state, self.replies)
        self.maintenance = RouteMaintenance(self.state, self.discovery)
        self.hellos = Hellos(self.state)
        self.datapath = DataPath(self.state)

    @property
    def _installed(self) -> dict[str, tuple[str, int]]:
        """What the kernel was told (the data path's copy of the valid routes)."""
        return self.datapath.installed

    # == public events ====================================================================
    def on_control(self, now: float, src: str, ttl: int, msg: Message) -> list[Action]:
        """A control message from `src` (IP source), received with IP TTL `ttl`."""
        s = self.state
        out: list[Action] = []
        if src == s.addr:
            return out
        # RFC 6.10: any packet from a neighbour shows the link is alive.
        s.neighbors.heard(src, now)
        # Decision: a RREQ or RREP that has travelled NET_DIAMETER hops or more describes
        # no path this network can have ("NET_DIAMETER measures the maximum possible number
        # of hops between two nodes in the network", section 10), and one more hop would
        # not fit the one-byte field: drop it.
        if isinstance(msg, (Rreq, Rrep)) and msg.hop_count >= s.p.net_diameter:
            s.dropped["hop_count"] += 1
            return self._finish(now, out)
        if isinstance(msg, Rreq):
            self.discovery.on_rreq(now, src, ttl, msg, out)  # RFC 6.5
        elif isinstance(msg, Rrep):
            if is_hello(msg, src):
                self.hellos.on_hello(now, src, msg)  # RFC 6.9
            else:
                self.replies.on_rrep(now, src, msg, out)  # RFC 6.7
        elif isinstance(msg, Rerr):
            self.maintenance.on_rerr(now, src, msg, out)  # RFC 6.11 (iii)
        elif isinstance(msg, RrepAck):
            self.replies.on_ack(now, src)  # RFC 6.8
        return self._finish(now, out)

    def on_no_route(self, now: float, src: str, dst: str, packet: bytes) -> list[Action]:
        """A data packet from `src` to `dst` found no kernel route."""
        out: list[Action] = []
        if self.state.table.valid(dst) is not None:
            # We hold a valid route the kernel has lost (removed behind our back): install
            # it again and send the packet on, whoever sent it.
            self.datapath.reinstall(dst)
            out.append(ReleasePackets(dst, (packet,)))
        elif src == self.state.addr:
            self.discovery.originate(now, dst, packet, out)  # RFC 6.3
        else:
            self.maintenance.forward_without_route(now, dst, packet, out)  # RFC 6.11 (ii)
        return self._finish(now, out)

    def on_route_used(self, now: float, addr: str) -> list[Action]:
        """Data to or from `addr` crossed this node recently (RFC 6.2)."""
        return self.on_routes_used(now, (addr,))

    def on_routes_used(self, now: float, addrs: Iterable[str]) -> list[Action]:
        """Data to or from each of `addrs` crossed this node recently (RFC 6.2): one poll of
        the route uses, in one event. It ends as `on_route_used` of each in turn ends, with
        the route actions of all of them in one diff."""
        for addr in addrs:
            self.datapath.used(now, addr)
        return self._finish(now, [])

    def on_link_lost(self, now: float, neighbor: str) -> list[Action]:
        """The link to `neighbor` broke (detected outside the core, e.g. by the driver)."""
        out: list[Action] = []
        self.state.neighbors.forget(neighbor)
        self.maintenance.link_break(now, neighbor, out)
        return self._finish(now, out)

    def on_timer(self, now: float) -> list[Action]:
        s = self.state
        out: list[Action] = []
        if s.reboot_until is not None and now >= s.reboot_until:
            s.reboot_until = None
        # RFC 6.10 / 6.11 (i): silent monitored neighbours are lost links.
        for n in self.hellos.lost(now):
            self.maintenance.link_break(now, n, out)
        self.maintenance.expire_routes(now)
        s.rreq_cache.purge(now)
        self.replies.expire(now)  # RFC 6.8
        for d in list(s.discoveries.values()):
            if d.deadline <= now:
                if d.repair_hops is not None and not d.deferred:
                    self.maintenance.repair_failed(now, d, out)  # RFC 6.12
                else:
                    self.discovery.timeout(now, d, out)  # RFC 6.3 / 6.4
        if now >= s.next_hello:
            self.hellos.maybe_send(now, out)  # RFC 6.9
        return self._finish(now, out)

    def next_deadline(self) -> float:
        s = self.state
        t = s.next_hello
        for c in (s.table.next_deadline(), self.hellos.next_deadline(), s.reboot_until):
            if c is not None and c < t:
                t = c
        for d in s.discoveries.values():
            if d.deadline < t:
                t = d.deadline
        if s.pending_acks:
            t = min(t, *s.pending_acks.values())
        return t

    # == after every event ================================================================
    def _finish(self, now: float, out: list[Action]) -> list[Action]:
        s = self.state
        if s.discoveries:
            # Discoveries that now have a route release their packets; a local repair that
            # found a longer route is reported by route maintenance (RFC 6.12).
            for d, r in self.discovery.complete(now, out):
                self.maintenance.repaired(now, d, r, out)
        if len(s.table) > s.p.route_table_limit:
            gone = s.table.shrink(s.p.route_table_limit, now, keep=s.discoveries)
            s.dropped["route_evicted"] += gone
        routes = self.datapath.sync()
        if not out:
            return routes
        # Decision: control messages leave before the route changes of the same event,
        # because they are what the next node waits for. They never need those routes:
        # they go to a neighbour or to the limited broadcast address (RFC 3561 6.5: a
        # forwarded RREQ is broadcast; 6.6/6.7: a RREP is unicast to the next hop towards
        # the originator, which is the neighbour it came from). A data packet that would
        # beat the install to the kernel cannot draw a RERR either: it reaches the core
        # through `on_no_route`, which finds the valid entry and installs it. RREP-ACKs
        # (RFC 6.8, only ever awaited for NEXT_HOP_WAIT) go last, after the releases
        # and DiscoveryDone: nobody's discovery waits for them.
        sends: list[Action] = []
        rest: list[Action] = []
        acks: list[Action] = []
        for a in out:
            if isinstance(a, (Unicast, Broadcast)):
                (acks if isinstance(a.msg, RrepAck) else sends).append(a)
            else:
                rest.append(a)
        return sends + routes + rest + acks

    # == inspection =======================================================================
    def routes(self) -> dict[str, tuple[str, int]]:
        """Valid routes: destination -> (next hop, hops)."""
        return {r.dest: r.kernel_key() for r in self.state.table.peek_all() if r.valid}
