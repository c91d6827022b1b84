"""Route replies (RFC 3561 6.6-6.8): generating a RREP, receiving and forwarding one, and the
RREP-ACK that shows a link works both ways.

Theory of operation
-------------------
`Replies` is the part of the protocol core (aodv.core) that answers a RREQ and carries the
answer back to its originator. Route discovery (aodv.discovery) calls `as_destination` or
`as_intermediate` when a RREQ it processed may be answered (6.6.1, 6.6.2, with the
gratuitous RREP of 6.6.3); the core hands it every RREP that is not a HELLO (`on_rrep`,
6.7), and every RREP-ACK (`on_ack`, 6.8). Every RREP leaves through `send`, which sets
the A flag towards a neighbour not yet shown to hear us and waits NEXT_HOP_WAIT for its
RREP-ACK; `expire` (on the core's timer) blacklists those that never answered.

State is the shared aodv.state.NodeState (routing table, neighbours, the RREP-ACK
bookkeeping); no clock, no IO: every method takes `now` and appends actions to `out`.
"""

from __future__ import annotations

from aodv import seqnum
from aodv.actions import Action, Unicast
from aodv.packet import Rrep, RrepAck, Rreq
from aodv.routes import Route
from aodv.state import NodeState, log

# The longest Lifetime taken from a peer's RREP, in units of our MY_ROUTE_TIMEOUT.
MAX_LIFETIME_FACTOR = 10


