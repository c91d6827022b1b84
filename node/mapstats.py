"""What a robot's map transport counts (`MapStats`), the same for floods and publish/subscribe.

Counted are the robot's maps (flood kind MAP; the display's beacons are not maps):
`published` the maps it sent (handed to the socket or the middleware), `failed` those the
transport refused (a full socket buffer; no subscriber known, or a write given up after its
bound), `bytes_published` the bytes of the maps sent, each once whatever the number of
receivers (on the wire, a flood goes out once and is relayed; a publication goes to every
subscriber by unicast); `received` and `bytes_received` the teammates' maps delivered to
message processing (a flood's duplicate copies not counted), `received_from` them per sender
("r2": n); `blocked_s` and `blocked_max_s` the wall seconds spent inside a publish (a
flood's sendto, a Zenoh put, a DDS write), in all and the longest one.

The timer thread publishes and the inbox thread receives: each side's counters are written
by one thread only, and as_dict() copies them.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field


@dataclass
class MapStats:
    transport: str  # "flood" or "pubsub"
    published: int = 0
    failed: int = 0
    bytes_published: int = 0
    received: int = 0
    bytes_received: int = 0
    received_from: Counter[int] = field(default_factory=Counter)
    blocked_s: float = 0.0
    blocked_max_s: float = 0.0

    def note_publish(self, size: int, ok: bool, seconds: float) -> None:
        """A map of `size` bytes was published (`ok`) or refused, in `seconds`."""
        if ok:
            self.published += 1
            self.bytes_published += size
        else:
            self.failed += 1
        self.blocked_s += seconds
        self.blocked_max_s = max(self.blocked_max_s, seconds)

    def note_receive(self, origin: int, size: int) -> None:
        """A map of `size` bytes from `origin` was delivered."""
        self.received += 1
        self.bytes_received += size
        self.received_from[origin] += 1

    def as_dict(self) -> dict:
        """The counters as rK.json records them (seconds rounded to microseconds)."""
        return {
            "transport": self.transport,
            "published": self.published,
            "failed": self.failed,
            "bytes_published": self.bytes_published,
            "received": self.received,
            "bytes_received": self.bytes_received,
            "received_from": {f"r{k}": n for k, n in sorted(self.received_from.items())},
            "blocked_s": round(self.blocked_s, 6),
            "blocked_max_s": round(self.blocked_max_s, 6),
        }
