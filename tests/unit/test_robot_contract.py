"""One contract, two implementations (docs/robot-contract.md): the Python robot's codecs
(node.body, node.wire) and the C++ robot's (native/robot, through `tb-robot --decode KIND`
and `--encode KIND`) are held to each other.

- What Python encodes, C++ decodes to the same fields, and the reverse, for every body
  message, floods with neighbour lists, map payloads and goal / re-plan messages.
- The C++ laser tables are numpy's, byte for byte (the scan's cells depend on them).
- A Hypothesis corpus of malformed inputs (valid encodings cut, flipped, extended, and
  arbitrary bytes) goes to both: Python raises ValueError or decodes; tb-robot prints the
  decoded form (exit 0) or "refused: ..." (exit 1), never crashes (a signal, a sanitizer
  report, another status). For messages both must agree on accept or refuse.

Skipped where build/tb-robot was not built (no g++ or libnng-dev).
"""

import json
import math
import subprocess
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from node import body, wire
from node.grid import decode_ternary
from node.native import TB_ROBOT, unbuilt_reason
from node.rays import Laser

pytestmark = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))

FUZZ = settings(max_examples=120, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
SHAPE = (400, 400)
ROBOTS = 10


def cpp(mode: str, kind: str, data: bytes, *extra: str) -> subprocess.CompletedProcess:
    p = subprocess.run([str(TB_ROBOT), mode, kind, *extra], input=data, capture_output=True,
                       timeout=20)  # fmt: skip
    assert p.returncode in (0, 1), f"tb-robot {mode} {kind} crashed: {p.returncode} {p.stderr!r}"
    assert not p.stderr, p.stderr
    return p


def cpp_decode(kind: str, data: bytes) -> dict | None:
    """The C++ decoding of `data`, or None when it refused."""
    p = cpp("--decode", kind, data, "--robots", str(ROBOTS), "--map-size", "400x400")
    out = p.stdout.decode()
    if p.returncode == 1:
        assert out.startswith("refused: ") and out.count("\n") == 1, out
        return None
    return json.loads(out)


def cpp_encode(kind: str, doc: dict) -> bytes:
    p = cpp("--encode", kind, json.dumps(doc).encode())
    assert p.returncode == 0
    return p.stdout


def py_decode(kind: str, data: bytes):
    """The Python decoding in the C++ decoder's form, or None when it raised ValueError."""
    try:
        if kind == "body":
            m = body.parse(data)
            if m[0] == "frame":
                f = m[1]
                return {"kind": "frame", "step": f.step, "x": f.x, "y": f.y, "theta": f.theta,
                        "sent": f.sent, "ranges": [float(r) for r in f.ranges]}  # fmt: skip
            if m[0] == "hello":
                return {"kind": "hello", "robot": m[1], "role": m[2]}
            if m[0] == "cmd":
                return {"kind": "cmd", "step": m[1], "target": list(m[2]) if m[2] else None}
            if m[0] == "done":
                return {"kind": "done", "step": m[1]}
            return {"kind": m[0]}
        if kind == "flood":
            h, payload = wire.unpack_flood(data)
            return {"kind": h.kind, "ttl": h.ttl, "origin": h.origin, "seq": h.seq,
                    "step": h.step, "sender": h.sender, "neighbours": list(h.neighbours),
                    "payload": len(payload)}  # fmt: skip
        if kind == "map":
            m = wire.unpack_map(data, SHAPE)
            return {"x": m.x, "y": m.y, "r0": m.r0, "c0": m.c0, "h": m.cells.shape[0],
                    "w": m.cells.shape[1],
                    "cells": "".join(str(int(v)) for v in m.cells.reshape(-1))}  # fmt: skip
        if kind == "msg":
            m = wire.parse_msg(data, ROBOTS)
            out = {"k": m["k"], "from": int(m["from"]), "step": int(m["step"]),
                   "goal": list(m["goal"])}  # fmt: skip
            if m["k"] == "goal":
                out.update(cost=m["cost"], fallback=m["fallback"])
            out["n"] = m["n"]
            return out
    except ValueError:
        return None
    raise AssertionError(kind)


def same(a, b) -> bool:
    """Equal, NaN equal to NaN (a frame may carry any float32)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


# ------------------------------------------------------------------ valid, both directions

RANGES = np.array([0.5, np.inf, 1.25, 2.0], dtype=np.float32)
CELLS = np.array([[0, 1, 2, 1], [1, 1, 0, 2], [2, 0, 0, 1]], dtype=np.uint8)

PY_ENCODED = {
    "body": [
        body.frame(17, 1.5, 2.25, 0.5, RANGES, 123.456),
        body.frame(0, 0.0, 0.0, 0.0, None),
        body.hello(3, body.ROLE_ROBOT),
        body.cmd(42, (1.05, 3.35)),
        body.cmd(43, None),
        body.done(99),
        body.END,
    ],
    "flood": [
        wire.pack_flood(wire.FloodHeader(1, 16, 3, 7, 120, 3, (5, 2, 9)), b"xyz"),
        wire.relayed(
            wire.pack_flood(wire.FloodHeader(2, 4, 11, 1, 5, 11, ()), b"12345678"), 3, 4, (1, 2)
        ),  # fmt: skip
    ],
    "map": [
        wire.pack_map(1.25, 2.5, CELLS, 10, 20),
        wire.pack_map(0.0, 0.0, np.zeros((5, 5), np.uint8)),
    ],
    "msg": [
        wire.goal_msg(3, 120, (12.350000000000001, 4.05), 4.2049999, True, 7),
        wire.goal_msg(1, 0, (0.05, 0.15), 0.0),
        wire.replan_msg(2, 121, (7.25, 19.95), 8),
    ],
}


@pytest.mark.parametrize(
    "kind,data", [(k, d) for k, ds in PY_ENCODED.items() for d in ds], ids=lambda v: str(v)[:20]
)
def test_what_python_encodes_cpp_decodes_alike(kind, data):
    py = py_decode(kind, data)
    assert py is not None
    assert same(cpp_decode(kind, data), py)


CPP_DOCS = {
    "body": [
        {"kind": "frame", "step": 17, "x": 1.5, "y": 2.25, "theta": 0.5, "sent": 123.456,
         "ranges": [0.5, 1.25, 2.0]},
        {"kind": "hello", "robot": 3, "role": 0},
        {"kind": "cmd", "step": 42, "target": [1.05, 3.35]},
        {"kind": "cmd", "step": 43, "target": None},
        {"kind": "done", "step": 99},
        {"kind": "end"},
    ],
    "flood": [{"kind_code": 1, "ttl": 16, "origin": 3, "seq": 7, "step": 120, "sender": 3,
               "neighbours": [9, 2, 5], "payload": "xyz"}],
    "map": [{"x": 1.25, "y": 2.5, "r0": 10, "c0": 20, "h": 3, "w": 4, "cells": "012111022001"}],
    "msg": [
        {"kind": "goal", "from": 3, "step": 120, "goal": [12.350000000000001, 4.05],
         "cost": 4.2049999, "fallback": True, "n": 7},
        {"kind": "goal", "from": 1, "step": 0, "goal": [0.05, 0.15], "cost": 0.0},
        {"kind": "replan", "from": 2, "step": 121, "goal": [7.25, 19.95], "n": 8},
    ],
}  # fmt: skip


@pytest.mark.parametrize(
    "kind,doc", [(k, d) for k, ds in CPP_DOCS.items() for d in ds], ids=lambda v: str(v)[:20]
)
def test_what_cpp_encodes_python_decodes_alike(kind, doc):
    data = cpp_encode(kind, doc)
    assert py_decode(kind, data) is not None
    assert same(py_decode(kind, data), cpp_decode(kind, data))


def test_goal_messages_are_the_same_bytes():
    """Python's json.dumps and the C++ writer: the same text for the same goal."""
    for g in ((12.350000000000001, 4.05), (1e-05, 123456789.125), (0.1, 20.0)):
        for cost in (4.2049999, 0.0, 1234.5675, 2.675):
            py = wire.goal_msg(3, 120, g, cost, True, 7)
            doc = {"kind": "goal", "from": 3, "step": 120, "goal": list(g), "cost": cost,
                   "fallback": True, "n": 7}  # fmt: skip
            assert cpp_encode("msg", doc) == py


def test_map_payloads_are_the_same_bytes():
    rng = np.random.default_rng(5)
    for h, w in ((1, 1), (7, 13), (40, 40)):
        t = rng.integers(0, 3, (h, w), dtype=np.uint8)
        t[0, :] = 0  # a box smaller than the window
        py = wire.pack_map(3.5, 4.5, t, 2, 3)
        doc = {"x": 3.5, "y": 4.5, "r0": 2, "c0": 3, "h": h, "w": w,
               "cells": "".join(str(int(v)) for v in t.reshape(-1))}  # fmt: skip
        assert cpp_encode("map", doc) == py


@pytest.mark.parametrize("geometry", [(2.0, 360, 0.05), (1.0, 180, 0.05), (3.3, 361, 0.07)])
def test_the_laser_tables_are_numpys_byte_for_byte(geometry):
    laser = Laser(*geometry)
    laser.prepare_tables()
    parts = [laser.dx.astype(np.float32).tobytes(), laser.dy.astype(np.float32).tobytes(),
             laser.mark.astype(np.uint8).tobytes()]  # fmt: skip
    for bx in range(16):
        for by in range(16):
            sure, odx, ody = laser._table(bx, by)
            n = np.int32(len(odx)).tobytes()
            parts += [sure.astype(np.uint8).tobytes(), n, odx.astype(np.float32).tobytes(),
                      ody.astype(np.float32).tobytes()]  # fmt: skip
    out = subprocess.run([str(TB_ROBOT), "--laser-tables", *map(str, geometry)],
                         capture_output=True, timeout=60, check=True).stdout  # fmt: skip
    assert out == b"".join(parts)


# ------------------------------------------------------------------ malformed, both refuse

SEEDS = {k: [d for d in ds] for k, ds in PY_ENCODED.items()}
SEEDS["map"].append(wire._MAP.pack(1, 2, 0, 0, 3, 3) + zlib.compress(b"\xff\xff\xff"))
SEEDS["msg"] += [b'{"k": "goal", "from": true, "step": 1, "goal": [1, 2], "cost": NaN}',
                 b'{"k": "replan", "from": 2, "step": 1, "goal": [1, 2], "n": false}']  # fmt: skip


def mutated(kind: str):
    seed = st.sampled_from(SEEDS[kind])
    cut = st.tuples(seed, st.integers(0, 64)).map(lambda t: t[0][: max(0, len(t[0]) - t[1])])
    flip = st.tuples(seed, st.integers(0, 10**6), st.integers(1, 255)).map(
        lambda t: t[0] if not t[0] else
        t[0][: t[1] % len(t[0])] + bytes([t[0][t[1] % len(t[0])] ^ t[2]])
        + t[0][t[1] % len(t[0]) + 1 :]
    )  # fmt: skip
    grow = st.tuples(seed, st.binary(max_size=16)).map(lambda t: t[0] + t[1])
    return st.one_of(cut, flip, grow, st.binary(max_size=64))


@pytest.mark.parametrize("kind", ["body", "flood", "map"])
@FUZZ
@given(data=st.data())
def test_malformed_frames_are_refused_alike(kind, data):
    raw = data.draw(mutated(kind))
    py = py_decode(kind, raw)
    assert same(cpp_decode(kind, raw), py)


JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**40), 2**40)
    | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner,
                                                                max_size=4),
    max_leaves=8,
)  # fmt: skip
MESSAGE = st.fixed_dictionaries(
    {"k": st.sampled_from(["goal", "replan", "other", 3])},
    optional={"from": st.one_of(st.integers(-2, 12), st.booleans(), JSONISH),
              "step": st.one_of(st.integers(-2, 10**6), JSONISH),
              "goal": st.one_of(st.lists(st.one_of(st.floats(), st.integers(), st.booleans()),
                                         max_size=3), JSONISH),
              "cost": st.one_of(st.floats(), st.integers(-1, 5), JSONISH),
              "fallback": JSONISH, "n": st.one_of(st.integers(-1, 9), st.booleans(), JSONISH)},
)  # fmt: skip


