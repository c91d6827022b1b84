"""The robot's link to its body: a local IPC channel to the world, as a driver to hardware.

Both sides' protocol lives here, with the robot program, which imports nothing of the harness;
the world's body-link server (testbed.world.bodylink) implements the other side with these
encoders. It listens on a Unix SOCK_SEQPACKET socket in the testbed's state directory. A Unix
socket lives in the filesystem, so a robot process inside its network namespace reaches it
without crossing the emulated network. Messages (one datagram each, network byte order):

    robot -> world  HELLO  'H' u16 robot u8 role (0 robot, 1 display)
    world -> robot  FRAME  'F' u32 step f32 x f32 y f32 theta f64 sent u16 n, then n float32
                           ranges (sent: the world's time.monotonic(), for latency stats)
    world -> robot  END    'E'                        (the run is over: finish and exit)
    robot -> world  CMD    'C' u32 step u8 go f32 x f32 y   (drive toward (x, y), or stop)
    robot -> world  DONE   'D' u32 step               (no reachable frontier left)

A robot answers every frame it acts on with one CMD carrying that frame's step: the world
counts a frame not answered before the next one as a missed step deadline.

A FRAME whose x, y, theta or sent is not finite is malformed (`parse`); so is, for a robot
(`BodyClient.expect`), one whose position is off its map or whose ray count is not its laser's
(`check_frame`). The robot counts it and drops it (docs/robot-contract.md, section 1).
"""

from __future__ import annotations

import math
import select
import socket
import struct
from dataclasses import dataclass

import numpy as np

ROLE_ROBOT, ROLE_DISPLAY = 0, 1
_HELLO = struct.Struct("!cHB")
_FRAME = struct.Struct("!cIfffdH")
_CMD = struct.Struct("!cIBff")
_DONE = struct.Struct("!cI")
MAX_DATAGRAM = 65536


@dataclass
class Frame:
    step: int
    x: float
    y: float
    theta: float
    ranges: np.ndarray
    sent: float = 0.0


def hello(robot: int, role: int) -> bytes:
    return _HELLO.pack(b"H", robot, role)


def frame(
    step: int, x: float, y: float, theta: float, ranges: np.ndarray | None, sent: float = 0.0
) -> bytes:
    r = b"" if ranges is None else np.asarray(ranges, dtype=">f4").tobytes()
    n = 0 if ranges is None else len(ranges)
    return _FRAME.pack(b"F", step, x, y, theta, sent, n) + r


END = b"E"


def cmd(step: int, target: tuple[float, float] | None) -> bytes:
    if target is None:
        return _CMD.pack(b"C", step, 0, 0.0, 0.0)
    return _CMD.pack(b"C", step, 1, target[0], target[1])


def done(step: int) -> bytes:
    return _DONE.pack(b"D", step)


def parse(data: bytes):
    """Decode one datagram: ("hello", robot, role) | ("frame", Frame) | ("end",) |
    ("cmd", step, target|None) | ("done", step). Raises ValueError on malformed input."""
    if not data:
        raise ValueError("empty body message")
    t = data[:1]
    try:
        if t == b"H":
            _, robot, role = _HELLO.unpack(data)
            return ("hello", robot, role)
        if t == b"F":
            _, step, x, y, theta, sent, n = _FRAME.unpack_from(data)
            body = data[_FRAME.size :]
            if len(body) != 4 * n:
                raise ValueError("frame length does not match its ray count")
            if not all(map(math.isfinite, (x, y, theta, sent))):
                raise ValueError("frame with a position, heading or time that is not finite")
            ranges = np.frombuffer(body, dtype=">f4").astype(np.float32)
            return ("frame", Frame(step, x, y, theta, ranges, sent))
        if t == b"E":
            return ("end",)
        if t == b"C":
            _, step, go, x, y = _CMD.unpack(data)
            return ("cmd", step, (x, y) if go else None)
        if t == b"D":
            _, step = _DONE.unpack(data)
            return ("done", step)
    except struct.error as e:
        raise ValueError(f"malformed body message: {e}") from None
    raise ValueError(f"unknown body message type {t!r}")


def check_frame(f: Frame, width_m: float, height_m: float, n_rays: int) -> None:
    """Raise ValueError unless frame `f` is one a robot on a map `width_m` x `height_m`
    (metres) with a laser of `n_rays` rays can have: its position on the map (0 <= x < width,
    0 <= y < height; the world never puts a robot elsewhere, and the robot's maps have no
    cells there) and one range per ray."""
    if not (0.0 <= f.x < width_m and 0.0 <= f.y < height_m):
        raise ValueError(f"frame position ({f.x:g}, {f.y:g}) is off the map")
    if len(f.ranges) != n_rays:
        raise ValueError(f"frame has {len(f.ranges)} ranges, the laser {n_rays}")


class BodyClient:
    """The robot side of the link (blocking socket; one reader thread, any writer)."""

    def __init__(self, path: str, robot: int, role: int = ROLE_ROBOT):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.sock.connect(path)
        self.robot, self.role = robot, role
        self.frame_bounds: tuple[float, float, int] | None = None

    def expect(self, width_m: float, height_m: float, n_rays: int) -> None:
        """From now on `recv` refuses (ValueError) a frame `check_frame` refuses."""
        self.frame_bounds = (width_m, height_m, n_rays)

    def ready(self) -> None:
        """Say HELLO: the world starts its clock once every robot has, so a robot says it
        only when it can answer frames at once (everything built, every part running)."""
        self.sock.sendall(hello(self.robot, self.role))

    def recv(self, timeout: float | None = None):
        """Next message from the world, or None on timeout; ("end",) when the world hangs up."""
        if timeout is not None and not select.select([self.sock], [], [], timeout)[0]:
            return None
        try:
            data = self.sock.recv(MAX_DATAGRAM)
        except OSError:
            return ("end",)
        if not data:
            return ("end",)
        msg = parse(data)
        if self.frame_bounds is not None and msg[0] == "frame":
            check_frame(msg[1], *self.frame_bounds)
        return msg

    def pending(self) -> bool:
        """True when another message is already waiting."""
        return bool(select.select([self.sock], [], [], 0)[0])

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendall(data)
        except OSError:
            pass  # the world is gone; the reader sees the hang-up

    def close(self) -> None:
        self.sock.close()
