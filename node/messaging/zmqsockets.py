"""What the two ZeroMQ messengers share: a context, a socket that listens on the robot's port,
one socket per teammate, and their use from several threads (`ZmqSockets`).

A ZeroMQ socket is not thread-safe, and a robot sends from two threads (the planner, message
processing), receives from a third (the inbox) and closes from a fourth. So each socket has
its own lock, held for the whole of a send (a second send to the same teammate waits for
the first: that wait is the robot's too, and counted as blocked). `close()` terminates the
context, which ends every call still blocked inside ZeroMQ with ETERM (even a send that
would wait forever), then closes each socket under its lock.

The descriptor `fileno()` gives is ZeroMQ's ZMQ_FD of the listening socket: readable when
the socket's state may have changed, which `receive()` then reads to the end (until EAGAIN),
as ZeroMQ's documentation asks, so that the next message makes it readable again.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import zmq

from node.messaging.base import MessengerBase

CLOSE_WAIT_S = 5.0  # close() waits this long at most for ZeroMQ's own threads to end


class _Socket:
    def __init__(self, sock: zmq.Socket):
        self.sock = sock
        self.lock = threading.Lock()


class ZmqSockets(MessengerBase):
    """The base of the ZeroMQ messengers: a subclass says which socket types they are and
    how a socket is set up (`_peer_options`), and how one message is handed over
    (`_hand_over`) and answered (`_answer`)."""

    LISTEN_TYPE = zmq.PULL
    PEER_TYPE = zmq.PUSH

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """The contract's arguments (node.messaging.base.MessengerBase)."""
        super().__init__(*args, **kwargs)
        bind_addr, port = self.bind_addr, self.port
        self.ctx = zmq.Context(io_threads=1)
        self._closed = False
        self._lock = threading.Lock()  # the peers dict
        self.peers: dict[int, _Socket] = {}
        rx = self.ctx.socket(self.LISTEN_TYPE)
        rx.setsockopt(zmq.LINGER, 0)
        try:
            rx.bind(f"tcp://{bind_addr}:{port}")
        except zmq.ZMQError as e:
            rx.close()
            self.ctx.term()
            raise OSError(e.errno, f"cannot listen on {bind_addr}:{port}: {e}") from None
        self.listener = _Socket(rx)
        self._fd: int = rx.getsockopt(zmq.FD)  # type: ignore[assignment]  # FD is an int option

    # -- what a subclass says ----------------------------------------------------------------

    def _peer_options(self, sock: zmq.Socket) -> None:
        """Set the options of a new socket to a teammate (before it connects)."""
        raise NotImplementedError

    def _hand_over(self, sock: zmq.Socket, data: bytes) -> bool:
        """Send one message on a teammate's socket; False if it was not handed over."""
        raise NotImplementedError

    def _answer(self, sock: zmq.Socket) -> None:
        """After a message was received on the listening socket (REP replies here)."""

    # -- the contract ------------------------------------------------------------------------

    def fileno(self) -> int:
        return self._fd

    def _peer(self, j: int) -> _Socket | None:
        """Teammate j's socket, made and connected on first use; None once closed."""
        with self._lock:
            if self._closed:
                return None
            p = self.peers.get(j)
            if p is None:
                sock = self.ctx.socket(self.PEER_TYPE)
                sock.setsockopt(zmq.LINGER, 0)
                sock.setsockopt(zmq.RECONNECT_IVL, self.reconnect_ms[0])
                sock.setsockopt(zmq.RECONNECT_IVL_MAX, self.reconnect_ms[1])
                self._peer_options(sock)
                sock.connect(f"tcp://{self.addr_of(j)}:{self.port}")
                p = self.peers[j] = _Socket(sock)
            return p

    def connect(self, j: int) -> None:
        """Start connecting to teammate j (ZeroMQ connects and reconnects in the background)."""
        self._peer(j)

    def _send(self, j: int, data: bytes) -> bool:
        try:
            p = self._peer(j)
            if p is not None:
                with p.lock:
                    if not p.sock.closed:
                        return self._hand_over(p.sock, data)
        except zmq.ZMQError:  # ETERM: closed meanwhile
            pass
        return False

    def receive(self) -> list[bytes]:
        out: list[bytes] = []
        rx = self.listener
        with rx.lock:
            if rx.sock.closed:
                return out
            try:
                while True:
                    out.append(rx.sock.recv(zmq.NOBLOCK))
                    self._answer(rx.sock)
            except zmq.Again:
                pass
            except zmq.ZMQError:  # ETERM: closed meanwhile
                pass
        return self._counted(out)

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            sockets = [self.listener, *self.peers.values()]
        # Terminating the context ends every call blocked inside ZeroMQ with ETERM (so each
        # socket's lock comes free), and returns once every socket is closed.
        term = threading.Thread(target=self._term, name="zmq-term", daemon=True)
        term.start()
        for s in sockets:
            with s.lock:
                s.sock.close()
        term.join(CLOSE_WAIT_S)

    def _term(self) -> None:
        with contextlib.suppress(zmq.ZMQError):
            self.ctx.term()
