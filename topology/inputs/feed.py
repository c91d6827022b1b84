"""A live position feed: lines of text move the robots of a running testbed.

Protocol, one update per line (what `testbed net feed NAME` reads on standard input and on
the Unix socket `feed.sock` in the testbed's run directory):

    ID X Y        robot ID (1..N, or rID) to (X, Y) metres, at once
    T ID X Y      the same at emulated time T (seconds since the feed started)

Blank lines and lines starting with # are skipped. The server answers nothing on success;
a bad line gets `error: line N: what` back (socket) or ends the feed with exit status 2
(standard input). A last line without a newline is that line. Limits: a line is at most
MAX_LINE_BYTES (4096) bytes, X and Y are within MAX_COORD_M (1e7 m) of 0, T is at most
MAX_TIME_S (1e6 s), and at most MAX_PENDING (100000) timed updates wait at once.

Theory of operation. One thread, one selector over standard input, the listening socket and
its clients. Everything readable is read, parsed and merged into one batch of moves (the last
position of each robot wins) before the links are updated once: at a high rate of updates the
cost is that of the link update per batch, not per line, which is how 1000 updates per second
reach a 1000-robot testbed. Timed updates wait in a heap until their emulated time is due
(wall time T / time_scale after the start). Positions go to the state file when the feed pauses
(50 ms) and at least once a second, where `net move`, `net links` and a trace player find
them.
"""

from __future__ import annotations

import heapq
import math
import os
import selectors
import socket
import time

from topology import state
from topology.inputs.linebuffer import TOO_LONG, LineBuffer
from topology.names import parse_robot_ref
from topology.spec import check_position

SOCKET_NAME = "feed.sock"
SOCKET_MODE = 0o600  # root's alone: nobody else may move the robots
SAVE_EVERY_S = 1.0
IDLE_SAVE_S = 0.05  # a pause this long in the feed saves the positions
MAX_WAIT_S = 1.0  # the longest the loop sleeps in one select (a far timed update waits on)
# PIPE_BUF: a line no longer than this reaches a pipe in one piece, never interleaved with
# another writer's; a valid line is under 100 bytes, so the rest is room for comments.
MAX_LINE_BYTES = 4096
# The latest emulated time an update may name (11.6 days): later than any testbed is up.
MAX_TIME_S = 1e6
# Timed updates waiting at once (each ~200 bytes in the heap: ~20 MB at most).
MAX_PENDING = 100_000


def socket_path(name: str) -> str:
    return os.path.join(state.run_dir(name), SOCKET_NAME)


def parse_line(line: str) -> tuple[float | None, int, float, float] | None:
    """(T or None, robot, x, y) of one feed line; None for a blank or comment line.
    Raises ValueError saying what is wrong."""
    text = line.strip()
    if not text or text.startswith("#"):
        return None
    parts = text.split()
    if len(parts) not in (3, 4):
        raise ValueError(f"expected 'ID X Y' or 'T ID X Y', found {len(parts)} fields")
    t = None
    if len(parts) == 4:
        try:
            t = float(parts[0])
        except ValueError:
            raise ValueError(f"time {parts[0]!r} is not a number") from None
        if not (math.isfinite(t) and 0 <= t <= MAX_TIME_S):
            raise ValueError(f"time {parts[0][:40]} must be a number >= 0 and <= {MAX_TIME_S:,.0f}")
        parts = parts[1:]
    k = parse_robot_ref(parts[0])
    x, y = check_position(parts[1:])
    return t, k, x, y


class _Source:
    """A stream of lines: standard input or one socket client."""

    def __init__(self, fileobj, is_stdin: bool):
        self.fileobj = fileobj
        self.is_stdin = is_stdin
        self.lines = LineBuffer(MAX_LINE_BYTES)
        self.lineno = 0


class FeedError(Exception):
    """A bad line on standard input: the feed ends (exit 2)."""


