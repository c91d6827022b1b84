"""What robots say to each other on the emulated network.

Floods (UDP broadcast, see node.flood) carry a header and a payload (network byte order):

    'RMF2' u8 kind u8 ttl u16 origin u32 seq u32 step    (16 bytes: the flood itself)
    u16 sender u8 n, n x u16 neighbour                   (this copy: who sent it, and whom
                                                           the sender hears)

`step` is the origin's step when it sent the flood. `sender` is the robot that transmitted
this copy (the origin, or a relay) and the neighbours are the robots the sender heard
recently: a relay rewrites both, and the receiver's self-pruning rule reads them
(node.flood). The only flood kind is MAP: part of the
origin's own local map (cells its own laser saw), cropped to its known cells, with its
position. Most map floods carry only the window its laser swept since its last flood (a
delta). The whole local map goes out when the robot hears from a robot (or the display) it had
not heard from for a while, so that whoever missed deltas while out of reach catches up, and
every `full_period` steps in any case:

    f32 x f32 y u16 r0 u16 c0 u16 h u16 w, then the zlib'd 2-bit ternary cells (node.grid)

The display, which explores nothing, floods a BEACON (its position) so that robots notice when
it comes back into reach.

Goals and re-plan requests travel over the run's middleware (node.messaging; nanomsg TCP by
default) as small JSON objects:

    {"k": "goal",   "from": 3, "step": 120, "goal": [x, y], "cost": 4.2[, "fallback": true],
     "n": 7}
    {"k": "replan", "from": 1, "step": 121, "goal": [x, y], "n": 8}  (the sender's winning goal)

"fallback" marks a goal taken although it is near a teammate's (every reachable frontier was):
asking its robot to re-plan would not help, so nobody does. "n" numbers the sender's messages
(1, 2, ...; a goal sent to several teammates is one message, one number), so that a receiver
can tell a duplicate the middleware delivered twice (node.messaging.arrivals); a message
without it (older senders, nanocat) is valid.

A message is decoded as docs/robot-contract.md (section 3) says, by both robots alike: the
bytes must be UTF-8 (no byte-order mark, no encoded surrogates), one JSON value nesting at
most MAX_DEPTH objects and arrays, its integer literals within the signed 64-bit range.

Every parser raises ValueError on malformed input, whatever the bytes; callers count and
drop it.
"""

from __future__ import annotations

import json
import math
import re
import struct
from dataclasses import dataclass

import numpy as np

from node.grid import decode_ternary, encode_ternary
from topology.names import MAX_ROBOTS

MAGIC = b"RMF2"
KIND_MAP = 1
KIND_BEACON = 2  # the display's "I am here": f32 x f32 y
MAX_NEIGHBOURS = 255
_HDR = struct.Struct("!4sBBHII")
_COPY = struct.Struct("!HB")
_MAP = struct.Struct("!ffHHHH")
_FIXED = _HDR.size + _COPY.size


@dataclass(frozen=True)
class FloodHeader:
    kind: int
    ttl: int
    origin: int
    seq: int
    step: int
    sender: int = 0  # who transmitted this copy; pack_flood's callers set it
    neighbours: tuple[int, ...] = ()  # whom the sender heard recently


def _copy_part(sender: int, neighbours) -> bytes:
    nb = sorted(neighbours)[:MAX_NEIGHBOURS]
    return _COPY.pack(sender, len(nb)) + struct.pack(f"!{len(nb)}H", *nb)


def pack_flood(h: FloodHeader, payload: bytes) -> bytes:
    return (
        _HDR.pack(MAGIC, h.kind, h.ttl, h.origin, h.seq, h.step)
        + _copy_part(h.sender, h.neighbours)
        + payload
    )


# The largest robot number a flood may name as its origin or sender: a team's robots and the
# display (docs/robot-contract.md, section 2). Bounded before anything is kept per origin, so a
# peer that names 65,535 origins cannot grow the duplicate cache past the largest team's.
MAX_FLOOD_ID = MAX_ROBOTS + 1


def flood_ids(data: bytes) -> tuple[int, int, int, int]:
    """(ttl, origin, seq, sender) of a flood in wire form; ValueError if it is not one."""
    if len(data) < _FIXED:
        raise ValueError("flood shorter than its header")
    magic, _, ttl, origin, seq, _ = _HDR.unpack_from(data)
    if magic != MAGIC:
        raise ValueError("not a robot flood (bad magic)")
    sender = _COPY.unpack_from(data, _HDR.size)[0]
    if not (1 <= origin <= MAX_FLOOD_ID and 1 <= sender <= MAX_FLOOD_ID):
        raise ValueError(f"flood of origin {origin} from {sender}: robots are 1..{MAX_FLOOD_ID}")
    return ttl, origin, seq, sender


def flood_neighbours(data: bytes) -> tuple[tuple[int, ...], int]:
    """(the sender's neighbours, the payload's offset) of a flood that passed flood_ids."""
    n = data[_HDR.size + 2]
    end = _FIXED + 2 * n
    if len(data) < end:
        raise ValueError("flood shorter than its neighbour list")
    return struct.unpack_from(f"!{n}H", data, _FIXED), end


def unpack_flood(data: bytes) -> tuple[FloodHeader, bytes]:
    ttl, origin, seq, sender = flood_ids(data)
    neighbours, off = flood_neighbours(data)
    kind, step = data[4], _HDR.unpack_from(data)[5]
    return FloodHeader(kind, ttl, origin, seq, step, sender, neighbours), data[off:]


