"""Route discovery (RFC 3561 6.3-6.5): originating RREQs with the expanding ring search,
buffering the data that waits for them, and processing and forwarding the RREQs of others.

Theory of operation
-------------------
`RouteDiscovery` is the part of the protocol core (aodv.core) that finds routes. Data of
our own without a route (`originate`) is queued (6.3) and starts a discovery: a RREQ with
TTL_START, or the old hop count plus TTL_INCREMENT, re-broadcast with a larger TTL each
RING_TRAVERSAL_TIME up to TTL_THRESHOLD, then at NET_DIAMETER with binary exponential
backoff for RREQ_RETRIES more (6.4, `timeout`). A RREQ over RREQ_RATELIMIT, or during the
reboot wait (6.13), is deferred, not sent. After every event the core asks `complete`
which discoveries now have a valid route: their packets are released. A local repair
(aodv.maintenance, 6.12) is a discovery too, started there with `send_rreq`.

A RREQ received (`on_rreq`, 6.5) is checked against the blacklist and the duplicate cache,
makes or updates the reverse route to its originator, and is answered (by aodv.replies,
6.6) or forwarded with one hop more and one TTL less.

State is the shared aodv.state.NodeState (the queue and the running discoveries live
there, as route maintenance reads them); no clock, no IO: methods take `now`.
"""

from __future__ import annotations

from aodv import seqnum
from aodv.actions import Action, DiscoveryDone, DropPackets, ReleasePackets
from aodv.packet import Rreq
from aodv.replies import Replies
from aodv.routes import Route
from aodv.state import Discovery, NodeState, RateLimit


