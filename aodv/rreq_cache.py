"""Duplicate RREQ detection (RFC 3561 section 6.5).

RFC 3561 6.5: "The node checks to determine whether it has received a RREQ with the same
Originator IP Address and RREQ ID within at least the last PATH_DISCOVERY_TIME. If such a
RREQ has been received, the node silently discards the newly received RREQ."
"""

from __future__ import annotations


class RreqCache:
    def __init__(self) -> None:
        self._seen: dict[tuple[str, int], float] = {}

    def seen(self, orig: str, rreq_id: int, now: float) -> bool:
        expiry = self._seen.get((orig, rreq_id))
        return expiry is not None and expiry > now

    def add(self, orig: str, rreq_id: int, until: float) -> None:
        self._seen[(orig, rreq_id)] = until

    def purge(self, now: float) -> None:
        for key in [k for k, t in self._seen.items() if t <= now]:
            del self._seen[key]

    def __len__(self) -> int:
        return len(self._seen)
