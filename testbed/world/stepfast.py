"""The world's step in compiled code: the sleep to the deadline, the commands, the deadline
count and the moves (native/stepcore/worldstep.cc, in build/libstepcore.so).

Theory of operation. The Python step loop (testbed.run.steploop.StepLoop) is the reference;
its compiled path (CompiledSteps there) calls these instead of its per-robot Python. A
`WorldStep` fills, once, the C struct `sc_world_step` (worldstep.h; `_Struct` here has the
same fields in the same order, all eight bytes wide) with the addresses of what a step
reads and writes: the world's bodies (testbed.world.world.Bodies, which World.move reads and
writes too), its move log (World.paths), the robots' records as arrays (last answered step,
deadlines missed and which), the body links' sockets and buffers (testbed.world.bodylink's
`_Sockets`) and the fork servers' descriptors. Then each step is:

- `sleep_until(deadline)`: the clock's deadline, slept in C (returns the clock then);
- `take(step, count_missed)`: every command in (World.command and RobotRecord.answered),
  the robots that had not answered counted (RobotRecord.missed_deadline), a look at the fork
  servers; what is not a command (a "done", a HELLO, a hang-up) is left to BodyServer in
  Python, as are the crashed robots when a fork server spoke;
- `move()`: World.move, compiled (False: it left the step to World.move, a position that
  is not finite);
- `links_due()`: whether the topology controller must be given the positions this step: a
  link may have come or gone (topology.radio.slack's reasoning, kept here in C: the least gap
  of a pair's distance from the range where the controller last took them, spent by the two
  largest moves of each step), or the links do not follow the positions alone (any range
  model but the disc, the ns-3 medium, a network shared through its state file, robots
  isolated: then always). Where it is not due, the controller's links are the range
  model's at these positions already, and set_positions would have answered "no change".

`load_records` and `store_records` carry the records between the arrays and the
RobotRecords (the compiled steps own them in between: the loop stores them back whatever
ends it). Where the library lacks these functions (not rebuilt, or TESTBED_STEPCORE=numpy),
`AVAILABLE` is False and the Python loop runs. tests/unit/test_step_fast.py holds each call
equal to its Python twin.
"""

from __future__ import annotations

import ctypes
import math

import numpy as np

from node import stepcore
from testbed.files.resultfile import MAX_MISSED_STEPS_KEPT

_P = ctypes.c_void_p
_L = ctypes.c_int64
_D = ctypes.c_double

# sc_world_step's fields, in worldstep.h's order.
_FIELDS: list[tuple[str, type[ctypes.c_int64] | type[ctypes.c_void_p] | type[ctypes.c_double]]] = [
    ("n", _L), ("m", _L),
    ("xyt", _P), ("target", _P), ("has_target", _P), ("alive", _P), ("collisions", _P),
    ("path_length", _P), ("blocked", _P), ("bh", _L), ("bw", _L), ("cell", _D), ("speed", _D),
    ("log_i", _P), ("log_xy", _P), ("log_cap", _L), ("log_len", _L),
    ("live", _P), ("last_cmd", _P), ("missed", _P), ("missed_steps", _P), ("missed_len", _P),
    ("missed_cap", _L),
    ("fds", _P), ("taken", _P), ("steps", _P), ("go", _P), ("xy", _P), ("hung", _P),
    ("others", _P), ("others_cap", _L), ("counts", _P),
    ("watch_fds", _P), ("n_watch", _L),
    ("others_used", _L), ("missed_now", _L), ("watch_ready", _L),
    ("links_slack", _L), ("comm_range", _D), ("slack_left", _D), ("link_xy", _P),
]  # fmt: skip


class _Struct(ctypes.Structure):
    _fields_ = _FIELDS


_SIGNATURES = {
    "sc_monotonic": (_D, []),
    "sc_sleep_until": (_D, [_D]),
    "sc_step_take": (_L, [_P, _L, _L]),
    "sc_world_move": (_L, [_P]),
    "sc_links_spend": (_L, [_P]),
    "sc_links_measure": (None, [_P]),
    "sc_py_hypot": (_D, [_D, _D]),
    "sc_py_atan2": (_D, [_D, _D]),
    "sc_py_hypot_mode": (None, [_L]),
}

# Subnormal lengths on which CPython 3.11's math.hypot and later versions' differ by an ulp:
# the library is set to whichever way this Python takes them (worldstep.cc's vector_norm2).
_SUBNORMAL_PROBES = (
    (-4.739300185776e-311, -5.946557129608e-311),
    (3e-310, 1e-312),
    (5e-324, 5e-324),
)


def _load():
    lib = stepcore.lib
    if lib is None or not stepcore.bind(lib, _SIGNATURES):
        return None
    for mode in (0, 1):
        lib.sc_py_hypot_mode(mode)
        if all(lib.sc_py_hypot(x, y) == math.hypot(x, y) for x, y in _SUBNORMAL_PROBES):
            return lib
    return None  # neither takes them as this Python does: the Python step loop runs


lib = _load()
AVAILABLE = lib is not None


def _addr(a: np.ndarray) -> int:
    assert a.flags.c_contiguous
    return a.ctypes.data


