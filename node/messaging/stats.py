"""What a messenger counts: `MessengerStats`, the same counters for every middleware.

`sent` and `failed` count the sends that returned True and False; `received` the messages
receive() handed over; `blocked_s` the wall seconds spent inside send(), and
`blocked_max_s` the longest single send. A send that has not returned yet counts too: a
middleware that waits without a bound (zeromq-reqrep to a dead teammate) would otherwise
report nothing of the wait that matters most. Its time so far is in `blocked_s` and
`blocked_max_s` of `as_dict()`, and `sending` says how many sends are still inside.

A messenger brackets each send with `send_started()` and `send_ended(token, ok)`; robots
send from two threads (the planner, message processing), so both are thread-safe.
"""

from __future__ import annotations

import itertools
import threading
import time
from dataclasses import dataclass, field

# The counters' names, in the order as_dict() gives them (the contract's).
COUNTERS = ("sent", "failed", "received", "blocked_s", "blocked_max_s")


@dataclass
class MessengerStats:
    sent: int = 0
    failed: int = 0
    received: int = 0
    blocked_s: float = 0.0
    blocked_max_s: float = 0.0
    # Sends in progress: token -> time.monotonic() when it started.
    _open: dict[int, float] = field(default_factory=dict, repr=False, compare=False)
    _tokens: itertools.count = field(default_factory=itertools.count, repr=False, compare=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def send_started(self) -> int:
        """A send begins now; the token goes to send_ended."""
        with self._lock:
            token = next(self._tokens)
            self._open[token] = time.monotonic()
        return token

    def send_ended(self, token: int, ok: bool) -> float:
        """The send of `token` returned `ok`; its wall seconds, now counted."""
        now = time.monotonic()
        with self._lock:
            seconds = now - self._open.pop(token)
            self.blocked_s += seconds
            self.blocked_max_s = max(self.blocked_max_s, seconds)
            if ok:
                self.sent += 1
            else:
                self.failed += 1
        return seconds

    def as_dict(self) -> dict:
        """The counters as rK.json records them (seconds rounded to microseconds), with the
        sends still inside send() counted up to now, and their number as `sending`."""
        now = time.monotonic()
        with self._lock:
            waits = [now - t for t in self._open.values()]
            blocked = self.blocked_s + sum(waits)
            longest = max([self.blocked_max_s, *waits])
            return {
                "sent": self.sent,
                "failed": self.failed,
                "received": self.received,
                "blocked_s": round(blocked, 6),
                "blocked_max_s": round(longest, 6),
                "sending": len(waits),
            }
