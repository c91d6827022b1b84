"""nanomsg, the default middleware: a PULL socket to hear, one PUSH per teammate (pynng).

nng speaks nanomsg's SP wire protocol, so Debian's `nanocat --push`/`--pull` talk to these
sockets (tests/integration/test_nanomsg_interop.py). Dialers connect in the background and
reconnect on their own; a send waits at most `send_timeout_ms` for a connected peer and then
gives up, so an unreachable teammate never blocks the robot. Routes to teammates more than
one hop away come from the robot's routing daemon, like any other traffic.

Every interval nng keeps here is in wall ms and comes from node.timing, divided by the time
scale there: the send timeout and the redial backoff (`reconnect_ms`: the first wait, and the
ceiling it doubles up to). A PUSH socket has no resend timer, and TCP keepalives stay off.

The wire is nanomsg's SP over TCP on the robot's goal port (`port`, 5101 in a run): the
listener on the robot's own address, one outgoing connection per teammate it sends to.
This messenger was the robots' only one (first named GoalNet); its sockets and options are
unchanged, and it counts what it does in `stats` (node.messaging.stats).
"""

from __future__ import annotations

import contextlib
import logging
from typing import Any

import pynng

from node.messaging import SEND_QUEUE
from node.messaging.base import MessengerBase

log = logging.getLogger(__name__)


class NanomsgMessenger(MessengerBase):
    name = "nanomsg"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """The contract's arguments (node.messaging.base.MessengerBase)."""
        super().__init__(*args, **kwargs)
        self.pull = pynng.Pull0()
        self.pull.listen(f"tcp://{self.bind_addr}:{self.port}")
        self.push: dict[int, pynng.Push0] = {}

    def fileno(self) -> int:
        return self.pull.recv_fd

    def _socket(self, j: int) -> pynng.Push0:
        s = self.push.get(j)
        if s is None:
            s = pynng.Push0(
                send_timeout=self.send_timeout_ms,
                reconnect_time_min=self.reconnect_ms[0],
                reconnect_time_max=self.reconnect_ms[1],
                send_buffer_size=SEND_QUEUE,
            )
            s.dial(f"tcp://{self.addr_of(j)}:{self.port}", block=False)
            self.push[j] = s
        return s

    def connect(self, j: int) -> None:
        """Start dialling teammate j (so its connection is up before the first send)."""
        self._socket(j)

    def _send(self, j: int, data: bytes) -> bool:
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
        """Every message waiting now; never blocks, never raises for what a peer sent."""
        out = []
        while True:
            try:
                out.append(_recv(self.pull))
            except pynng.TryAgain:
                return self._counted(out)

    def close(self) -> None:
        for s in [self.pull, *self.push.values()]:
            with contextlib.suppress(Exception):
                s.close()


def _recv(pull: pynng.Pull0) -> bytes:
    """One message, without blocking (pynng.TryAgain when none waits). An empty message is
    b"" (the robot counts it as malformed): pynng's recv has nng take the message, then
    fails to copy its empty body out (RuntimeError, "cannot use unpack() on NULL")."""
    try:
        return pull.recv(block=False)
    except RuntimeError:
        return b""
