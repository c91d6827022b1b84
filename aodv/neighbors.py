"""Neighbour sensing (RFC 3561 sections 6.9, 6.10) and the RREQ blacklist (section 6.8).

A neighbour is monitored once a HELLO came from it: RFC 6.10 "If, within the past
DELETE_PERIOD, it has received a Hello message from a neighbor, and then for that neighbor
does not receive any packets (Hello messages or otherwise) for more than ALLOWED_HELLO_LOSS *
HELLO_INTERVAL milliseconds, the node SHOULD assume that the link to this neighbor is
currently lost."

`next_deadline` keeps a heap of the neighbours' deadlines, brought up to date from the
neighbours heard or forgotten since it last ran, so that a HELLO from one of a hundred
neighbours does not cost a pass over all of them.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

# Decision: the neighbour list is bounded (forged IP sources would grow it); past the bound
# the neighbours heard least recently are forgotten, down to 90% of it.
DEFAULT_LIMIT = 256


@dataclass
class Neighbor:
    addr: str
    last_hello: float | None = None
    last_heard: float = 0.0
    # Allowed silence, from the neighbour's Hello Interval extension when it sent one.
    timeout: float = 0.0


class Neighbors:
    def __init__(self, limit: int = DEFAULT_LIMIT) -> None:
        self.limit = limit
        self.evicted = 0
        self._n: dict[str, Neighbor] = {}
        self._blacklist: dict[str, float] = {}
        # next_deadline's heap of (deadline, address), current for DELETE_PERIOD _heap_dp,
        # and the neighbours changed since it was brought up to date (None: all of them).
        self._heap: list[tuple[float, str]] = []
        self._heap_dp: float | None = None
        self._changed: set[str] | None = None

    def heard(self, addr: str, now: float) -> Neighbor:
        n = self._n.get(addr)
        if n is None:
            if len(self._n) >= self.limit:
                self._evict()
            n = self._n[addr] = Neighbor(addr)
        n.last_heard = now
        if self._changed is not None:
            self._changed.add(addr)
        return n

    def _evict(self) -> None:
        by_age = sorted(self._n.values(), key=lambda n: n.last_heard)
        for n in by_age[: len(by_age) - int(self.limit * 0.9)]:
            del self._n[n.addr]
            self.evicted += 1
        self._changed = None
        if len(self._blacklist) >= self.limit:
            self._blacklist.clear()

    def hello(self, addr: str, now: float, timeout: float) -> None:
        n = self.heard(addr, now)
        n.last_hello = now
        n.timeout = timeout

    def get(self, addr: str) -> Neighbor | None:
        """The neighbour, for reading only."""
        return self._n.get(addr)

    def forget(self, addr: str) -> None:
        self._n.pop(addr, None)  # its heap entry goes stale and is dropped when on top

    def lost(self, now: float, delete_period: float) -> list[str]:
        """Monitored neighbours silent for longer than their timeout; they are forgotten.

        Whether a neighbour was monitored is judged when its allowed silence ended, not when
        the timer is handled: a daemon that handles it late (descheduled) must not find the
        neighbour unmonitored by then, keep it, and be woken for it again at once."""
        out = []
        for n in list(self._n.values()):
            if _monitored_at_break(n, delete_period):
                if now >= n.last_heard + n.timeout:
                    out.append(n.addr)
                    del self._n[n.addr]
            elif now >= n.last_heard + delete_period:  # at next_deadline's instant, not after
                del self._n[n.addr]
        return out

    def next_deadline(self, delete_period: float) -> float | None:
        """When lost() has something to do next for a neighbour that sent a HELLO: its
        allowed silence ends (if it is monitored then), else it is forgotten. The same
        rule as lost(), so a deadline that has passed is always cleared by handling it
        (a deadline lost() ignored would wake the daemon's loop again and again)."""
        heap, neighbors = self._heap, self._n
        if self._changed is None or delete_period != self._heap_dp:
            heap[:] = [
                (t, a)
                for a, n in neighbors.items()
                if (t := _deadline(n, delete_period)) is not None
            ]
            heapq.heapify(heap)
            self._heap_dp = delete_period
        else:
            for a in self._changed:
                n = neighbors.get(a)
                if n is not None and (t := _deadline(n, delete_period)) is not None:
                    heapq.heappush(heap, (t, a))
            if len(heap) > 2 * len(neighbors) + 64:  # stale pairs: rebuild next time
                self._changed = None
                return self.next_deadline(delete_period)
        self._changed = set()
        while heap:
            t, a = heap[0]
            n = neighbors.get(a)
            if n is not None and _deadline(n, delete_period) == t:
                return t
            heapq.heappop(heap)
        return None

    # -- RFC 6.8 blacklist -------------------------------------------------------------
    def blacklist(self, addr: str, until: float) -> None:
        self._blacklist[addr] = until

    def unblacklist(self, addr: str) -> None:
        self._blacklist.pop(addr, None)

    def blacklisted(self, addr: str, now: float) -> bool:
        until = self._blacklist.get(addr)
        if until is None:
            return False
        if until <= now:
            del self._blacklist[addr]
            return False
        return True


def _deadline(n: Neighbor, delete_period: float) -> float | None:
    """next_deadline's rule for one neighbour (None: it never sent a HELLO)."""
    if n.last_hello is None:
        return None
    if _monitored_at_break(n, delete_period):
        return n.last_heard + n.timeout
    return n.last_heard + delete_period


def _monitored_at_break(n: Neighbor, delete_period: float) -> bool:
    """RFC 6.10's condition at the moment the neighbour's allowed silence ends: a HELLO came
    from it within DELETE_PERIOD before that moment."""
    return n.last_hello is not None and n.last_hello >= n.last_heard + n.timeout - delete_period
