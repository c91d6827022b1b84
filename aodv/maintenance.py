"""Route maintenance (RFC 3561 6.11-6.12): route errors, local repair and route expiry.

Theory of operation
-------------------
`RouteMaintenance` is the part of the protocol core (aodv.core) that takes routes down and
tells the nodes that used them. The three cases of 6.11 come in as: a link break
(`link_break`, from a lost neighbour, 6.10, or the driver), data to forward with no route
(`forward_without_route`) and a RERR from a next hop (`on_rerr`). Each invalidates the
routes concerned and sends one RERR (`send_rerr`: unicast to a lone precursor, else the
limited broadcast, at most RERR_RATELIMIT a second). A broken route others use through us
may instead be repaired locally (6.12): a discovery (aodv.discovery) for its destination
whose outcome comes back here (`repaired`, `repair_failed`). `expire_routes` runs on the
core's timer: routes past their lifetime become invalid, invalid ones past DELETE_PERIOD
leave the table.

State is the shared aodv.state.NodeState; no clock, no IO: methods take `now`.
"""

from __future__ import annotations

from aodv import seqnum
from aodv.actions import LOCAL_TTL, Action, DiscoveryDone, DropPackets, Unicast
from aodv.discovery import RouteDiscovery
from aodv.packet import Rerr
from aodv.routes import Route
from aodv.state import Discovery, NodeState, RateLimit, log


