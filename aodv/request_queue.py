"""Data packets waiting for a route (RFC 3561 section 6.3).

RFC 3561 6.3: "Data packets waiting for a route (i.e., waiting for a RREP after a RREQ has
been sent) SHOULD be buffered. The buffering SHOULD be "first-in, first-out" (FIFO)."
Packets are opaque to the core; the daemon hands them in and gets them back to send or
to answer with ICMP destination unreachable. When a destination's queue is full the oldest
packet is dropped (returned by `push`).
"""

from __future__ import annotations

from collections import deque


class RequestQueue:
    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._q: dict[str, deque[bytes]] = {}

    def push(self, dest: str, packet: bytes) -> bytes | None:
        q = self._q.setdefault(dest, deque())
        q.append(packet)
        if len(q) > self.limit:
            return q.popleft()
        return None

    def pop_all(self, dest: str) -> list[bytes]:
        return list(self._q.pop(dest, ()))

    def __contains__(self, dest: str) -> bool:
        return dest in self._q
