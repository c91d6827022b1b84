"""The part of the messenger contract every middleware keeps the same way (`MessengerBase`),
and the receiving side of those whose stack delivers on a thread of its own (`InboxMessenger`).

Theory of operation. A messenger is made with the contract's arguments (node.messaging.
contract), which `MessengerBase.__init__` keeps, bounded once for all: the send timeout at
least 1 ms, the reconnect back-off (first wait, ceiling) each at least 1 ms and the ceiling
not below the first wait. `send` is counted here (node.messaging.stats: its wait, whether it
was handed over) around the middleware's own `_send(j, data)`, and what `receive` returns is
counted by `_counted`. A middleware's class subclasses one of the two and writes only what
is its own: its sockets or session, `fileno`, `connect`, `_send`, `receive` (or the inbox's),
`close`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from node.messaging.inbox import Inbox
from node.messaging.stats import MessengerStats


class MessengerBase:
    name = ""  # the middleware, as node.messaging's registry names it

    def __init__(
        self,
        me: int,
        bind_addr: str,
        port: int,
        addr_of: Callable[[int], str],
        team: Sequence[int] = (),
        send_timeout_ms: int = 20,
        reconnect_ms: tuple[int, int] = (50, 500),
    ) -> None:
        self.me = me
        self.bind_addr = bind_addr
        self.port = port
        self.addr_of = addr_of
        self.team = tuple(team)
        self.send_timeout_ms = max(1, int(send_timeout_ms))
        lo, hi = (max(1, int(v)) for v in reconnect_ms)
        self.reconnect_ms = (lo, max(lo, hi))
        self.stats = MessengerStats()

    def send(self, j: int, data: bytes) -> bool:
        """Hand `data` to teammate j; False if that failed (counted either way)."""
        token = self.stats.send_started()
        ok = False
        try:
            ok = self._send(j, data)
        finally:
            self.stats.send_ended(token, ok)
        return ok

    def _send(self, j: int, data: bytes) -> bool:
        """The middleware's send: True once `data` is handed over, waiting at most
        send_timeout_ms."""
        raise NotImplementedError

    def _counted(self, out: list[bytes]) -> list[bytes]:
        """What receive() returns, counted."""
        self.stats.received += len(out)
        return out


class InboxMessenger(MessengerBase):
    """A messenger whose stack hands messages over on a thread of its own (Zenoh, Cyclone
    DDS): they wait in an Inbox, whose eventfd is the messenger's descriptor."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._inbox = Inbox()

    def fileno(self) -> int:
        return self._inbox.fileno()

    def receive(self) -> list[bytes]:
        return self._counted(self._inbox.take_all())