class RouteMaintenance:
    def __init__(self, state: NodeState, discovery: RouteDiscovery) -> None:
        self.s = state
        self.discovery = discovery
        self._rerr_limit = RateLimit(state.p.rerr_ratelimit, state.p.rate_window)

    # == RFC 6.11 route errors ============================================================
    def link_break(self, now: float, nbr: str, out: list[Action]) -> None:
        s = self.s
        # RFC 6.11 (i): "...the node first makes a list of unreachable destinations
        # consisting of the unreachable neighbor and any additional destinations ... in
        # the local routing table that use the unreachable neighbor as the next hop."
        # "1. The destination sequence number of this routing entry, if it exists and is
        # valid, is incremented for cases (i) and (ii)".
        broken = s.table.via(nbr)
        for r in broken:
            if r.valid_seq:
                r.seq = seqnum.increment(r.seq)
            s.invalidate(r, now)
        if broken:
            log.info("%s: link to %s lost, %d routes invalid", s.addr, nbr, len(broken))
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
                s.p.local_repair
                and r.precursors
                and r.active_until > now
                and r.hops <= s.p.max_repair_ttl
                and r.dest not in s.discoveries
                and s.reboot_until is None
            ):
                self._start_repair(now, r, out)
            elif r.precursors:
                report.append(r)
        self.send_rerr(now, report, out, fallback=False)

    def forward_without_route(self, now: float, dst: str, packet: bytes, out: list[Action]) -> None:
        s = self.s
        # RFC 6.11 (ii): "...if it gets a data packet destined to a node for which it does
        # not have an active route and is not repairing (if using local repair)". RFC
        # 6.12: "During local repair data packets SHOULD be buffered."
        d = s.discoveries.get(dst)
        if d is not None and d.repair_hops is not None:
            self.discovery.buffer(dst, packet, out)
            return
        # RFC 6.13: a rebooted node "SHOULD broadcast a RERR ... and MUST reset the waiting
        # timer to expire after current time plus DELETE_PERIOD."
        if s.reboot_until is not None:
            s.reboot_until = now + s.p.delete_period
        r = s.table.get(dst)
        if r is None:
            # Decision: with no entry the RERR carries sequence number 0, which a receiver
            # never copies over a number it holds (`on_rerr`: sequence numbers never go
            # back).
            r = s.table.add(Route(dst, dst, 0, 0, False, now + s.p.delete_period, False))
        elif r.valid_seq:
            # RFC 6.11: "The destination sequence number of this routing entry, if it
            # exists and is valid, is incremented for cases (i) and (ii)".
            r.seq = seqnum.increment(r.seq)
            r.lifetime = max(r.lifetime, now + s.p.delete_period)
        # Decision: with no precursor known for the destination (the packet's previous hop
        # is hidden from us), the RERR is broadcast with TTL 1; neighbours without a route
        # through us to `dst` ignore it (RFC 6.11 case iii only acts on such routes).
        self.send_rerr(now, [r], out, fallback=True)

    def on_rerr(self, now: float, src: str, m: Rerr, out: list[Action]) -> None:
        s = self.s
        # RFC 6.11: "...the list should consist of those destinations in the RERR for
        # which there exists a corresponding entry in the local routing table that has
        # the transmitter of the received RERR as the next hop."
        affected = []
        for dest, seq in m.unreachable:
            r = s.table.valid(dest)
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
            s.invalidate(r, now)
        if s.reboot_until is not None:
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
        self.send_rerr(now, routes, out, fallback=False, no_delete=m.no_delete)

    def send_rerr(
        self,
        now: float,
        routes: list[Route],
        out: list[Action],
        fallback: bool,
        no_delete: bool = False,
    ) -> None:
        if not routes:
            return
        # RFC 6.11: "A node should not generate more than RERR_RATELIMIT RERR messages
        # per second." Decision: RERRs over the limit are dropped (and counted).
        if not self._rerr_limit.allow(now):
            self.s.dropped["rerr_ratelimit"] += 1
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
                self.s.broadcast(now, rerr, LOCAL_TTL, out)

    # == RFC 6.12 local repair ============================================================
    def _start_repair(self, now: float, r: Route, out: list[Action]) -> None:
        s, p = self.s, self.s.p
        # RFC 6.12: "To repair the link break, the node increments the sequence number for
        # the destination and then broadcasts a RREQ for that destination. The TTL of the
        # RREQ should initially be set to: max(MIN_REPAIR_TTL, 0.5 * #hops) +
        # LOCAL_ADD_TTL, where #hops is the number of hops to the sender (originator) of
        # the currently undeliverable packet." MIN_REPAIR_TTL "should be the last known hop
        # count to the destination". Decision: the break is found by HELLO loss, with no
        # undeliverable packet in hand; #hops is the longest route among the precursors'
        # (the farthest upstream user we know of is at least one hop further away).
        upstream = [s.table.valid(pr) for pr in r.precursors]
        far = max((u.hops for u in upstream if u is not None), default=1) + 1
        ttl = min(max(r.hops, far // 2) + p.local_add_ttl, p.net_diameter)
        d = s.discoveries[r.dest] = Discovery(r.dest, ttl, now, repair_hops=r.hops)
        log.info("%s: repairing the route to %s locally (TTL %d)", s.addr, r.dest, ttl)
        self.discovery.send_rreq(now, d, out)

    def repaired(self, now: float, d: Discovery, r: Route, out: list[Action]) -> None:
        """A local repair found route `r` (its packets are released already)."""
        # RFC 6.12: "If the hop count of the newly determined route to the destination is
        # greater than the hop count of the previously known route the node SHOULD issue
        # a RERR message for the destination, with the 'N' bit set."
        if d.repair_hops is not None and r.hops > d.repair_hops and r.precursors:
            self.send_rerr(now, [r], out, fallback=False, no_delete=True)

    def repair_failed(self, now: float, d: Discovery, out: list[Action]) -> None:
        s = self.s
        # RFC 6.12: "If, at the end of the discovery period, the repairing node has not
        # received a RREP (or other control message creating or updating the route) for
        # that destination, it proceeds in as described in Section 6.11 by transmitting a
        # RERR message for that destination." Decision: the discovery period of a repair
        # is one RING_TRAVERSAL_TIME of its TTL (RFC 6.4's wait for a RREQ of that TTL).
        del s.discoveries[d.dest]
        out.append(DropPackets(d.dest, tuple(s.queue.pop_all(d.dest))))
        out.append(DiscoveryDone(d.dest, False, now - d.started, now - d.round_started, True))
        r = s.table.get(d.dest)
        if r is not None and r.precursors:
            self.send_rerr(now, [r], out, fallback=False)

    # == route expiry =====================================================================
    def expire_routes(self, now: float) -> None:
        s = self.s
        # RFC 6.11 / section 2: an active route whose lifetime passed becomes invalid;
        # an invalid one is deleted after DELETE_PERIOD.
        for r in s.table:
            if r.lifetime <= now:
                if r.valid:
                    s.invalidate(r, now)
                else:
                    s.table.remove(r.dest)