class FeedServer:
    def __init__(self, net, path: str, stdin: bool = True):
        self.net = net
        self.path = path
        self.robots = net.spec.robots
        self.scale = net.spec.time_scale
        self.sel = selectors.DefaultSelector()
        self.timed: list[tuple[float, int, int, float, float]] = []
        self.seq = 0
        self.applied = 0  # robot moves applied (a robot moved twice in one batch counts once)
        self.lines = 0  # updates accepted
        self.batches = 0
        self.start = time.monotonic()
        self._ended: list[_Source] = []
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        if os.path.lexists(path):
            os.unlink(path)
        # The mode before bind is the mode bind gives the file (less the umask), so the
        # socket is never connectable by others, not even between bind and chmod.
        os.fchmod(self.listener.fileno(), SOCKET_MODE)
        self.listener.bind(path)
        os.chmod(path, SOCKET_MODE)
        self.listener.listen(16)
        self.listener.setblocking(False)
        self.sel.register(self.listener, selectors.EVENT_READ, None)
        self.stdin_open = stdin
        if stdin:
            fd = os.dup(0)
            os.set_blocking(fd, False)
            self.sel.register(fd, selectors.EVENT_READ, _Source(fd, True))

    def close(self) -> None:
        for key in list(self.sel.get_map().values()):
            src = key.data
            if isinstance(src, _Source):
                self._drop(src)
        self.listener.close()
        if os.path.lexists(self.path):
            os.unlink(self.path)
        self.net.save()

    def _drop(self, src: _Source) -> None:
        self.sel.unregister(src.fileobj)
        if src.is_stdin:
            os.close(src.fileobj)
            self.stdin_open = False
        else:
            src.fileobj.close()

    def _read(self, src: _Source, moves: dict) -> None:
        try:
            chunk = os.read(src.fileobj, 1 << 16) if src.is_stdin else src.fileobj.recv(1 << 16)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._lines(src, src.lines.end(), moves)  # a last line without its newline
            self._ended.append(src)  # dropped once its last moves are applied
            return
        self._lines(src, src.lines.feed(chunk), moves)

    def _lines(self, src: _Source, lines: list[bytes | None], moves: dict) -> None:
        for raw in lines:
            src.lineno += 1
            try:
                if raw is TOO_LONG:
                    raise ValueError(f"longer than {MAX_LINE_BYTES} bytes")
                parsed = parse_line(raw.decode(errors="replace"))
                if parsed is not None and parsed[1] > self.robots:
                    raise ValueError(f"robot {parsed[1]} is not one of r1..r{self.robots}")
                if parsed is not None and parsed[0] is not None and len(self.timed) >= MAX_PENDING:
                    raise ValueError(f"{MAX_PENDING} timed updates are waiting already")
            except ValueError as exc:
                message = f"line {src.lineno}: {exc}"
                if src.is_stdin:
                    raise FeedError(message) from None
                try:
                    src.fileobj.sendall(f"error: {message}\n".encode())
                except OSError:
                    pass
                continue
            if parsed is None:
                continue
            t, k, x, y = parsed
            self.lines += 1
            if t is None:
                moves[k] = (x, y)
            else:
                self.seq += 1
                heapq.heappush(self.timed, (t, self.seq, k, x, y))

    def emulated_now(self) -> float:
        return (time.monotonic() - self.start) * self.scale

    def serve(self, until_stdin_closes: bool = True, stop=None) -> None:
        """Apply updates until standard input ends (with stdin) or forever (without):
        timed updates still pending when stdin ends are applied when due first."""
        last_saved = time.monotonic()
        dirty = False
        while stop is None or not stop.is_set():
            if until_stdin_closes and not self.stdin_open and not self.timed:
                return
            timeout = IDLE_SAVE_S if dirty or stop is not None else None
            if self.timed:
                due = max(0.0, self.timed[0][0] / self.scale - (time.monotonic() - self.start))
                timeout = min(due, MAX_WAIT_S) if timeout is None else min(timeout, due)
            moves: dict[int, tuple[float, float]] = {}
            for key, _ in self.sel.select(timeout):
                if key.data is None:
                    try:
                        conn, _ = self.listener.accept()
                    except BlockingIOError:
                        continue
                    conn.setblocking(False)
                    self.sel.register(conn, selectors.EVENT_READ, _Source(conn, False))
                else:
                    self._read(key.data, moves)
            now = self.emulated_now()
            while self.timed and self.timed[0][0] <= now:
                _, _, k, x, y = heapq.heappop(self.timed)
                moves[k] = (x, y)
            if moves:
                self.net.move_many(moves, save=False)
                self.applied += len(moves)
                self.batches += 1
                dirty = True
            if dirty and (not moves or time.monotonic() - last_saved > SAVE_EVERY_S):
                self.net.save()  # when the feed pauses, or once a second under a stream
                last_saved = time.monotonic()
                dirty = False
            for src in self._ended:
                self._drop(src)
            self._ended.clear()


def send(path: str, lines) -> None:
    """A client: send `lines` (an iterable of str) to the feed socket at `path`."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.connect(path)
        for line in lines:
            s.sendall(line.encode() if line.endswith("\n") else (line + "\n").encode())