class Replies:
    def __init__(self, state: NodeState) -> None:
        self.s = state

    # == RFC 6.6 generating a RREP ========================================================
    def as_destination(self, now: float, m: Rreq, rev: Route, out: list[Action]) -> None:
        s = self.s
        # RFC 6.1: "Immediately before a destination node originates a RREP in response
        # to a RREQ, it MUST update its own sequence number to the maximum of its current
        # sequence number and the destination sequence number in the RREQ packet."
        # Decision: 6.6.1 says instead "increment ... if the sequence number in the RREQ
        # packet is equal to that incremented value"; the 6.1 maximum covers that case
        # and never answers with a number older than the one asked for. With the U flag
        # set the RREQ's number is meaningless and is ignored.
        if not m.unknown_seq:
            s.seq = seqnum.newest(s.seq, m.dest_seq)
        # RFC 6.6.1: "...enters the value zero in the Hop Count field of the RREP. The
        # destination node copies the value MY_ROUTE_TIMEOUT into the Lifetime field".
        rrep = Rrep(
            dest=s.addr,
            dest_seq=s.seq,
            orig=m.orig,
            lifetime_ms=s.p.ms(s.p.my_route_timeout),
            hop_count=0,
        )
        rev.active_until = max(rev.active_until, rev.lifetime)
        self.send(now, rrep, rev.next_hop, out)

    def as_intermediate(
        self, now: float, m: Rreq, rev: Route, fwd: Route, out: list[Action]
    ) -> None:
        p = self.s.p
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
            lifetime_ms=p.ms(fwd.lifetime - now),
            hop_count=fwd.hops,
        )
        self.send(now, rrep, rev.next_hop, out)
        # RFC 6.6.3: "If the RREQ has the 'G' flag set, and the intermediate node returns
        # a RREP to the originating node, it MUST also unicast a gratuitous RREP to the
        # destination node." (Destination = RREQ originator, its sequence number from the
        # RREQ, Originator = RREQ destination, hop count and lifetime of the reverse route.)
        if m.gratuitous:
            grat = Rrep(
                dest=m.orig,
                dest_seq=m.orig_seq,
                orig=m.dest,
                lifetime_ms=p.ms(rev.lifetime - now),
                hop_count=rev.hops,
            )
            self.send(now, grat, fwd.next_hop, out)

    def send(self, now: float, rrep: Rrep, next_hop: str, out: list[Action]) -> None:
        s = self.s
        # RFC 6.7/6.8: "If a node forwards a RREP over a link that is likely to have errors
        # or be unidirectional, the node SHOULD set the 'A' flag". Decision: a link is
        # "likely unidirectional" until the neighbour has shown it hears us (it sent us a
        # RREP-ACK or a RREP, i.e. picked us as its next hop) within DELETE_PERIOD.
        proof = s.bidirectional.get(next_hop)
        if proof is None or proof < now - s.p.delete_period:
            rrep = rrep._replace(ack_required=True)
            s.pending_acks[next_hop] = now + s.p.next_hop_wait
        out.append(Unicast(rrep, next_hop))

    # == RFC 6.7 receiving a RREP =========================================================
    def on_rrep(self, now: float, src: str, m: Rrep, out: list[Action]) -> None:
        # RFC 6.8: "...the node receiving the RREP with the 'A' bit set... sends a
        # RREP-ACK" back to the sender. (The core's `_finish` puts it after everything.)
        self._rrep_body(now, src, m, out)
        if m.ack_required:
            out.append(Unicast(RrepAck(), src))

    def _rrep_body(self, now: float, src: str, m: Rrep, out: list[Action]) -> None:
        s = self.s
        s.bidirectional[src] = now
        # RFC 6.7: "...searches ... for a route to the previous hop. If needed, a route is
        # created for the previous hop, but without a valid sequence number".
        s.touch_prev_hop(now, src)
        if m.dest == s.addr:
            return
        # RFC 6.7: "...increments the hop count value in the RREP by one".
        hops = m.hop_count + 1
        r = s.table.get(m.dest)
        # RFC 6.7: the existing entry is updated only if "(i) the sequence number in the
        # routing table is marked as invalid ..., (ii) the Destination Sequence Number in
        # the RREP is greater than the node's copy ..., (iii) the sequence numbers are
        # the same, but the route is marked as inactive, or (iv) the sequence numbers are
        # the same, and the New Hop Count is smaller than the hop count in route table".
        if r is None:
            r = s.table.add(Route(m.dest, src, hops, m.dest_seq, True, 0.0))
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
        if m.orig == s.addr or s.reboot_until is not None:
            return
        # RFC 6.7: "If the current node is not the node indicated by the Originator IP
        # Address in the RREP message AND a forward route has been created or updated...,
        # the node consults its route table entry for the originating node to determine
        # the next hop for the RREP packet, and then forwards the RREP towards the
        # originator".
        rev = s.table.valid(m.orig)
        if rev is None:
            log.debug("%s: RREP for %s has no route back to %s", s.addr, m.dest, m.orig)
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
        s.refresh(rev, now + s.p.active_route_timeout)
        nh_dst = s.table.valid(r.next_hop)
        if nh_dst is not None:
            nh_dst.precursors.add(rev.next_hop)
        nh_src = s.table.valid(rev.next_hop)
        if nh_src is not None:
            nh_src.precursors.add(r.next_hop)
        # Positional, as the forwarded RREQ: dest, dest_seq, orig, lifetime_ms, hop_count,
        # repair, ack_required (decided by `send`), prefix_size.
        fwd = Rrep(m.dest, m.dest_seq, m.orig, m.lifetime_ms, hops, False, False, m.prefix_size)
        self.send(now, fwd, rev.next_hop, out)

    def _peer_lifetime(self, lifetime_ms: int) -> float:
        """A RREP's Lifetime, at most MAX_LIFETIME_FACTOR times our MY_ROUTE_TIMEOUT.

        Decision: the RFC bounds no Lifetime, but no honest node gives more than its own
        MY_ROUTE_TIMEOUT plus what data refreshes added; 2**32-1 ms would keep a route for
        49 days whatever happened to the path."""
        limit = MAX_LIFETIME_FACTOR * self.s.p.my_route_timeout
        t = self.s.p.from_ms(lifetime_ms)
        if t > limit:
            self.s.dropped["lifetime_clamped"] += 1
            return limit
        return t

    # == RFC 6.8 RREP-ACK =================================================================
    def on_ack(self, now: float, src: str) -> None:
        # Decision: a RREP-ACK that arrives after NEXT_HOP_WAIT (a busy neighbour, not a
        # unidirectional link) still proves the link works both ways: it lifts the
        # blacklisting its absence caused.
        s = self.s
        s.pending_acks.pop(src, None)
        s.bidirectional[src] = now
        s.neighbors.unblacklist(src)

    def expire(self, now: float) -> None:
        s = self.s
        # RFC 6.8: "...if the RREP-ACK is not received within NEXT_HOP_WAIT, the node
        # adds the next hop to a blacklist for BLACKLIST_TIMEOUT."
        for nbr, deadline in list(s.pending_acks.items()):
            if deadline <= now:
                del s.pending_acks[nbr]
                log.info("%s: no RREP-ACK from %s, blacklisted", s.addr, nbr)
                s.neighbors.blacklist(nbr, now + s.p.blacklist_timeout)
        # The proofs of bidirectional links are bounded as the neighbour list is.
        if len(s.bidirectional) > s.p.neighbor_limit:
            old = now - s.p.delete_period
            s.bidirectional = {a: t for a, t in s.bidirectional.items() if t >= old}
