"""The world's side of the robots' body links (protocol in node.body).

One Unix SOCK_SEQPACKET listening socket; each robot process (and the display) connects and
says HELLO with its number and role. Sends never block the world's step loop: a robot whose
socket buffer is full (it stopped reading) simply misses that frame.
"""

from __future__ import annotations

import contextlib
import logging
import os
import selectors
import socket
import time
from typing import cast

from node import body

log = logging.getLogger(__name__)


class BodyServer:
    def __init__(self, path: str):
        self.path = path
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        self.lsock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.lsock.bind(path)
        self.lsock.listen(128)
        self.lsock.setblocking(False)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.lsock, selectors.EVENT_READ, None)
        self.robots: dict[int, socket.socket] = {}
        self.displays: dict[int, socket.socket] = {}
        self.malformed = 0

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.lsock.accept()
            except BlockingIOError:
                return
            conn.setblocking(False)
            self.sel.register(conn, selectors.EVENT_READ, {"robot": None})

    def poll(self, timeout: float) -> list[tuple[int, tuple]]:
        """Messages that arrived within `timeout` seconds: (robot, parsed message)."""
        out: list[tuple[int, tuple]] = []
        for key, _ in self.sel.select(max(0.0, timeout)):
            if key.data is None:
                self._accept()
                continue
            conn, meta = cast(socket.socket, key.fileobj), key.data  # only sockets registered
            while True:
                try:
                    data = conn.recv(body.MAX_DATAGRAM)
                except BlockingIOError:
                    break
                except OSError:
                    data = b""
                if not data:
                    self._drop(conn, meta)
                    break
                try:
                    msg = body.parse(data)
                except ValueError as e:
                    self.malformed += 1
                    log.warning("body link: %s", e)
                    continue
                if msg[0] == "hello":
                    meta["robot"] = msg[1]
                    table = self.displays if msg[2] == body.ROLE_DISPLAY else self.robots
                    table[msg[1]] = conn
                    out.append((msg[1], msg))
                elif meta["robot"] is not None:
                    out.append((meta["robot"], msg))
        return out

    def _drop(self, conn: socket.socket, meta: dict) -> None:
        with contextlib.suppress(KeyError, ValueError):
            self.sel.unregister(conn)
        k = meta.get("robot")
        for table in (self.robots, self.displays):
            if k is not None and table.get(k) is conn:
                del table[k]
        conn.close()

    def wait_for(self, robots: set[int], displays: set[int], timeout: float) -> list:
        """Wait until every robot in `robots` and display in `displays` said HELLO.

        Returns the non-HELLO messages received meanwhile (normally none)."""
        deadline = time.monotonic() + timeout
        extra = []
        while not (robots <= set(self.robots) and displays <= set(self.displays)):
            left = deadline - time.monotonic()
            if left <= 0:
                break
            extra += [m for m in self.poll(min(left, 0.2)) if m[1][0] != "hello"]
        return extra

    def send(self, k: int, data: bytes, display: bool = False) -> bool:
        conn = (self.displays if display else self.robots).get(k)
        if conn is None:
            return False
        try:
            conn.send(data)
            return True
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return False

    def close(self) -> None:
        for key in list(self.sel.get_map().values()):
            with contextlib.suppress(OSError):
                cast(socket.socket, key.fileobj).close()
        self.sel.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
