"""HELLO messages and neighbour liveness (RFC 3561 6.9-6.10).

Theory of operation
-------------------
`Hellos` is the part of the protocol core (aodv.core) that keeps the neighbour list: a
HELLO received (a RREP with TTL 1 about its own sender, aodv.packet.is_hello) makes or
refreshes the route to that neighbour and sets how long it may stay silent
(ALLOWED_HELLO_LOSS times its Hello Interval, 6.9); `lost` names the monitored neighbours
that stayed silent longer, whose link the core then declares broken (route maintenance,
aodv.maintenance, 6.11 case i). `maybe_send` runs when the HELLO timer fires: a node on an
active route broadcasts a HELLO unless it broadcast something else within HELLO_INTERVAL
(every broadcast moves the timer, aodv.state.NodeState.broadcast).

State is the shared aodv.state.NodeState; no clock, no IO: methods take `now`.
"""

from __future__ import annotations

from aodv.actions import LOCAL_TTL, Action
from aodv.packet import Rrep
from aodv.routes import Route
from aodv.state import NodeState


class Hellos:
    def __init__(self, state: NodeState) -> None:
        self.s = state

    def on_hello(self, now: float, src: str, m: Rrep) -> None:
        s = self.s
        # RFC 6.9: "Whenever a node receives a Hello message from a neighbor, the node
        # SHOULD make sure that it has an active route to the neighbor, and create one if
        # necessary. If a route already exists, then the Lifetime for the route should be
        # increased, if necessary, to be at least ALLOWED_HELLO_LOSS * HELLO_INTERVAL. The
        # route to the neighbor, if it exists, MUST subsequently contain the latest
        # Destination Sequence Number from the Hello message."
        # The neighbour's own HELLO_INTERVAL comes from its Hello Interval extension.
        interval = s.p.hello_interval
        if m.hello_interval_ms is not None:
            interval = s.p.from_ms(self._peer_hello_interval_ms(m.hello_interval_ms))
        timeout = s.p.allowed_hello_loss * interval
        s.neighbors.hello(src, now, timeout)
        r = s.table.get(src)
        if r is None or not r.valid:
            s.table.add(Route(src, src, 1, m.dest_seq, True, now + timeout))
            return
        r.next_hop, r.hops = src, 1
        r.seq, r.valid_seq = m.dest_seq, True
        r.lifetime = max(r.lifetime, now + timeout)

    def _peer_hello_interval_ms(self, interval_ms: int) -> float:
        """A neighbour's Hello Interval (RFC 9.1), within [ours / 4, ours * 16].

        Decision: 0 would declare the link lost at once, 2**32-1 would keep a silent
        neighbour for 99 days; a robot team runs one configuration, so a value far from
        ours is an error or an attack."""
        own = self.s.p.hello_interval_ms
        clamped = min(max(interval_ms, own / 4), own * 16)
        if clamped != interval_ms:
            self.s.dropped["hello_interval_clamped"] += 1
        return clamped

    def lost(self, now: float) -> list[str]:
        """RFC 6.10 / 6.11 (i): the monitored neighbours that fell silent (forgotten)."""
        return self.s.neighbors.lost(now, self.s.p.delete_period)

    def next_deadline(self) -> float | None:
        """When `lost` has something to do next."""
        return self.s.neighbors.next_deadline(self.s.p.delete_period)

    def maybe_send(self, now: float, out: list[Action]) -> None:
        s = self.s
        # RFC 6.9: "...a node SHOULD only use hello messages if it is part of an active
        # route." "Every HELLO_INTERVAL milliseconds, the node checks whether it has sent
        # a broadcast (e.g., a RREQ ...) within the last HELLO_INTERVAL. If it has not, it
        # MAY broadcast a RREP with TTL = 1, called a Hello message". Decision: the next
        # check is HELLO_INTERVAL after the last broadcast, so a neighbour never waits
        # more than HELLO_INTERVAL between two broadcasts from us.
        active = any(r.valid and r.active_until > now for r in s.table.peek_all())
        if active and s.reboot_until is None:
            hello = Rrep(
                dest=s.addr,
                dest_seq=s.seq,
                orig=s.addr,
                lifetime_ms=s.p.ms(s.p.neighbor_timeout),
                hop_count=0,
                hello_interval_ms=int(s.p.hello_interval_ms),
            )
            s.broadcast(now, hello, LOCAL_TTL, out)
        else:
            s.next_hello = now + s.p.hello_interval