class RouteDiscovery:
    def __init__(self, state: NodeState, replies: Replies) -> None:
        self.s = state
        self.replies = replies
        p = state.p
        self._rreq_limit = RateLimit(p.rreq_ratelimit, p.rate_window)
        self._fwd_limit = RateLimit(p.rreq_forward_ratelimit, p.rate_window)

    # == RFC 6.3 / 6.4 originating a RREQ =================================================
    def buffer(self, dst: str, packet: bytes, out: list[Action]) -> None:
        """Queue a packet for `dst` (RFC 6.3); a full queue drops its oldest."""
        overflow = self.s.queue.push(dst, packet)
        if overflow is not None:
            out.append(DropPackets(dst, (overflow,)))

    def originate(self, now: float, dst: str, packet: bytes, out: list[Action]) -> None:
        s = self.s
        self.buffer(dst, packet, out)
        self._keep_invalid_entry(now, dst)
        if dst in s.discoveries:
            return
        # RFC 6.4: "...the originating node SHOULD use the expanding ring search technique
        # ... initially uses TTL = TTL_START"; "...the TTL ... is initially set to the Hop
        # Count plus TTL_INCREMENT" when an (invalid) entry knows the old distance.
        old = s.table.get(dst)
        ttl = s.p.ttl_start if old is None else old.hops + s.p.ttl_increment
        if ttl > s.p.ttl_threshold:
            ttl = s.p.net_diameter
        d = s.discoveries[dst] = Discovery(dst, ttl, now)
        self.send_rreq(now, d, out)

    def _keep_invalid_entry(self, now: float, dst: str) -> None:
        """Data for a destination whose entry is invalid keeps the entry (and so its
        sequence number) for another DELETE_PERIOD.

        RFC 6.3: "The Destination Sequence Number field in the RREQ message is the last
        known destination sequence number for this destination"; 6.11: the invalid entry's
        "Lifetime field is updated to current time plus DELETE_PERIOD. Before this time,
        the entry SHOULD NOT be deleted." A discovery with its retries outlasts
        DELETE_PERIOD (ring, then 2.8 + 5.6 + 11.2 s with the defaults): without this the
        entry went while the discovery ran, and its last RREQs asked with U set."""
        r = self.s.table.get(dst)
        if r is not None and not r.valid:
            r.lifetime = max(r.lifetime, now + self.s.p.delete_period)

    def send_rreq(self, now: float, d: Discovery, out: list[Action]) -> None:
        s, p = self.s, self.s.p
        # RFC 6.13: "...after rebooting, a node MUST wait for DELETE_PERIOD before
        # transmitting any route discovery messages." The data waits in the queue.
        if s.reboot_until is not None and now < s.reboot_until:
            d.deferred, d.deadline = True, s.reboot_until
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
        s.seq = seqnum.increment(s.seq)
        s.rreq_id = seqnum.increment(s.rreq_id)
        # RFC 6.3: "The Destination Sequence Number field in the RREQ message is the last
        # known destination sequence number for this destination ...  If no sequence
        # number is known, the unknown sequence number flag MUST be set."
        old = s.table.get(d.dest)
        known = old is not None and old.valid_seq
        rreq = Rreq(
            rreq_id=s.rreq_id,
            dest=d.dest,
            dest_seq=old.seq if old is not None and known else 0,
            orig=s.addr,
            orig_seq=s.seq,
            hop_count=0,
            gratuitous=p.gratuitous_rrep,
            dest_only=p.dest_only,
            unknown_seq=not known,
        )
        # RFC 6.3: "Before broadcasting the RREQ, the originating node buffers the RREQ ID
        # and the Originator IP address (its own address) of the RREQ for
        # PATH_DISCOVERY_TIME."
        s.rreq_cache.add(s.addr, s.rreq_id, now + p.path_discovery_time, now)
        s.broadcast(now, rreq, d.ttl, out)
        d.round_started = now
        # RFC 6.4: "The timeout for receiving a RREP is RING_TRAVERSAL_TIME" during the
        # ring search; "Once TTL = NET_DIAMETER, the timeout for waiting for the RREP is
        # set to NET_TRAVERSAL_TIME". RFC 6.3: binary exponential backoff, "...the wait
        # time for the RREP ... is 2^k * NET_TRAVERSAL_TIME" for retry k.
        if d.ttl >= p.net_diameter:
            d.deadline = now + (2**d.retries) * p.net_traversal_time
        else:
            d.deadline = now + p.ring_traversal_time(d.ttl)

    def timeout(self, now: float, d: Discovery, out: list[Action]) -> None:
        """The deadline of a discovery of our own passed (or of a deferred RREQ)."""
        s, p = self.s, self.s.p
        if d.deferred:
            self.send_rreq(now, d, out)
            return
        if d.ttl < p.net_diameter:
            # RFC 6.4: "...the TTL_VALUE is incremented by TTL_INCREMENT ... until TTL set
            # in the RREQ reaches TTL_THRESHOLD, beyond which a TTL = NET_DIAMETER is used
            # for each attempt."
            d.ttl += p.ttl_increment
            if d.ttl > p.ttl_threshold:
                d.ttl = p.net_diameter
            self.send_rreq(now, d, out)
            return
        # RFC 6.3: "...the node MAY try again to discover a route by broadcasting another
        # RREQ, up to a maximum of RREQ_RETRIES times at the maximum TTL value."
        if d.retries < p.rreq_retries:
            d.retries += 1
            self.send_rreq(now, d, out)
            return
        # RFC 6.3: "...all data packets destined for the corresponding destination SHOULD
        # be dropped from the buffer and a Destination Unreachable message SHOULD be
        # delivered to the application."
        del s.discoveries[d.dest]
        out.append(DropPackets(d.dest, tuple(s.queue.pop_all(d.dest))))
        out.append(DiscoveryDone(d.dest, False, now - d.started, now - d.round_started))

    def complete(self, now: float, out: list[Action]) -> list[tuple[Discovery, Route]]:
        """Release the packets of every discovery that now has a valid route; return the
        local repairs among them (with their new routes) for route maintenance."""
        s = self.s
        repaired = []
        for dest, d in list(s.discoveries.items()):
            r = s.table.valid(dest)
            if r is not None:
                del s.discoveries[dest]
                out.append(ReleasePackets(dest, tuple(s.queue.pop_all(dest))))
                repair = d.repair_hops is not None
                out.append(
                    DiscoveryDone(dest, True, now - d.started, now - d.round_started, repair)
                )
                if repair:
                    repaired.append((d, r))
        return repaired

    # == RFC 6.5 processing and forwarding a RREQ =========================================
    def on_rreq(self, now: float, src: str, ttl: int, m: Rreq, out: list[Action]) -> None:
        s = self.s
        # RFC 6.8: "...a node ignores all RREQs received from any node in its blacklist
        # set."
        if s.neighbors.blacklisted(src, now):
            return
        # RFC 6.5: "When a node receives a RREQ, it first creates or updates a route to
        # the previous hop without a valid sequence number."
        s.touch_prev_hop(now, src)
        if m.orig == s.addr:
            return
        # RFC 6.5: "...checks to determine whether it has received a RREQ with the same
        # Originator IP Address and RREQ ID within at least the last PATH_DISCOVERY_TIME.
        # If such a RREQ has been received, the node silently discards the newly received
        # RREQ."
        if s.rreq_cache.seen(m.orig, m.rreq_id, now):
            return
        s.rreq_cache.add(m.orig, m.rreq_id, now + s.p.path_discovery_time, now)
        # RFC 6.5: "...first increments the hop count value in the RREQ by one..."
        hops = m.hop_count + 1
        rev = self._update_reverse_route(now, src, m, hops)
        if s.reboot_until is not None:
            # RFC 6.13: it "SHOULD create route entries as appropriate ... but MUST NOT
            # forward any control packets" (and sends no RREP) while it waits.
            return
        if m.dest == s.addr:
            self.replies.as_destination(now, m, rev, out)
            return
        # RFC 6.6 (ii): "it has an active route to the destination, the destination
        # sequence number in the node's existing route table entry for the destination is
        # valid and greater than or equal to the Destination Sequence Number of the RREQ
        # ... and the 'destination only' ('D') flag is NOT set."
        # Decision: with the U flag the RREQ's number means nothing, any valid one will do.
        # Decision: never answer with a route whose next hop is the node that asked (it
        # would point the requester back through itself); forward the RREQ instead.
        fwd = s.table.valid(m.dest)
        if (
            fwd is not None
            and fwd.valid_seq
            and not m.dest_only
            and (m.unknown_seq or seqnum.at_least(fwd.seq, m.dest_seq))
            and fwd.next_hop != src
        ):
            self.replies.as_intermediate(now, m, rev, fwd, out)
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
            s.dropped["rreq_forward_ratelimit"] += 1
            return
        known = s.table.get(m.dest)
        dest_seq, unknown = m.dest_seq, m.unknown_seq
        if known is not None and known.valid_seq:
            dest_seq = known.seq if unknown else seqnum.newest(m.dest_seq, known.seq)
            unknown = False
        # (Positional: keyword arguments cost a NamedTuple twice as much, on every hop.)
        fwd_msg = Rreq(
            m.rreq_id, m.dest, dest_seq, m.orig, m.orig_seq, hops,
            m.join, m.repair, m.gratuitous, m.dest_only, unknown,
        )  # fmt: skip
        s.broadcast(now, fwd_msg, ttl - 1, out)

    def _update_reverse_route(self, now: float, src: str, m: Rreq, hops: int) -> Route:
        s = self.s
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
        minimal = now + 2 * s.p.net_traversal_time - 2 * hops * s.p.node_traversal_time
        r = s.table.get(m.orig)
        if r is None:
            return s.table.add(Route(m.orig, src, hops, m.orig_seq, True, minimal))
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
