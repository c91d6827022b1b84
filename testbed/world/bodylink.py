"""The world's side of the robots' body links (protocol in node.body).

One Unix SOCK_SEQPACKET listening socket; each robot process (and the display) connects and
says HELLO with its number and role. Sends never block the world's step loop: a robot whose
socket buffer is full (it stopped reading) simply misses that frame.

Each step's share (`take` the robots' commands, `send_frames` their frames) runs in two
compiled calls where the step core was built (native/stepcore/bodylink.cc): it was a dozen
Python calls a robot a step. `poll` and `send` are the reference they are tested against, and
what runs elsewhere: before the steps (HELLOs), for the display, and where the step core is
not built. A connection that arrives during the steps waits for the next `poll`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import selectors
import socket
import time
from typing import cast

import numpy as np

from node import body, stepcore
from node.stepcore import address, ptr

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
        self._sockets: _Sockets | None = None  # the step's sockets, for the compiled calls

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
                self._message(conn, meta, data, out)
        return out

    def _message(self, conn: socket.socket, meta: dict, data: bytes, out: list) -> None:
        """One datagram from `conn`, parsed into `out` as (robot, message); a HELLO names the
        socket, a malformed one is counted."""
        try:
            msg = body.parse(data)
        except ValueError as e:
            self.malformed += 1
            log.warning("body link: %s", e)
            return
        if msg[0] == "hello":
            meta["robot"] = msg[1]
            table = self.displays if msg[2] == body.ROLE_DISPLAY else self.robots
            table[msg[1]] = conn
            self._sockets = None
            out.append((msg[1], msg))
        elif meta["robot"] is not None:
            out.append((meta["robot"], msg))

    def take(self, n: int) -> list[tuple[int, tuple]]:
        """A step's messages from robots 1..n and the displays, as `poll(0.0)` gives them,
        except that each robot's commands come as one: ("cmd", the largest step, the last
        target), what its commands come to (RobotRecord.answered keeps the largest step,
        World.command the last target). Compiled where the step core runs."""
        if stepcore.lib is None:
            return self.poll(0.0)
        s = self.step_sockets(n)
        used = stepcore.lib.sc_body_take(len(s.fds), s.fds_p, *s.take_args)
        with_cmds, hung = s.counts.tolist()
        out = self.taken_rest(s, used, hung)
        if with_cmds:
            taken, steps, go, xy = s.taken.tolist(), s.steps.tolist(), s.go.tolist(), s.xy.tolist()
            for i, t in enumerate(taken):
                if t:
                    out.append((s.keys[i], ("cmd", steps[i], tuple(xy[i]) if go[i] else None)))
        return out

    def taken_rest(self, s: _Sockets, used: int, hung: int) -> list[tuple[int, tuple]]:
        """What sc_body_take (its return `used`, `hung` sockets hung up) left to Python: the
        datagrams that are not commands, parsed as `poll` parses them, and the sockets that
        hung up, dropped."""
        out: list[tuple[int, tuple]] = []
        if used != 0:
            self._others(s, used if used >= 0 else -1 - used, out)
        if hung:
            for i in np.flatnonzero(s.hung).tolist():
                conn = s.conn(i)
                self._drop(conn, self._meta(conn))
        return out

    def _others(self, s: _Sockets, used: int, out: list) -> None:
        """The datagrams sc_body_take left to Python (all but commands), in `out`."""
        buf, at = s.others, 0
        while at < used:
            i, size = (int(v) for v in buf[at : at + 8].view(np.uint32))
            data = buf[at + 8 : at + 8 + size].tobytes()
            at += 8 + size
            conn = s.conn(i)
            self._message(conn, self._meta(conn), data, out)

    def _meta(self, conn: socket.socket) -> dict:
        key = self.sel.get_map().get(conn)
        return key.data if key is not None else {"robot": None}

    def send_frames(self, step: int, now: float, xyt: np.ndarray, ranges: np.ndarray,
                    has: np.ndarray, live: np.ndarray) -> None:  # fmt: skip
        """Each live robot k (live[k - 1]) its frame of `step`: pose row k - 1 of `xyt`,
        `ranges` row k - 1 where has[k - 1] is 1 (else every ray +inf), `now` as its time
        sent. Compiled where the step core runs."""
        n = len(live)
        if stepcore.lib is None:
            for i in np.flatnonzero(live).tolist():
                x, y, theta = xyt[i].tolist()
                r = ranges[i] if has[i] == 1 else np.full(ranges.shape[1], np.inf, np.float32)
                self.send(i + 1, body.frame(step, x, y, theta, r, now))
            return
        assert xyt.dtype == np.float64 and ranges.dtype == np.float32 and has.dtype == np.int8
        assert live.dtype == np.bool_ and xyt.shape == (n, 3) and ranges.shape[0] == has.size == n
        s = self.step_sockets(n)
        stepcore.lib.sc_body_frames(n, s.fds_p, address(live), step, address(xyt), now,
                                    address(ranges), address(has), ranges.shape[1])  # fmt: skip

    def step_sockets(self, n: int) -> _Sockets:
        """The sockets of robots 1..n and the displays, with the compiled calls' buffers (the
        same object while no socket comes or goes)."""
        s = self._sockets
        if s is None or s.n != n:
            s = self._sockets = _Sockets(n, self.robots, self.displays)
        return s

    def _drop(self, conn: socket.socket, meta: dict) -> None:
        self._sockets = None
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


OTHERS_BYTES = 1 << 20  # room for the step's datagrams that are not commands (16 of the largest)


class _Sockets:
    """The sockets of robots 1..n (-1 where none) and then of the displays, with the buffers
    sc_body_take and sc_body_frames fill and read, kept while no socket comes or goes."""

    def __init__(self, n: int, robots: dict[int, socket.socket],
                 displays: dict[int, socket.socket]) -> None:  # fmt: skip
        self.n = n
        conns = [robots.get(k) for k in range(1, n + 1)] + list(displays.values())
        self.keys = list(range(1, n + 1)) + list(displays)
        self.conns = conns
        m = len(conns)
        self.fds = np.array([-1 if c is None else c.fileno() for c in conns], dtype=np.int32)
        self.fds_p = ptr(self.fds)
        self.taken = np.zeros(m, dtype=np.int32)
        self.steps = np.zeros(m, dtype=np.int64)
        self.go = np.zeros(m, dtype=np.uint8)
        self.xy = np.zeros((m, 2), dtype=np.float64)
        self.hung = np.zeros(m, dtype=np.uint8)
        self.others = np.zeros(OTHERS_BYTES, dtype=np.uint8)
        self.counts = np.zeros(2, dtype=np.int32)  # sockets with commands, sockets hung up
        self.take_args = (ptr(self.taken), ptr(self.steps), ptr(self.go), ptr(self.xy),
                          ptr(self.hung), ptr(self.others), OTHERS_BYTES,
                          ptr(self.counts))  # fmt: skip

    def conn(self, i: int) -> socket.socket:
        """Socket i, one the compiled calls read (they read none where there is none)."""
        conn = self.conns[i]
        assert conn is not None
        return conn