@FUZZ
@given(msg=MESSAGE)
def test_messages_are_accepted_and_refused_alike(msg):
    raw = json.dumps(msg).encode()  # NaN and Infinity as Python writes them
    assert same(cpp_decode("msg", raw), py_decode("msg", raw))


@FUZZ
@given(data=st.data())
def test_malformed_messages_are_refused_alike(data):
    raw = data.draw(mutated("msg"))  # one contract, whatever the bytes (issue 55)
    assert same(cpp_decode("msg", raw), py_decode("msg", raw))


def test_a_map_window_with_a_bad_cell_is_refused_by_both():
    raw = SEEDS["map"][-1]
    with pytest.raises(ValueError):
        decode_ternary(3, 3, raw[16:])
    assert cpp_decode("map", raw) is None


@pytest.mark.parametrize(
    "argv,stdin",
    [
        (["--decode", "nothing"], b""),
        (["--encode", "msg"], b"not json"),
        (["--encode", "map"], b'{"h": 100000, "w": 100000, "cells": ""}'),
        (["--laser-tables", "0", "360", "0.05"], b""),
        (["--laser-tables", "1e9", "360", "0.05"], b""),
        (["--laser-tables", "2", "x", "0.05"], b""),
    ],
)
def test_bad_self_test_input_is_one_line_and_status_2(argv, stdin):
    p = subprocess.run([str(TB_ROBOT), *argv], input=stdin, capture_output=True, timeout=20)
    assert p.returncode == 2 and p.stderr.count(b"\n") == 1 and p.stderr.startswith(b"node: ")


TOP = wire.MAX_FLOOD_ID
ROBOT_IDS = [(0, 1), (1, 0), (TOP + 1, 1), (1, TOP + 1), (65535, 65535), (TOP, TOP), (1, 2)]


@pytest.mark.parametrize("origin,sender", ROBOT_IDS)
def test_floods_name_robots_of_a_team_alike(origin, sender):
    """A flood's origin and sender are robots 1..MAX_FLOOD_ID (a team's and its display) in
    both robots, before either keeps anything per origin (a peer naming 65,535 origins
    would otherwise grow the duplicate cache without bound)."""
    h = wire.FloodHeader(wire.KIND_MAP, 3, origin, 7, 9, sender, (2,))
    data = wire.pack_flood(h, b"")
    py = py_decode("flood", data)
    assert (py is not None) == (
        1 <= origin <= wire.MAX_FLOOD_ID and 1 <= sender <= wire.MAX_FLOOD_ID
    )
    if TB_ROBOT.exists():
        assert cpp_decode("flood", data) == py
