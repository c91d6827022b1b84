"""Sans-IO AODV protocol core (RFC 3561).

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
                                             DiscoveryDone(dest, ok, latency, round_latency)

After every call `next_deadline()` says when `on_timer` must run next. Route actions are
a diff of the valid routing-table entries against what was already installed. Every
returned list is ordered for the discovery's critical path (see `_finish`): RREQs, RREPs
and RERRs first, then route actions, then releases, drops and DiscoveryDone (a Release
always follows the Install it needs), and RREP-ACKs last.

Where the RFC leaves a choice, the decision is written next to the rule as "Decision:".
The main ones, for a reader in a hurry:

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

import logging
from collections import Counter, deque
from dataclasses import dataclass

from aodv import seqnum
from aodv.neighbors import Neighbors
from aodv.packet import Message, Rerr, Rrep, RrepAck, Rreq, is_hello
from aodv.params import Params
from aodv.request_queue import RequestQueue
from aodv.routes import Route, RoutingTable
from aodv.rreq_cache import RreqCache

log = logging.getLogger(__name__)

# Decision (RREP IP TTL): a RREP travels hop by hop and is unicast to the next hop, which
# re-originates it, so any IP TTL >= 1 arrives. We send 64 so that a RREP can never be
# taken for a HELLO (IP TTL 1, RFC 6.9) by a receiver that looks at the IP TTL.
UNICAST_TTL = 64
# RFC 6.11: a RERR to several precursors goes to "the local broadcast address
# (Destination IP == 0xFFFFFFFF, TTL == 1)". HELLOs (RFC 6.9) also carry IP TTL 1.
# Decision (limited vs subnet broadcast): robots have /32 addresses and no subnet, so
# every broadcast is the limited broadcast 255.255.255.255 on wlan0.
LOCAL_TTL = 1
# The longest Lifetime taken from a peer's RREP, in units of our MY_ROUTE_TIMEOUT.
MAX_LIFETIME_FACTOR = 10


# -- actions ---------------------------------------------------------------------------
# Plain slotted dataclasses (values by convention): a frozen one costs several times as
# much to build, and every control message builds two or three actions.
@dataclass(slots=True)
class Unicast:
    msg: Message
    dst: str
    ttl: int = UNICAST_TTL


@dataclass(slots=True)
class Broadcast:
    msg: Message
    ttl: int


@dataclass(slots=True)
class InstallRoute:
    dest: str
    next_hop: str
    hops: int


@dataclass(slots=True)
class DeleteRoute:
    dest: str


@dataclass(slots=True)
class ReleasePackets:
    dest: str
    packets: tuple[bytes, ...]


@dataclass(slots=True)
class DropPackets:
    dest: str
    packets: tuple[bytes, ...]


@dataclass(slots=True)
class DiscoveryDone:
    dest: str
    ok: bool
    latency: float  # first RREQ to route (or to giving up)
    round_latency: float  # the last RREQ sent to route
    repair: bool = False  # a local repair (RFC 6.12), not a discovery of our own


Action = (
    Unicast | Broadcast | InstallRoute | DeleteRoute | ReleasePackets | DropPackets | DiscoveryDone
)


@dataclass
class _Discovery:
    dest: str
    ttl: int
    started: float
    deadline: float = 0.0
    round_started: float = 0.0
    retries: int = 0
    deferred: bool = False  # the RREQ waits (rate limit or reboot), it was not sent
    repair_hops: int | None = None  # a local repair: the hop count of the broken route


class _RateLimit:
    """At most `limit` events per sliding `window` (RFC RREQ_RATELIMIT, RERR_RATELIMIT)."""

    def __init__(self, limit: int, window: float) -> None:
        self.limit, self.window = limit, window
        self._times: deque[float] = deque()

    def _trim(self, now: float) -> None:
        while self._times and self._times[0] <= now - self.window:
            self._times.popleft()

    def allow(self, now: float) -> bool:
        self._trim(now)
        if len(self._times) >= self.limit:
            return False
        self._times.append(now)
        return True

    def next_free(self, now: float) -> float:
        self._trim(now)
        return self._times[0] + self.window if len(self._times) >= self.limit else now


class AodvCore:
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
        self.addr = addr
        self.p = params
        self.seq = seq
        self.rreq_id = rreq_id
        self.table = RoutingTable()
        self.rreq_cache = RreqCache(params.rreq_cache_limit)
        self.neighbors = Neighbors(params.neighbor_limit)
        self.queue = RequestQueue(params.queue_len)
        self.discoveries: dict[str, _Discovery] = {}
        self.pending_acks: dict[str, float] = {}
        self.bidirectional: dict[str, float] = {}
        self._rreq_limit = _RateLimit(params.rreq_ratelimit, params.rate_window)
        self._rerr_limit = _RateLimit(params.rerr_ratelimit, params.rate_window)
        self._fwd_limit = _RateLimit(params.rreq_forward_ratelimit, params.rate_window)
        self._installed: dict[str, tuple[str, int]] = {}
        self.next_hello = now + params.hello_interval
        # What the core refused or bounded, by reason (the daemon writes it in its stats).
        self.dropped: Counter[str] = Counter()
        # RFC 6.13: "...after rebooting, a node MUST wait for DELETE_PERIOD before
        # transmitting any route discovery messages." Decision: the daemon says whether
        # this start is a reboot (a previous instance ran in this network: it left its
        # counters or its routes); a first start has no stale sequence numbers to protect.
        self.reboot_until = now + params.delete_period if rebooted else None

    # == public events ====================================================================
    def on_control(self, now: float, src: str, ttl: int, msg: Message) -> list[Action]:
        """A control message from `src` (IP source), received with IP TTL `ttl`."""
        out: list[Action] = []
        if src == self.addr:
            return out
        # RFC 6.10: any packet from a neighbour shows the link is alive.
        self.neighbors.heard(src, now)
        # Decision: a RREQ or RREP that has travelled NET_DIAMETER hops or more describes
        # no path this network can have ("NET_DIAMETER measures the maximum possible number
        # of hops between two nodes in the network", section 10), and one more hop would
        # not fit the one-byte field: drop it.
        if isinstance(msg, (Rreq, Rrep)) and msg.hop_count >= self.p.net_diameter:
            self.dropped["hop_count"] += 1
            return self._finish(now, out)
        if isinstance(msg, Rreq):
            self._rreq(now, src, ttl, msg, out)
        elif isinstance(msg, Rrep):
            if is_hello(msg, src):
                self._hello(now, src, msg)
            else:
                self._rrep(now, src, msg, out)
        elif isinstance(msg, Rerr):
            self._rerr(now, src, msg, out)
        elif isinstance(msg, RrepAck):
            self._rrep_ack(now, src)
        return self._finish(now, out)

    def on_no_route(self, now: float, src: str, dst: str, packet: bytes) -> list[Action]:
        """A data packet from `src` to `dst` found no kernel route."""
        out: list[Action] = []
        if self.table.valid(dst) is not None:
            # We hold a valid route the kernel has lost (removed behind our back): install
            # it again and send the packet on, whoever sent it.
            self._installed.pop(dst, None)
            out.append(ReleasePackets(dst, (packet,)))
        elif src == self.addr:
            self._originate(now, dst, packet, out)
        else:
            self._forward_without_route(now, dst, packet, out)
        return self._finish(now, out)

    def on_route_used(self, now: float, addr: str) -> list[Action]:
        """Data to or from `addr` crossed this node recently.

        RFC 6.2: "Each time a route is used to forward a data packet, its Active Route
        Lifetime field of the source, destination and the next hop on the path to the
        destination is updated to be no less than the current time plus
        ACTIVE_ROUTE_TIMEOUT." The daemon reports sources and destinations alike.
        """
        r = self.table.valid(addr)
        if r is not None:
            self._refresh(r, now + self.p.active_route_timeout)
            nh = self.table.valid(r.next_hop)
            if nh is not None:
                self._refresh(nh, now + self.p.active_route_timeout)
        return self._finish(now, [])

    def on_link_lost(self, now: float, neighbor: str) -> list[Action]:
        """The link to `neighbor` broke (detected outside the core, e.g. by the driver)."""
        out: list[Action] = []
        self.neighbors.forget(neighbor)
        self._link_break(now, neighbor, out)
        return self._finish(now, out)

    def on_timer(self, now: float) -> list[Action]:
        out: list[Action] = []
        if self.reboot_until is not None and now >= self.reboot_until:
            self.reboot_until = None
        # RFC 6.10 / 6.11 (i): silent monitored neighbours are lost links.
        for n in self.neighbors.lost(now, self.p.delete_period):
            self._link_break(now, n, out)
        self._expire_routes(now, out)
        self.rreq_cache.purge(now)
        self._expire_acks(now)
        if len(self.bidirectional) > self.p.neighbor_limit:
            old = now - self.p.delete_period
            self.bidirectional = {a: t for a, t in self.bidirectional.items() if t >= old}
        for d in list(self.discoveries.values()):
            if d.deadline <= now:
                self._discovery_timeout(now, d, out)
        if now >= self.next_hello:
            self._maybe_hello(now, out)
        return self._finish(now, out)

    def next_deadline(self) -> float:
        t = self.next_hello
        neighbors = self.neighbors.next_deadline(self.p.delete_period)
        for c in (self.table.next_deadline(), neighbors, self.reboot_until):
            if c is not None and c < t:
                t = c
        for d in self.discoveries.values():
            if d.deadline < t:
                t = d.deadline
        if self.pending_acks:
            t = min(t, *self.pending_acks.values())
        return t

    # == values from peers ================================================================
    def _peer_lifetime(self, lifetime_ms: int) -> float:
        """A RREP's Lifetime, at most MAX_LIFETIME_FACTOR times our MY_ROUTE_TIMEOUT.

        Decision: the RFC bounds no Lifetime, but no honest node gives more than its own
        MY_ROUTE_TIMEOUT plus what data refreshes added; 2**32-1 ms would keep a route for
        49 days whatever happened to the path."""
        limit = MAX_LIFETIME_FACTOR * self.p.my_route_timeout
        t = self.p.from_ms(lifetime_ms)
        if t > limit:
            self.dropped["lifetime_clamped"] += 1
            return limit
        return t

    def _peer_hello_interval_ms(self, interval_ms: int) -> float:
        """A neighbour's Hello Interval (RFC 9.1), within [ours / 4, ours * 16].

        Decision: 0 would declare the link lost at once, 2**32-1 would keep a silent
        neighbour for 99 days; a robot team runs one configuration, so a value far from
        ours is an error or an attack."""
        own = self.p.hello_interval_ms
        clamped = min(max(interval_ms, own / 4), own * 16)
        if clamped != interval_ms:
            self.dropped["hello_interval_clamped"] += 1
        return clamped

    # == RFC 6.5 RREQ =====================================================================
    def _rreq(self, now: float, src: str, ttl: int, m: Rreq, out: list[Action]) -> None:
        # RFC 6.8: "...a node ignores all RREQs received from any node in its blacklist
        # set."
        if self.neighbors.blacklisted(src, now):
            return
        # RFC 6.5: "When a node receives a RREQ, it first creates or updates a route to
        # the previous hop without a valid sequence number."
        self._touch_prev_hop(now, src)
        if m.orig == self.addr:
            return
        # RFC 6.5: "...checks to determine whether it has received a RREQ with the same
        # Originator IP Address and RREQ ID within at least the last PATH_DISCOVERY_TIME.
        # If such a RREQ has been received, the node silently discards the newly received
        # RREQ."
        if self.rreq_cache.seen(m.orig, m.rreq_id, now):
            return
        self.rreq_cache.add(m.orig, m.rreq_id, now + self.p.path_discovery_time, now)
        # RFC 6.5: "...first increments the hop count value in the RREQ by one..."
        hops = m.hop_count + 1
        rev = self._update_reverse_route(now, src, m, hops)
        if self.reboot_until is not None:
            # RFC 6.13: it "SHOULD create route entries as appropriate ... but MUST NOT
            # forward any control packets" (and sends no RREP) while it waits.
            return
        if m.dest == self.addr:
            self._reply_as_destination(now, m, rev, out)
            return
        # RFC 6.6 (ii): "it has an active route to the destination, the destination
        # sequence number in the node's existing route table entry for the destination is
        # valid and greater than or equal to the Destination Sequence Number of the RREQ
        # ... and the 'destination only' ('D') flag is NOT set."
        # Decision: with the U flag the RREQ's number means nothing, any valid one will do.
        # Decision: never answer with a route whose next hop is the node that asked (it
        # would point the requester back through itself); forward the RREQ instead.
        fwd = self.table.valid(m.dest)
        if (
            fwd is not None
            and fwd.valid_seq
            and not m.dest_only
            and (m.unknown_seq or seqnum.at_least(fwd.seq, m.dest_seq))
            and fwd.next_hop != src
        ):
            self._reply_as_intermediate(now, m, rev, fwd, out)
            return
        # RFC 6.5: forward only if the IP TTL allows; "the Destination Sequence number for
        # the requested destination is set to the maximum of the corresponding value
        # received in the RREQ message, and the destination sequence value currently
        # maintained by the node ... the forwarding node MUST NOT modify its maintained
        # value".
        if ttl <= 1:
            return
        # Not in RFC 3561 (it limits only originated RREQs): a flood guard. Legitimate
        # load is at most RREQ_RATELIMIT per originator, each RREQ forwarded once.
        if not self._fwd_limit.allow(now):
            self.dropped["rreq_forward_ratelimit"] += 1
            return
        known = self.table.get(m.dest)
        dest_seq, unknown = m.dest_seq, m.unknown_seq
        if known is not None and known.valid_seq:
            dest_seq = known.seq if unknown else seqnum.newest(m.dest_seq, known.seq)
            unknown = False
        # (Positional: keyword arguments cost a NamedTuple twice as much, on every hop.)
        fwd_msg = Rreq(
            m.rreq_id, m.dest, dest_seq, m.orig, m.orig_seq, hops,
            m.join, m.repair, m.gratuitous, m.dest_only, unknown,
        )  # fmt: skip
        self._broadcast(now, fwd_msg, ttl - 1, out)

    def _update_reverse_route(self, now: float, src: str, m: Rreq, hops: int) -> Route:
        # RFC 6.5: "...the Originator Sequence Number from the RREQ is compared to the
        # corresponding destination sequence number in the route table entry and copied
        # if greater than the existing value there; the valid sequence number field is set
        # to true; the next hop in the routing table becomes the node from which the RREQ
        # was received ...; the hop count is copied from the Hop Count in the RREQ".
        # "MinimalLifetime = (current time + 2*NET_TRAVERSAL_TIME -
        # 2*HopCount*NODE_TRAVERSAL_TIME)" and the lifetime is the maximum of the
        # existing one and MinimalLifetime.
        # Decision: the next hop only changes when the RREQ is fresher, equally fresh and
        # shorter, or the entry was unusable (RFC 6.2's update rule), so a late copy
        # of a RREQ over a longer path cannot replace a good reverse route.
        minimal = now + 2 * self.p.net_traversal_time - 2 * hops * self.p.node_traversal_time
        r = self.table.get(m.orig)
        if r is None:
            return self.table.add(Route(m.orig, src, hops, m.orig_seq, True, minimal))
        better = (
            not r.valid
            or not r.valid_seq
            or seqnum.newer(m.orig_seq, r.seq)
            or (m.orig_seq == r.seq and hops < r.hops)
        )
        if not r.valid_seq or seqnum.newer(m.orig_seq, r.seq):
            r.seq = m.orig_seq
        r.valid_seq = True
        if better:
            r.next_hop, r.hops = src, hops
        r.lifetime = max(r.lifetime, minimal) if r.valid else minimal
        r.valid = True
        return r

    # == RFC 6.6 generating a RREP ========================================================
    def _reply_as_destination(self, now: float, m: Rreq, rev: Route, out: list) -> None:
        # RFC 6.1: "Immediately before a destination node originates a RREP in response
        # to a RREQ, it MUST update its own sequence number to the maximum of its current
        # sequence number and the destination sequence number in the RREQ packet."
        # Decision: 6.6.1 says instead "increment ... if the sequence number in the RREQ
        # packet is equal to that incremented value"; the 6.1 maximum covers that case
        # and never answers with a number older than the one asked for. With the U flag
        # set the RREQ's number is meaningless and is ignored.
        if not m.unknown_seq:
            self.seq = seqnum.newest(self.seq, m.dest_seq)
        # RFC 6.6.1: "...enters the value zero in the Hop Count field of the RREP. The
        # destination node copies the value MY_ROUTE_TIMEOUT into the Lifetime field".
        rrep = Rrep(
            dest=self.addr,
            dest_seq=self.seq,
            orig=m.orig,
            lifetime_ms=self.p.ms(self.p.my_route_timeout),
            hop_count=0,
        )
        rev.active_until = max(rev.active_until, rev.lifetime)
        self._send_rrep(now, rrep, rev.next_hop, out)

    def _reply_as_intermediate(
        self, now: float, m: Rreq, rev: Route, fwd: Route, out: list
    ) -> None:
        # RFC 6.6.2: "...copies its known sequence number for the destination into the
        # Destination Sequence Number field ... places its distance in hops from the
        # destination ... in the Hop Count field, and updates the Lifetime field of the
        # RREP by subtracting the current time from the expiration time in its route table
        # entry." "...placing the last hop node ... into the precursor list for the
        # forward route entry ... [and] the next hop towards the destination in the
        # precursor list for the reverse route entry."
        fwd.precursors.add(rev.next_hop)
        rev.precursors.add(fwd.next_hop)
        fwd.active_until = max(fwd.active_until, fwd.lifetime)
        rev.active_until = max(rev.active_until, rev.lifetime)
        rrep = Rrep(
            dest=m.dest,
            dest_seq=fwd.seq,
            orig=m.orig,
            lifetime_ms=self.p.ms(fwd.lifetime - now),
            hop_count=fwd.hops,
        )
        self._send_rrep(now, rrep, rev.next_hop, out)
        # RFC 6.6.3: "If the RREQ has the 'G' flag set, and the intermediate node returns
        # a RREP to the originating node, it MUST also unicast a gratuitous RREP to the
        # destination node." (Destination = RREQ originator, its sequence number from the
        # RREQ, Originator = RREQ destination, hop count and lifetime of the reverse route.)
        if m.gratuitous:
            grat = Rrep(
                dest=m.orig,
                dest_seq=m.orig_seq,
                orig=m.dest,
                lifetime_ms=self.p.ms(rev.lifetime - now),
                hop_count=rev.hops,
            )
            self._send_rrep(now, grat, fwd.next_hop, out)

    def _send_rrep(self, now: float, rrep: Rrep, next_hop: str, out: list) -> None:
        # RFC 6.7/6.8: "If a node forwards a RREP over a link that is likely to have errors
        # or be unidirectional, the node SHOULD set the 'A' flag". Decision: a link is
        # "likely unidirectional" until the neighbour has shown it hears us (it sent us a
        # RREP-ACK or a RREP, i.e. picked us as its next hop) within DELETE_PERIOD.
        proof = self.bidirectional.get(next_hop)
        if proof is None or proof < now - self.p.delete_period:
            rrep = rrep._replace(ack_required=True)
            self.pending_acks[next_hop] = now + self.p.next_hop_wait
        out.append(Unicast(rrep, next_hop))

    # == RFC 6.7 receiving a RREP =========================================================
    def _rrep(self, now: float, src: str, m: Rrep, out: list[Action]) -> None:
        # RFC 6.8: "...the node receiving the RREP with the 'A' bit set... sends a
        # RREP-ACK" back to the sender. (`_finish` puts it after everything else.)
        self._rrep_body(now, src, m, out)
        if m.ack_required:
            out.append(Unicast(RrepAck(), src))

    def _rrep_body(self, now: float, src: str, m: Rrep, out: list[Action]) -> None:
        self.bidirectional[src] = now
        # RFC 6.7: "...searches ... for a route to the previous hop. If needed, a route is
        # created for the previous hop, but without a valid sequence number".
        self._touch_prev_hop(now, src)
        if m.dest == self.addr:
            return
        # RFC 6.7: "...increments the hop count value in the RREP by one".
        hops = m.hop_count + 1
        r = self.table.get(m.dest)
        # RFC 6.7: the existing entry is updated only if "(i) the sequence number in the
        # routing table is marked as invalid ..., (ii) the Destination Sequence Number in
        # the RREP is greater than the node's copy ..., (iii) the sequence numbers are
        # the same, but the route is marked as inactive, or (iv) the sequence numbers are
        # the same, and the New Hop Count is smaller than the hop count in route table".
        if r is None:
            r = self.table.add(Route(m.dest, src, hops, m.dest_seq, True, 0.0))
        elif not (
            not r.valid_seq
            or seqnum.newer(m.dest_seq, r.seq)
            or (m.dest_seq == r.seq and not r.valid)
            or (m.dest_seq == r.seq and hops < r.hops)
        ):
            return
        # RFC 6.7: "the route is marked as active, the destination sequence number is
        # marked as valid, the next hop ... is assigned to be the node from which the RREP
        # is received, ... the hop count is set to the value of the New Hop Count, the
        # expiry time is set to the current time plus the value of the Lifetime in the
        # RREP message, and the destination sequence number is the Destination Sequence
        # Number in the RREP message."
        r.valid, r.valid_seq, r.next_hop, r.hops = True, True, src, hops
        r.lifetime = now + self._peer_lifetime(m.lifetime_ms)
        r.seq = m.dest_seq
        r.active_until = r.lifetime
        if m.orig == self.addr or self.reboot_until is not None:
            return
        # RFC 6.7: "If the current node is not the node indicated by the Originator IP
        # Address in the RREP message AND a forward route has been created or updated...,
        # the node consults its route table entry for the originating node to determine
        # the next hop for the RREP packet, and then forwards the RREP towards the
        # originator".
        rev = self.table.valid(m.orig)
        if rev is None:
            log.debug("%s: RREP for %s has no route back to %s", self.addr, m.dest, m.orig)
            return
        # RFC 6.7: "When any node transmits a RREP, the precursor list for the
        # corresponding destination node is updated by adding to it the next hop node to
        # which the RREP is forwarded. Also, at each node the (reverse) route used to
        # forward a RREP has its lifetime changed to be the maximum of (existing-lifetime,
        # (current time + ACTIVE_ROUTE_TIMEOUT)). Finally, the precursor list for the next
        # hop towards the destination is updated to contain the next hop towards the
        # source." Decision: as ns-3 does, the symmetric entries are filled too (the
        # reverse route and the next hop towards the source get the next hop towards the
        # destination), so a break on either side reaches both ends by RERR.
        r.precursors.add(rev.next_hop)
        rev.precursors.add(r.next_hop)
        self._refresh(rev, now + self.p.active_route_timeout)
        nh_dst = self.table.valid(r.next_hop)
        if nh_dst is not None:
            nh_dst.precursors.add(rev.next_hop)
        nh_src = self.table.valid(rev.next_hop)
        if nh_src is not None:
            nh_src.precursors.add(r.next_hop)
        # Positional, as the forwarded RREQ: dest, dest_seq, orig, lifetime_ms, hop_count,
        # repair, ack_required (decided by _send_rrep), prefix_size.
        fwd = Rrep(m.dest, m.dest_seq, m.orig, m.lifetime_ms, hops, False, False, m.prefix_size)
        self._send_rrep(now, fwd, rev.next_hop, out)

    def _rrep_ack(self, now: float, src: str) -> None:
        # Decision: a RREP-ACK that arrives after NEXT_HOP_WAIT (a busy neighbour, not a
        # unidirectional link) still proves the link works both ways: it lifts the
        # blacklisting its absence caused.
        self.pending_acks.pop(src, None)
        self.bidirectional[src] = now
        self.neighbors.unblacklist(src)

    def _expire_acks(self, now: float) -> None:
        # RFC 6.8: "...if the RREP-ACK is not received within NEXT_HOP_WAIT, the node
        # adds the next hop to a blacklist for BLACKLIST_TIMEOUT."
        for nbr, deadline in list(self.pending_acks.items()):
            if deadline <= now:
                del self.pending_acks[nbr]
                log.info("%s: no RREP-ACK from %s, blacklisted", self.addr, nbr)
                self.neighbors.blacklist(nbr, now + self.p.blacklist_timeout)

    # == RFC 6.9 HELLO ====================================================================
    def _hello(self, now: float, src: str, m: Rrep) -> None:
        # RFC 6.9: "Whenever a node receives a Hello message from a neighbor, the node
        # SHOULD make sure that it has an active route to the neighbor, and create one if
        # necessary. If a route already exists, then the Lifetime for the route should be
        # increased, if necessary, to be at least ALLOWED_HELLO_LOSS * HELLO_INTERVAL. The
        # route to the neighbor, if it exists, MUST subsequently contain the latest
        # Destination Sequence Number from the Hello message."
        # The neighbour's own HELLO_INTERVAL comes from its Hello Interval extension.
        interval = self.p.hello_interval
        if m.hello_interval_ms is not None:
            interval = self.p.from_ms(self._peer_hello_interval_ms(m.hello_interval_ms))
        timeout = self.p.allowed_hello_loss * interval
        self.neighbors.hello(src, now, timeout)
        r = self.table.get(src)
        if r is None or not r.valid:
            self.table.add(Route(src, src, 1, m.dest_seq, True, now + timeout))
            return
        r.next_hop, r.hops = src, 1
        r.seq, r.valid_seq = m.dest_seq, True
        r.lifetime = max(r.lifetime, now + timeout)

    def _maybe_hello(self, now: float, out: list[Action]) -> None:
        # RFC 6.9: "...a node SHOULD only use hello messages if it is part of an active
        # route." "Every HELLO_INTERVAL milliseconds, the node checks whether it has sent
        # a broadcast (e.g., a RREQ ...) within the last HELLO_INTERVAL. If it has not, it
        # MAY broadcast a RREP with TTL = 1, called a Hello message". Decision: the next
        # check is HELLO_INTERVAL after the last broadcast, so a neighbour never waits
        # more than HELLO_INTERVAL between two broadcasts from us.
        active = any(r.valid and r.active_until > now for r in self.table)
        if active and self.reboot_until is None:
            hello = Rrep(
                dest=self.addr,
                dest_seq=self.seq,
                orig=self.addr,
                lifetime_ms=self.p.ms(self.p.neighbor_timeout),
                hop_count=0,
                hello_interval_ms=int(self.p.hello_interval_ms),
            )
            self._broadcast(now, hello, LOCAL_TTL, out)
        else:
            self.next_hello = now + self.p.hello_interval

    # == RFC 6.3 / 6.4 route discovery ====================================================
    def _buffer(self, dst: str, packet: bytes, out: list[Action]) -> None:
        """Queue a packet for `dst` (RFC 6.3); a full queue drops its oldest."""
        overflow = self.queue.push(dst, packet)
        if overflow is not None:
            out.append(DropPackets(dst, (overflow,)))

    def _originate(self, now: float, dst: str, packet: bytes, out: list[Action]) -> None:
        self._buffer(dst, packet, out)
        self._keep_invalid_entry(now, dst)
        if dst in self.discoveries:
            return
        # RFC 6.4: "...the originating node SHOULD use the expanding ring search technique
        # ... initially uses TTL = TTL_START"; "...the TTL ... is initially set to the Hop
        # Count plus TTL_INCREMENT" when an (invalid) entry knows the old distance.
        old = self.table.get(dst)
        ttl = self.p.ttl_start if old is None else old.hops + self.p.ttl_increment
        if ttl > self.p.ttl_threshold:
            ttl = self.p.net_diameter
        d = self.discoveries[dst] = _Discovery(dst, ttl, now)
        self._send_rreq(now, d, out)

    def _keep_invalid_entry(self, now: float, dst: str) -> None:
        """Data for a destination whose entry is invalid keeps the entry (and so its
        sequence number) for another DELETE_PERIOD.

        RFC 6.3: "The Destination Sequence Number field in the RREQ message is the last
        known destination sequence number for this destination"; 6.11: the invalid entry's
        "Lifetime field is updated to current time plus DELETE_PERIOD. Before this time,
        the entry SHOULD NOT be deleted." A discovery with its retries outlasts
        DELETE_PERIOD (ring, then 2.8 + 5.6 + 11.2 s with the defaults): without this the
        entry went while the discovery ran, and its last RREQs asked with U set."""
        r = self.table.get(dst)
        if r is not None and not r.valid:
            r.lifetime = max(r.lifetime, now + self.p.delete_period)

    def _send_rreq(self, now: float, d: _Discovery, out: list[Action]) -> None:
        # RFC 6.13: "...after rebooting, a node MUST wait for DELETE_PERIOD before
        # transmitting any route discovery messages." The data waits in the queue.
        if self.reboot_until is not None and now < self.reboot_until:
            d.deferred, d.deadline = True, self.reboot_until
            return
        # RFC 6.3: "A node SHOULD NOT originate more than RREQ_RATELIMIT RREQ messages per
        # second." Decision: a RREQ over the limit is delayed, not dropped.
        if not self._rreq_limit.allow(now):
            d.deferred, d.deadline = True, self._rreq_limit.next_free(now)
            return
        d.deferred = False
        self._keep_invalid_entry(now, d.dest)
        # RFC 6.1: "Immediately before a node originates a route discovery, it MUST
        # increment its own sequence number." RFC 6.3: "...the RREQ ID field is
        # incremented by one from the last RREQ ID used by the current node."
        self.seq = seqnum.increment(self.seq)
        self.rreq_id = seqnum.increment(self.rreq_id)
        # RFC 6.3: "The Destination Sequence Number field in the RREQ message is the last
        # known destination sequence number for this destination ...  If no sequence
        # number is known, the unknown sequence number flag MUST be set."
        old = self.table.get(d.dest)
        known = old is not None and old.valid_seq
        rreq = Rreq(
            rreq_id=self.rreq_id,
            dest=d.dest,
            dest_seq=old.seq if old is not None and known else 0,
            orig=self.addr,
            orig_seq=self.seq,
            hop_count=0,
            gratuitous=self.p.gratuitous_rrep,
            dest_only=self.p.dest_only,
            unknown_seq=not known,
        )
        # RFC 6.3: "Before broadcasting the RREQ, the originating node buffers the RREQ ID
        # and the Originator IP address (its own address) of the RREQ for
        # PATH_DISCOVERY_TIME."
        self.rreq_cache.add(self.addr, self.rreq_id, now + self.p.path_discovery_time, now)
        self._broadcast(now, rreq, d.ttl, out)
        d.round_started = now
        # RFC 6.4: "The timeout for receiving a RREP is RING_TRAVERSAL_TIME" during the
        # ring search; "Once TTL = NET_DIAMETER, the timeout for waiting for the RREP is
        # set to NET_TRAVERSAL_TIME". RFC 6.3: binary exponential backoff, "...the wait
        # time for the RREP ... is 2^k * NET_TRAVERSAL_TIME" for retry k.
        if d.ttl >= self.p.net_diameter:
            d.deadline = now + (2**d.retries) * self.p.net_traversal_time
        else:
            d.deadline = now + self.p.ring_traversal_time(d.ttl)

    def _discovery_timeout(self, now: float, d: _Discovery, out: list[Action]) -> None:
        if d.deferred:
            self._send_rreq(now, d, out)
            return
        if d.repair_hops is not None:
            self._repair_failed(now, d, out)
            return
        if d.ttl < self.p.net_diameter:
            # RFC 6.4: "...the TTL_VALUE is incremented by TTL_INCREMENT ... until TTL set
            # in the RREQ reaches TTL_THRESHOLD, beyond which a TTL = NET_DIAMETER is used
            # for each attempt."
            d.ttl += self.p.ttl_increment
            if d.ttl > self.p.ttl_threshold:
                d.ttl = self.p.net_diameter
            self._send_rreq(now, d, out)
            return
        # RFC 6.3: "...the node MAY try again to discover a route by broadcasting another
        # RREQ, up to a maximum of RREQ_RETRIES times at the maximum TTL value."
        if d.retries < self.p.rreq_retries:
            d.retries += 1
            self._send_rreq(now, d, out)
            return
        # RFC 6.3: "...all data packets destined for the corresponding destination SHOULD
        # be dropped from the buffer and a Destination Unreachable message SHOULD be
        # delivered to the application."
        del self.discoveries[d.dest]
        out.append(DropPackets(d.dest, tuple(self.queue.pop_all(d.dest))))
        out.append(DiscoveryDone(d.dest, False, now - d.started, now - d.round_started))

    def _complete_discoveries(self, now: float, out: list[Action]) -> None:
        for dest, d in list(self.discoveries.items()):
            r = self.table.valid(dest)
            if r is not None:
                del self.discoveries[dest]
                out.append(ReleasePackets(dest, tuple(self.queue.pop_all(dest))))
                repair = d.repair_hops is not None
                out.append(
                    DiscoveryDone(dest, True, now - d.started, now - d.round_started, repair)
                )
                # RFC 6.12: "If the hop count of the newly determined route to the
                # destination is greater than the hop count of the previously known route
                # the node SHOULD issue a RERR message for the destination, with the 'N'
                # bit set."
                if d.repair_hops is not None and r.hops > d.repair_hops and r.precursors:
                    self._send_rerr(now, [r], out, fallback=False, no_delete=True)

    # == RFC 6.12 local repair ============================================================
    def _start_repair(self, now: float, r: Route, out: list[Action]) -> None:
        # RFC 6.12: "To repair the link break, the node increments the sequence number for
        # the destination and then broadcasts a RREQ for that destination. The TTL of the
        # RREQ should initially be set to: max(MIN_REPAIR_TTL, 0.5 * #hops) +
        # LOCAL_ADD_TTL, where #hops is the number of hops to the sender (originator) of
        # the currently undeliverable packet." MIN_REPAIR_TTL "should be the last known hop
        # count to the destination". Decision: the break is found by HELLO loss, with no
        # undeliverable packet in hand; #hops is the longest route among the precursors'
        # (the farthest upstream user we know of is at least one hop further away).
        upstream = [self.table.valid(p) for p in r.precursors]
        far = max((u.hops for u in upstream if u is not None), default=1) + 1
        ttl = min(max(r.hops, far // 2) + self.p.local_add_ttl, self.p.net_diameter)
        d = self.discoveries[r.dest] = _Discovery(r.dest, ttl, now, repair_hops=r.hops)
        log.info("%s: repairing the route to %s locally (TTL %d)", self.addr, r.dest, ttl)
        self._send_rreq(now, d, out)

    def _repair_failed(self, now: float, d: _Discovery, out: list[Action]) -> None:
        # RFC 6.12: "If, at the end of the discovery period, the repairing node has not
        # received a RREP (or other control message creating or updating the route) for
        # that destination, it proceeds in as described in Section 6.11 by transmitting a
        # RERR message for that destination." Decision: the discovery period of a repair
        # is one RING_TRAVERSAL_TIME of its TTL (RFC 6.4's wait for a RREQ of that TTL).
        del self.discoveries[d.dest]
        out.append(DropPackets(d.dest, tuple(self.queue.pop_all(d.dest))))
        out.append(DiscoveryDone(d.dest, False, now - d.started, now - d.round_started, True))
        r = self.table.get(d.dest)
        if r is not None and r.precursors:
            self._send_rerr(now, [r], out, fallback=False)

    # == RFC 6.11 RERR ====================================================================
    def _link_break(self, now: float, nbr: str, out: list[Action]) -> None:
        # RFC 6.11 (i): "...the node first makes a list of unreachable destinations
        # consisting of the unreachable neighbor and any additional destinations ... in
        # the local routing table that use the unreachable neighbor as the next hop."
        # "1. The destination sequence number of this routing entry, if it exists and is
        # valid, is incremented for cases (i) and (ii)".
        broken = self.table.via(nbr)
        for r in broken:
            if r.valid_seq:
                r.seq = seqnum.increment(r.seq)
            self._invalidate(r, now)
        if broken:
            log.info("%s: link to %s lost, %d routes invalid", self.addr, nbr, len(broken))
        report = []
        for r in broken:
            # RFC 6.12: "When a link break in an active route occurs, the node upstream of
            # that break MAY choose to repair the link locally if the destination was no
            # farther than MAX_REPAIR_TTL hops away." Decision: routes others use through
            # us (with precursors) and that carried data lately are repaired; an idle
            # route is not (its neighbour fell silent because nothing used it, and a
            # repair would keep it alive for nobody); for our own traffic the next packet
            # starts an ordinary discovery.
            if (
                self.p.local_repair
                and r.precursors
                and r.active_until > now
                and r.hops <= self.p.max_repair_ttl
                and r.dest not in self.discoveries
                and self.reboot_until is None
            ):
                self._start_repair(now, r, out)
            elif r.precursors:
                report.append(r)
        self._send_rerr(now, report, out, fallback=False)

    def _forward_without_route(self, now: float, dst: str, packet: bytes, out: list) -> None:
        # RFC 6.11 (ii): "...if it gets a data packet destined to a node for which it does
        # not have an active route and is not repairing (if using local repair)". RFC
        # 6.12: "During local repair data packets SHOULD be buffered."
        d = self.discoveries.get(dst)
        if d is not None and d.repair_hops is not None:
            self._buffer(dst, packet, out)
            return
        # RFC 6.13: a rebooted node "SHOULD broadcast a RERR ... and MUST reset the waiting
        # timer to expire after current time plus DELETE_PERIOD."
        if self.reboot_until is not None:
            self.reboot_until = now + self.p.delete_period
        r = self.table.get(dst)
        if r is None:
            # Decision: with no entry the RERR carries sequence number 0, which a receiver
            # never copies over a number it holds (`_rerr`: sequence numbers never go back).
            r = self.table.add(Route(dst, dst, 0, 0, False, now + self.p.delete_period, False))
        elif r.valid_seq:
            # RFC 6.11: "The destination sequence number of this routing entry, if it
            # exists and is valid, is incremented for cases (i) and (ii)".
            r.seq = seqnum.increment(r.seq)
            r.lifetime = max(r.lifetime, now + self.p.delete_period)
        # Decision: with no precursor known for the destination (the packet's previous hop
        # is hidden from us), the RERR is broadcast with TTL 1; neighbours without a route
        # through us to `dst` ignore it (RFC 6.11 case iii only acts on such routes).
        self._send_rerr(now, [r], out, fallback=True)

    def _rerr(self, now: float, src: str, m: Rerr, out: list[Action]) -> None:
        # RFC 6.11: "...the list should consist of those destinations in the RERR for
        # which there exists a corresponding entry in the local routing table that has
        # the transmitter of the received RERR as the next hop."
        affected = []
        for dest, seq in m.unreachable:
            r = self.table.valid(dest)
            if r is None or r.next_hop != src:
                continue
            affected.append(r)
            if m.no_delete:
                continue
            # RFC 6.11: the sequence number is "copied from the incoming RERR in case
            # (iii)"; RFC 6.1: a node changes a destination's sequence number only on "new
            # information about the sequence number" ("information older than what is
            # held is discarded"). Decision: the route is invalidated whatever the number
            # (its next hop says it cannot deliver: keeping it would black-hole data), and
            # the number only moves forward.
            if not r.valid_seq or seqnum.newer(seq, r.seq):
                r.seq = seq
            r.valid_seq = True
            self._invalidate(r, now)
        if self.reboot_until is not None:
            return
        # RFC 6.11: "The RERR should contain those destinations that are part of the
        # created list of unreachable destinations and have a non-empty precursor list."
        # RFC 6.12, for a RERR with N: "A node that receives a RERR message with the 'N'
        # flag set MUST NOT delete the route to that destination. The only action taken
        # should be the retransmission of the message, if the RERR arrived from the next
        # hop along that route, and if there are one or more precursor nodes along that
        # route." An originator (no precursors) keeps its route: it MAY re-discover; we
        # do not. So both pass on the same list, with the RERR's own N flag.
        routes = [r for r in affected if r.precursors]
        self._send_rerr(now, routes, out, fallback=False, no_delete=m.no_delete)

    def _send_rerr(
        self,
        now: float,
        routes: list[Route],
        out: list,
        fallback: bool,
        no_delete: bool = False,
    ) -> None:
        if not routes:
            return
        # RFC 6.11: "A node should not generate more than RERR_RATELIMIT RERR messages
        # per second." Decision: RERRs over the limit are dropped (and counted).
        if not self._rerr_limit.allow(now):
            self.dropped["rerr_ratelimit"] += 1
            return
        # RFC 6.11: "The neighboring node(s) that should receive the RERR are all those
        # that belong to a precursor list of at least one of the unreachable
        # destination(s)... In case there is only one unique neighbor that needs to
        # receive the RERR, the RERR SHOULD be unicast toward that neighbor. Otherwise
        # the RERR is typically sent to the local broadcast address (Destination IP ==
        # 0xFFFFFFFF, TTL == 1)".
        targets = set().union(*(r.precursors for r in routes))
        for i in range(0, len(routes), 255):
            pairs = tuple((r.dest, r.seq) for r in routes[i : i + 255])
            rerr = Rerr(unreachable=pairs, no_delete=no_delete)
            if len(targets) == 1:
                out.append(Unicast(rerr, next(iter(targets)), LOCAL_TTL))
            elif targets or fallback:
                self._broadcast(now, rerr, LOCAL_TTL, out)

    # == helpers ==========================================================================
    def _touch_prev_hop(self, now: float, src: str) -> None:
        """A route to a neighbour we just heard, without a valid sequence number."""
        r = self.table.get(src)
        until = now + self.p.active_route_timeout
        if r is None:
            self.table.add(Route(src, src, 1, 0, False, until))
        elif not r.valid or r.next_hop != src:
            r.valid, r.next_hop, r.hops, r.lifetime = True, src, 1, until
        else:
            r.lifetime = max(r.lifetime, until)

    def _refresh(self, r: Route, until: float) -> None:
        r.lifetime = max(r.lifetime, until)
        r.active_until = max(r.active_until, until)

    def _invalidate(self, r: Route, now: float) -> None:
        # RFC 6.11: "2. The entry is invalidated by marking the route entry as invalid
        # 3. The Lifetime field is updated to current time plus DELETE_PERIOD."
        r.valid = False
        r.lifetime = now + self.p.delete_period

    def _expire_routes(self, now: float, out: list[Action]) -> None:
        # RFC 6.11 / section 2: an active route whose lifetime passed becomes invalid;
        # an invalid one is deleted after DELETE_PERIOD.
        for r in self.table:
            if r.lifetime <= now:
                if r.valid:
                    self._invalidate(r, now)
                else:
                    self.table.remove(r.dest)

    def _broadcast(self, now: float, msg: Message, ttl: int, out: list[Action]) -> None:
        out.append(Broadcast(msg, ttl))
        self.next_hello = now + self.p.hello_interval

    def _finish(self, now: float, out: list[Action]) -> list[Action]:
        if self.discoveries:
            self._complete_discoveries(now, out)
        if len(self.table) > self.p.route_table_limit:
            gone = self.table.shrink(self.p.route_table_limit, now, keep=self.discoveries)
            self.dropped["route_evicted"] += gone
        routes = self._sync_routes()
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

    def _sync_routes(self) -> list[Action]:
        """Install/delete actions that bring the kernel in line with the valid entries.
        (One pass over the table: this runs after every event.)"""
        acts: list[Action] = []
        installed = self._installed
        n_valid = 0
        for r in self.table.entries():
            if r.valid:
                n_valid += 1
                key = r.kernel_key()
                if installed.get(r.dest) != key:
                    installed[r.dest] = key
                    acts.append(InstallRoute(r.dest, *key))
            elif r.dest in installed:
                del installed[r.dest]
                acts.append(DeleteRoute(r.dest))
        if len(installed) > n_valid:  # installed entries that left the table
            for dest in [d for d in installed if self.table.valid(d) is None]:
                del installed[dest]
                acts.append(DeleteRoute(dest))
        return acts

    # == inspection =======================================================================
    def routes(self) -> dict[str, tuple[str, int]]:
        """Valid routes: destination -> (next hop, hops)."""
        return {r.dest: r.kernel_key() for r in self.table if r.valid}
