"""The messenger contract: what every middleware's class offers the robot (`Messenger`).

The robot (node.robot) holds one messenger and never asks which middleware it is: it
connects to its teammates, sends each a message with a bounded wait, receives what is
waiting when the messenger's descriptor is readable, and closes it at the end. The class of
each middleware (node.messaging's registry) has exactly these members; this Protocol is
for type checking and for the reader. Every class is made with the same arguments (me,
bind_addr, port, addr_of, team, send_timeout_ms, reconnect_ms), which it takes from
node.messaging.base.MessengerBase, its base: that keeps them bounded, counts `send` and
`receive` in `stats`, and for a stack that delivers on its own thread (InboxMessenger) gives
`fileno` and `receive`. The Zenoh and DDS messengers also offer `map_topic()`, the robots'
maps on their session (node.messaging.maps).
"""

from __future__ import annotations

from typing import Protocol

from node.messaging.stats import MessengerStats


class Messenger(Protocol):
    name: str  # the middleware: "nanomsg", "zeromq", "zeromq-reqrep", "zenoh", "dds"
    stats: MessengerStats  # updated by send() and receive()

    def fileno(self) -> int:
        """A descriptor that is readable when receive() may return something."""
        ...

    def connect(self, j: int) -> None:
        """Start reaching teammate j (may do nothing)."""
        ...

    def send(self, j: int, data: bytes) -> bool:
        """Hand `data` to teammate j; False if that failed. Waits at most send_timeout_ms
        (zeromq-reqrep excepted: it awaits the reply without a bound, by design)."""
        ...

    def receive(self) -> list[bytes]:
        """Every message waiting now; never blocks."""
        ...

    def close(self) -> None:
        """Free the messenger's sockets, threads and sessions; idempotent."""
        ...
