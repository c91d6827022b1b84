"""Duplicate RREQ detection (RFC 3561 section 6.5).

RFC 3561 6.5: "The node checks to determine whether it has received a RREQ with the same
Originator IP Address and RREQ ID within at least the last PATH_DISCOVERY_TIME. If such a
RREQ has been received, the node silently discards the newly received RREQ."

Bounded (the RFC sets no bound; a flood of forged originators would grow it without one):
past `limit` entries, expired ones go first, then the oldest (entries are kept in insertion
order, and every entry lives PATH_DISCOVERY_TIME, so the oldest is the soonest to expire).
An entry evicted early can let a late duplicate through once: it is counted in `evicted`.
"""

from __future__ import annotations


class RreqCache:
    def __init__(self, limit: int = 4096) -> None:
        self.limit = limit
        self.evicted = 0
        self._seen: dict[tuple[str, int], float] = {}

    def seen(self, orig: str, rreq_id: int, now: float) -> bool:
        expiry = self._seen.get((orig, rreq_id))
        return expiry is not None and expiry > now

    def add(self, orig: str, rreq_id: int, until: float, now: float = float("-inf")) -> None:
        seen = self._seen
        seen.pop((orig, rreq_id), None)  # re-inserted at the end: insertion order = age
        seen[(orig, rreq_id)] = until
        if len(seen) > self.limit:
            self.purge(now)
            while len(seen) > self.limit:
                del seen[next(iter(seen))]
                self.evicted += 1

    def purge(self, now: float) -> None:
        for key in [k for k, t in self._seen.items() if t <= now]:
            del self._seen[key]

    def __len__(self) -> int:
        return len(self._seen)
