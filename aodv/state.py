"""The state of one AODV node, shared by the parts of its protocol core.

Theory of operation
-------------------
`AodvCore` (aodv.core) is split by the sections of RFC 3561 into collaborating classes:
route discovery (aodv.discovery, 6.3-6.5), replies (aodv.replies, 6.6-6.8), HELLOs
(aodv.hello, 6.9-6.10), route maintenance (aodv.maintenance, 6.11-6.12) and the data path
(aodv.datapath, 6.2 and the kernel's copy of the table). They share one `NodeState`,
passed explicitly to each: the node's address, parameters and counters (sequence number,
RREQ ID, 6.1/6.3), its routing table, neighbour list, duplicate-RREQ cache, request queue
and running discoveries, the RREP-ACK bookkeeping of 6.8, when it broadcast last, and the
reboot wait of 6.13. What more than one section does to that state is written here once
(the route to a neighbour just heard, refreshing and invalidating a route, a broadcast);
what only one section touches lives in its class.

Like the core, nothing here reads a clock or touches a socket: every method takes `now`.
Every part logs on the one logger "aodv.core" (aodv.sim.warm_up silences it while it
exercises throwaway nodes).
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from dataclasses import dataclass

from aodv.actions import Action, Broadcast
from aodv.neighbors import Neighbors
from aodv.packet import Message
from aodv.params import Params
from aodv.request_queue import RequestQueue
from aodv.routes import Route, RoutingTable
from aodv.rreq_cache import RreqCache

log = logging.getLogger("aodv.core")


@dataclass
class Discovery:
    """A route discovery under way (RFC 6.3/6.4), or a local repair (6.12)."""

    dest: str
    ttl: int
    started: float
    deadline: float = 0.0
    round_started: float = 0.0
    retries: int = 0
    deferred: bool = False  # the RREQ waits (rate limit or reboot), it was not sent
    repair_hops: int | None = None  # a local repair: the hop count of the broken route


class RateLimit:
    """At most `limit` events per sliding `window` (RFC RREQ_RATELIMIT, RERR_RATELIMIT)."""

    def __init__(self, limit: int, window: float) -> None:
        self.limit, self.window = limit, window
        self._times: deque[float] = deque()

    def _trim(self, now: float) -> None:
        # The same sum as next_free's deadline: at that deadline the oldest time has left the
        # window (`now - window` may round the other way, and the deferred RREQ would be
        # deferred again to the same instant, waking the loop at once, again and again).
        while self._times and self._times[0] + self.window <= now:
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


class NodeState:
    def __init__(
        self, addr: str, params: Params, now: float, rebooted: bool, seq: int, rreq_id: int
    ) -> None:
        self.addr = addr
        self.p = params
        self.seq = seq
        self.rreq_id = rreq_id
        self.table = RoutingTable()
        self.rreq_cache = RreqCache(params.rreq_cache_limit)
        self.neighbors = Neighbors(params.neighbor_limit)
        self.queue = RequestQueue(params.queue_len)
        self.discoveries: dict[str, Discovery] = {}
        # RFC 6.8: neighbours a RREP with the A flag went to (when their RREP-ACK is due),
        # and when each neighbour last showed that it hears us.
        self.pending_acks: dict[str, float] = {}
        self.bidirectional: dict[str, float] = {}
        self.next_hello = now + params.hello_interval
        # What the core refused or bounded, by reason (the daemon writes it in its stats).
        self.dropped: Counter[str] = Counter()
        # RFC 6.13: "...after rebooting, a node MUST wait for DELETE_PERIOD before
        # transmitting any route discovery messages." Decision: the daemon says whether
        # this start is a reboot (a previous instance ran in this network: it left its
        # counters or its routes); a first start has no stale sequence numbers to protect.
        self.reboot_until = now + params.delete_period if rebooted else None

    def touch_prev_hop(self, now: float, src: str) -> None:
        """A route to a neighbour we just heard, without a valid sequence number."""
        r = self.table.get(src)
        until = now + self.p.active_route_timeout
        if r is None:
            self.table.add(Route(src, src, 1, 0, False, until))
        elif not r.valid or r.next_hop != src:
            r.valid, r.next_hop, r.hops, r.lifetime = True, src, 1, until
        else:
            r.lifetime = max(r.lifetime, until)

    def refresh(self, r: Route, until: float) -> None:
        r.lifetime = max(r.lifetime, until)
        r.active_until = max(r.active_until, until)

    def invalidate(self, r: Route, now: float) -> None:
        # RFC 6.11: "2. The entry is invalidated by marking the route entry as invalid
        # 3. The Lifetime field is updated to current time plus DELETE_PERIOD."
        r.valid = False
        r.lifetime = now + self.p.delete_period

    def broadcast(self, now: float, msg: Message, ttl: int, out: list[Action]) -> None:
        # RFC 6.9: a broadcast of any kind postpones the next HELLO (see aodv.hello).
        out.append(Broadcast(msg, ttl))
        self.next_hello = now + self.p.hello_interval
