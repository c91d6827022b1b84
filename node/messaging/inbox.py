"""Messages a middleware's own thread hands over, waiting for the robot's loop to take them.

Callback-based stacks (Zenoh, Cyclone DDS) deliver a message on a thread of their own. The
robot's loop waits on file descriptors (select), so the inbox pairs a queue with an eventfd:
`put` appends, then makes the eventfd readable; `take_all` clears the eventfd, then empties
the queue. In that order a message put while `take_all` runs is either taken now or leaves
the eventfd readable for the next wakeup: none waits unseen (a wakeup may find nothing).
"""

from __future__ import annotations

import collections
import contextlib
import os


class Inbox:
    def __init__(self) -> None:
        self._queue: collections.deque[bytes] = collections.deque()
        self._fd = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        self._closed = False

    def fileno(self) -> int:
        return self._fd

    def put(self, data: bytes) -> None:
        """From the middleware's thread: queue `data` and wake the reader."""
        if self._closed:
            return
        self._queue.append(data)
        with contextlib.suppress(OSError):  # closed under us: the message has no reader left
            os.eventfd_write(self._fd, 1)

    def take_all(self) -> list[bytes]:
        """Everything queued now; never blocks."""
        if self._closed:
            return []
        with contextlib.suppress(BlockingIOError):
            os.eventfd_read(self._fd)
        out = []
        while self._queue:
            out.append(self._queue.popleft())
        return out

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self._fd)