def relayed(data: bytes, ttl: int, sender: int, neighbours) -> bytes:
    """The same flood as retransmitted by `sender`: its TTL, sender and neighbours replaced."""
    _, off = flood_neighbours(data)
    return (
        data[:5] + bytes([ttl]) + data[6 : _HDR.size] + _copy_part(sender, neighbours) + data[off:]
    )


_BEACON = struct.Struct("!ff")


def pack_beacon(x: float, y: float) -> bytes:
    return _BEACON.pack(x, y)


def unpack_beacon(payload: bytes) -> tuple[float, float]:
    if len(payload) != _BEACON.size:
        raise ValueError("beacon payload has the wrong length")
    return _BEACON.unpack(payload)


def pack_map(x: float, y: float, ternary: np.ndarray, r_off: int = 0, c_off: int = 0) -> bytes:
    """A map payload for `ternary`, a window of the map whose top-left cell is (r_off, c_off)."""
    r0, c0, h, w, blob = encode_ternary(ternary)
    return _MAP.pack(x, y, r0 + r_off if h else 0, c0 + c_off if w else 0, h, w) + blob


@dataclass
class MapMsg:
    x: float
    y: float
    r0: int
    c0: int
    cells: np.ndarray


def unpack_map(payload: bytes, shape: tuple[int, int]) -> MapMsg:
    if len(payload) < _MAP.size:
        raise ValueError("map payload shorter than its header")
    x, y, r0, c0, h, w = _MAP.unpack_from(payload)
    if r0 + h > shape[0] or c0 + w > shape[1]:
        raise ValueError("map does not fit this robot's grid")
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError("map position is not finite")
    cells = decode_ternary(h, w, payload[_MAP.size :])
    return MapMsg(x, y, r0, c0, cells)


def goal_msg(
    sender: int,
    step: int,
    goal: tuple[float, float],
    cost: float,
    fallback: bool = False,
    n: int | None = None,
) -> bytes:
    m = {"k": "goal", "from": sender, "step": step, "goal": list(goal), "cost": round(cost, 3)}
    if fallback:
        m["fallback"] = True
    if n is not None:
        m["n"] = n
    return json.dumps(m).encode()


def replan_msg(sender: int, step: int, goal: tuple[float, float], n: int | None = None) -> bytes:
    m = {"k": "replan", "from": sender, "step": step, "goal": list(goal)}
    if n is not None:
        m["n"] = n
    return json.dumps(m).encode()


MAX_DEPTH = 64  # objects and arrays one inside another in a message, at most
_INT64_DIGITS = 20  # "-9223372036854775808": a longer literal is out of range
_STRING = re.compile(r'"(?:[^"\\]++|\\.)*+"?', re.DOTALL)  # to its end, or the text's
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")


def _int64(literal: str) -> int:
    """json's parse_int: an integer literal, refused outside the signed 64-bit range (its
    length is looked at first, so a literal of any length costs nothing)."""
    if len(literal) > _INT64_DIGITS or not -(2**63) <= (v := int(literal)) < 2**63:
        raise ValueError(f"integer out of range: {literal[:24]}")
    return v


_DECODER = json.JSONDecoder(parse_int=_int64)


def _check_depth(text: str) -> None:
    """ValueError when `text` opens more than MAX_DEPTH objects and arrays one inside
    another, strings skipped; before json recurses into them. On a valid text this is the
    nesting; on an invalid one it is at least the depth json reaches before it gives up
    (both skip strings alike up to the first error), so the verdict is json's otherwise."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:
        return
    brackets = np.frombuffer(_NOT_BRACKET.sub("", _STRING.sub("", text)).encode(), np.uint8)
    steps = np.where((brackets == ord("[")) | (brackets == ord("{")), 1, -1)
    if steps.size and int(np.cumsum(steps).max()) > MAX_DEPTH:
        raise ValueError(f"nested deeper than {MAX_DEPTH}")


def _json(data: bytes):
    """The JSON value of a message's bytes; ValueError for anything else, whatever the
    bytes (the contract's text: strict UTF-8, bounded nesting and integers)."""
    try:
        text = bytes(data).decode("utf-8")
        _check_depth(text)
        return _DECODER.decode(text)
    except ValueError as e:  # UnicodeDecodeError and json.JSONDecodeError are ValueErrors
        raise ValueError(f"message is not JSON: {e}") from None


def parse_msg(data: bytes, n_robots: int) -> dict:
    """Validate a goal or replan message; returns the dict with goal as a tuple. ValueError
    for anything else, whatever the bytes."""
    m = _json(data)
    if not isinstance(m, dict) or m.get("k") not in ("goal", "replan"):
        raise ValueError("message has no known kind")
    sender, step, goal = m.get("from"), m.get("step"), m.get("goal")
    if not isinstance(sender, int) or not 1 <= sender <= n_robots:
        raise ValueError("message sender is not a robot of this team")
    if not isinstance(step, int) or step < 0:
        raise ValueError("message step is not a step")
    if (
        not isinstance(goal, list)
        or len(goal) != 2
        or not all(isinstance(v, int | float) and math.isfinite(v) for v in goal)
    ):
        raise ValueError("message goal is not a point")
    m["from"], m["step"] = int(sender), int(step)  # true is 1, as the C++ robot reads it
    m["goal"] = (float(goal[0]), float(goal[1]))
    n = m.get("n")
    if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
        raise ValueError("message number is not a number >= 1")
    m["n"] = n
    if m["k"] == "goal":
        cost = m.get("cost")
        if not isinstance(cost, int | float) or not math.isfinite(cost) or cost < 0:
            raise ValueError("goal message has no valid cost")
        m["cost"] = float(cost)
        m["fallback"] = bool(m.get("fallback", False))
    return m
