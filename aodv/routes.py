"""The AODV routing table (RFC 3561 section 2 and 6.2): one entry per destination.

An entry is VALID (usable, installed in the kernel by the daemon) or INVALID (kept for
DELETE_PERIOD so its sequence number survives, RFC 6.11). `lifetime` is the absolute time
at which a valid entry becomes invalid, or at which an invalid entry is deleted.

The table is bounded (`shrink`): RFC 3561 sets no bound, but a flood of RREQs from forged
originators would otherwise give one reverse route each. Decision: past the bound, entries
are evicted in this order: invalid ones, then valid ones no data used lately, then the rest,
each soonest-to-expire first; entries named in `keep` (destinations being discovered) stay.

What changed since the core last synchronised the kernel is kept (`take_touched`): every
entry handed out by `get`, `valid` or `add`, or removed, is touched (whoever holds it may
change it before the event ends); a loop over all entries touches all. The core then
compares only the touched entries with the kernel, and `next_deadline` keeps a heap of
lifetimes updated from them: a HELLO from one of a hundred neighbours costs the work of one
entry, not of a hundred (every event used to pass over the whole table twice).
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass, field


@dataclass
class Route:
    dest: str
    next_hop: str
    hops: int
    seq: int
    valid_seq: bool
    lifetime: float
    valid: bool = True
    precursors: set[str] = field(default_factory=set)
    # Until when this entry is part of an active route (RFC 6.9: only such nodes send
    # HELLOs): set by route replies and by data using it, not by HELLOs or RREQs.
    active_until: float = 0.0

    def kernel_key(self) -> tuple[str, int]:
        """What the kernel route depends on: a change means reinstall."""
        return (self.next_hop, self.hops)


class RoutingTable:
    def __init__(self) -> None:
        self._routes: dict[str, Route] = {}
        # Destinations touched since take_touched() (a dict: in the order touched), or
        # None when every entry may have changed (a loop over all of them).
        self._touched: dict[str, None] | None = None
        # (lifetime, destination) of every entry, and stale pairs not yet popped: a pair is
        # current while its entry exists with that lifetime (next_deadline drops the rest).
        self._heap: list[tuple[float, str]] = []

    def _touch(self, dest: str) -> None:
        if self._touched is not None:
            self._touched[dest] = None

    def get(self, dest: str) -> Route | None:
        self._touch(dest)
        return self._routes.get(dest)

    def peek(self, dest: str) -> Route | None:
        """The entry for reading only: not touched (whoever changes it must `get` it)."""
        return self._routes.get(dest)

    def valid(self, dest: str) -> Route | None:
        self._touch(dest)
        r = self._routes.get(dest)
        return r if r is not None and r.valid else None

    def add(self, route: Route) -> Route:
        self._touch(route.dest)
        self._routes[route.dest] = route
        return route

    def remove(self, dest: str) -> None:
        self._touch(dest)
        self._routes.pop(dest, None)

    def __iter__(self) -> Iterator[Route]:
        """A snapshot: the loop may add or remove entries."""
        self._touched = None
        return iter(list(self._routes.values()))

    def entries(self) -> Iterable[Route]:
        """The live entries, for loops that change no entry's presence."""
        self._touched = None
        return self._routes.values()

    def peek_all(self) -> Iterable[Route]:
        """Every entry, for reading only: nothing is touched."""
        return self._routes.values()

    def __len__(self) -> int:
        return len(self._routes)

    def via(self, next_hop: str) -> list[Route]:
        """Valid routes whose next hop is `next_hop`."""
        out = [r for r in self._routes.values() if r.valid and r.next_hop == next_hop]
        for r in out:
            self._touch(r.dest)
        return out

    def take_touched(self) -> list[str] | None:
        """The destinations touched since the last call, in table order (those no longer in
        the table after them, in the order touched), or None when all may have changed; the
        lifetimes' heap learns of them. Starts afresh."""
        touched, self._touched = self._touched, {}
        routes = self._routes
        if touched is None:
            self._heap = [(r.lifetime, d) for d, r in routes.items()]
            heapq.heapify(self._heap)
            return None
        for d in touched:
            r = routes.get(d)
            if r is not None:
                heapq.heappush(self._heap, (r.lifetime, d))
        if len(self._heap) > 2 * len(routes) + 64:  # stale pairs: rebuild
            self._heap = [(r.lifetime, d) for d, r in routes.items()]
            heapq.heapify(self._heap)
        if len(touched) <= 1:
            return list(touched)
        present = [d for d in routes if d in touched]
        return present + [d for d in touched if d not in routes]

    def next_deadline(self) -> float | None:
        """The soonest lifetime, as of the last take_touched() (the core calls it at the end
        of every event)."""
        heap, routes = self._heap, self._routes
        while heap:
            t, d = heap[0]
            r = routes.get(d)
            if r is not None and r.lifetime == t:
                return t
            heapq.heappop(heap)
        return None

    def shrink(self, limit: int, now: float, keep: Collection[str] = ()) -> int:
        """Evict down to 90% of `limit` if above it (in batches: a flood adds one entry per
        message); return how many entries went. The caller deletes their kernel routes."""
        if len(self._routes) <= limit:
            return 0
        target = int(limit * 0.9)

        def order(r: Route) -> tuple[int, float]:
            return (2 if r.valid and r.active_until > now else 1 if r.valid else 0, r.lifetime)

        victims = sorted((r for r in self._routes.values() if r.dest not in keep), key=order)
        gone = victims[: len(self._routes) - target]
        for r in gone:
            self._touch(r.dest)
            del self._routes[r.dest]
        return len(gone)
