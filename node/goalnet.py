"""Goal messages over nanomsg TCP (pynng): a PULL socket to hear, one PUSH per teammate.

nng speaks nanomsg's SP wire protocol, so Debian's `nanocat --push`/`--pull` talk to these
sockets (tests/integration/test_nanomsg_interop.py). Dialers connect in the background and
reconnect on their own; a send waits at most `send_timeout_ms` for a connected peer and then
gives up, so an unreachable teammate never blocks the robot. Routes to teammates more than
one hop away come from the robot's routing daemon, like any other traffic.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable

import pynng

log = logging.getLogger(__name__)


class GoalNet:
    def __init__(
        self,
        me: int,
        bind_addr: str,
        port: int,
        addr_of: Callable[[int], str],
        send_timeout_ms: int = 20,
    ):
        self.me = me
        self.port = port
        self.addr_of = addr_of
        self.send_timeout_ms = max(1, int(send_timeout_ms))
        self.pull = pynng.Pull0()
        self.pull.listen(f"tcp://{bind_addr}:{port}")
        self.push: dict[int, pynng.Push0] = {}

    def fileno(self) -> int:
        return self.pull.recv_fd

    def _socket(self, j: int) -> pynng.Push0:
        s = self.push.get(j)
        if s is None:
            s = pynng.Push0(
                send_timeout=self.send_timeout_ms,
                reconnect_time_min=50,
                reconnect_time_max=500,
                send_buffer_size=8,
            )
            s.dial(f"tcp://{self.addr_of(j)}:{self.port}", block=False)
            self.push[j] = s
        return s

    def connect(self, j: int) -> None:
        """Start dialling teammate j (so its connection is up before the first send)."""
        self._socket(j)

    def send(self, j: int, data: bytes) -> bool:
        """Send to teammate j; False if it could not be handed over within the timeout."""
        try:
            self._socket(j).send(data)
            return True
        except (pynng.Timeout, pynng.TryAgain):
            return False
        except pynng.NNGException as e:
            log.debug("send to r%d failed: %s", j, e)
            return False

    def receive(self) -> list[bytes]:
        out = []
        while True:
            try:
                out.append(self.pull.recv(block=False))
            except pynng.TryAgain:
                return out

    def close(self) -> None:
        for s in [self.pull, *self.push.values()]:
            with contextlib.suppress(Exception):
                s.close()
