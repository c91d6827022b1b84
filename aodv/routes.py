"""The AODV routing table (RFC 3561 section 2 and 6.2): one entry per destination.

An entry is VALID (usable, installed in the kernel by the daemon) or INVALID (kept for
DELETE_PERIOD so its sequence number survives, RFC 6.11). `lifetime` is the absolute time
at which a valid entry becomes invalid, or at which an invalid entry is deleted.

The table is bounded (`shrink`): RFC 3561 sets no bound, but a flood of RREQs from forged
originators would otherwise give one reverse route each. Decision: past the bound, entries
are evicted in this order: invalid ones, then valid ones no data used lately, then the rest,
each soonest-to-expire first; entries named in `keep` (destinations being discovered) stay.
"""

from __future__ import annotations

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

    def get(self, dest: str) -> Route | None:
        return self._routes.get(dest)

    def valid(self, dest: str) -> Route | None:
        r = self._routes.get(dest)
        return r if r is not None and r.valid else None

    def add(self, route: Route) -> Route:
        self._routes[route.dest] = route
        return route

    def remove(self, dest: str) -> None:
        self._routes.pop(dest, None)

    def __iter__(self) -> Iterator[Route]:
        """A snapshot: the loop may add or remove entries."""
        return iter(list(self._routes.values()))

    def entries(self) -> Iterable[Route]:
        """The live entries, for loops that change no entry's presence."""
        return self._routes.values()

    def __len__(self) -> int:
        return len(self._routes)

    def via(self, next_hop: str) -> list[Route]:
        """Valid routes whose next hop is `next_hop`."""
        return [r for r in self._routes.values() if r.valid and r.next_hop == next_hop]

    def next_deadline(self) -> float | None:
        return min((r.lifetime for r in self._routes.values()), default=None)

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
            del self._routes[r.dest]
        return len(gone)