class WorldStep:
    """One run's compiled step: the struct over `world`'s arrays, the robots' record arrays
    and `live` (the step loop's, one bool a robot, changed in place)."""

    def __init__(self, world, live: np.ndarray) -> None:
        assert lib is not None and live.dtype == np.bool_ and live.flags.c_contiguous
        self.world = world
        n = world.n
        a = world.body_arrays
        log = world.move_log
        self.live = live
        self.last_cmd = np.full(n, -1, dtype=np.int64)
        self.missed = np.zeros(n, dtype=np.int64)
        self.missed_steps = np.zeros((n, MAX_MISSED_STEPS_KEPT), dtype=np.int64)
        self.missed_len = np.zeros(n, dtype=np.int64)
        self.blocked = np.ascontiguousarray(world.blocked, dtype=np.uint8)
        self._watch = np.zeros(0, dtype=np.int32)
        self._sockets = None
        self.records_held = False  # the arrays, not the RobotRecords, hold the records now
        self.changed = True  # a robot's state changed since the loop last asked if it is over
        self.crash_pending = False  # an exit report was read before the watch began
        s = self.s = _Struct()
        s.n, s.m = n, 0
        s.xyt, s.target, s.has_target = _addr(a.xyt), _addr(a.target), _addr(a.has_target)
        s.alive, s.collisions, s.path_length = (
            _addr(a.alive),
            _addr(a.collisions),
            _addr(a.path_length),
        )
        s.blocked, s.bh, s.bw = _addr(self.blocked), *self.blocked.shape
        s.cell, s.speed = float(world.truth.cell), float(world.speed)
        s.log_i, s.log_xy, s.log_cap = _addr(log.i), _addr(log.xy), len(log.i)
        s.live, s.last_cmd, s.missed = _addr(live), _addr(self.last_cmd), _addr(self.missed)
        s.missed_steps, s.missed_len = _addr(self.missed_steps), _addr(self.missed_len)
        s.missed_cap = MAX_MISSED_STEPS_KEPT
        self.link_xy = np.zeros((n + 1, 2), dtype=np.float64)
        s.link_xy, s.links_slack, s.slack_left = _addr(self.link_xy), 0, -1.0
        self.p = ctypes.addressof(s)

    def links_follow_positions(self, comm_range: float, display: tuple[float, float]) -> None:
        """Links follow the positions alone (the disc model of range `comm_range` on veth links,
        the display standing at `display`): from now on `links_due` says when the topology
        controller must be given them."""
        self.link_xy[-1] = display
        self.s.comm_range, self.s.links_slack, self.s.slack_left = float(comm_range), 1, -1.0

    def links_due(self) -> bool:
        """Whether a link may have come or gone since the positions the topology controller
        last took (always, where the slack does not apply); spends this step's moves."""
        assert lib is not None
        return bool(lib.sc_links_spend(self.p))

    def links_taken(self) -> None:
        """The topology controller took the bodies' positions: the slack is measured there."""
        assert lib is not None
        lib.sc_links_measure(self.p)

    def sockets(self, socks) -> None:
        """The body links' sockets and buffers (a bodylink `_Sockets`), when they changed."""
        if socks is self._sockets:
            return
        self._sockets = socks
        s = self.s
        s.m = len(socks.fds)
        s.fds, s.taken, s.steps, s.go = (
            socks.fds_p,
            *(_addr(x) for x in (socks.taken, socks.steps, socks.go)),
        )
        s.xy, s.hung, s.others = _addr(socks.xy), _addr(socks.hung), _addr(socks.others)
        s.others_cap, s.counts = len(socks.others), _addr(socks.counts)

    def watch(self, fds: list[int]) -> None:
        """The descriptors whose readiness sends the step loop looking for crashed robots."""
        self._watch = np.array(fds, dtype=np.int32)
        self.s.watch_fds, self.s.n_watch = _addr(self._watch), len(fds)

    def load_records(self, robots: dict) -> None:
        """The RobotRecords' (robots 1..n) answered steps and misses into the arrays, which
        hold them until `store_records`."""
        for k, r in robots.items():
            i = k - 1
            self.last_cmd[i] = r.last_cmd
            self.missed[i] = r.missed
            kept = r.missed_steps[:MAX_MISSED_STEPS_KEPT]
            self.missed_steps[i, : len(kept)] = kept
            self.missed_len[i] = len(kept)
        self.records_held = True

    def store_records(self, robots: dict) -> None:
        """The arrays back into the RobotRecords."""
        for k, r in robots.items():
            i = k - 1
            r.last_cmd = int(self.last_cmd[i])
            r.missed = int(self.missed[i])
            r.missed_steps = self.missed_steps[i, : int(self.missed_len[i])].tolist()
        self.records_held = False

    def sleep_until(self, deadline: float) -> float:
        """Sleep until CLOCK_MONOTONIC reads `deadline` (seconds); the clock then. A signal
        ends it early (the time returned is before the deadline)."""
        assert lib is not None
        return float(lib.sc_sleep_until(deadline))

    def take(self, step: int, count_missed: bool) -> tuple[int, int, int, bool]:
        """The step's commands (see the module's docstring): (sc_body_take's return, sockets
        hung up, robots that missed the deadline, whether a fork server has something to
        say)."""
        assert lib is not None
        s = self.s
        s.log_len = int(self.world.move_log.length[0])
        lib.sc_step_take(self.p, step, 1 if count_missed else 0)
        return (
            s.others_used,
            int(self._sockets.counts[1]) if self._sockets else 0,
            (s.missed_now),
            bool(s.watch_ready),
        )

    def move(self) -> bool:
        """World.move, compiled; False when it left the step to World.move (nothing done)."""
        assert lib is not None
        log = self.world.move_log
        s = self.s
        if s.log_len + s.n > s.log_cap:
            log.drain(self.world._paths)
        s.log_len = int(log.length[0])
        if lib.sc_world_move(self.p):
            return False
        log.length[0] = s.log_len
        self.world.step_no += 1
        return True
