"""Issue 55's hostile body frames and forged flood sequence numbers, kept as tests: the Python
robot (node.body, node.flood) and the C++ robot (`tb-robot --decode frame`, `--decode
floodseq`: native/robot/body.cc, flood.cc) given the same inputs give the same verdict, and
the verdict is docs/robot-contract.md's (sections 1 and 2).

Before: a frame at NaN, 3.4e38, -100 or just off the map ended a live Python robot (status 3)
while the C++ robot counted or scanned it; one flood claiming origin 2 with sequence number
2^32 - 1 made origin 2's real floods 1 and 2 duplicates, dropped without a count, in both."""

from __future__ import annotations

import math
import select
import socket
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from common.paths import PROJECT_ROOT
from node import body, constgen, flood, wire
from node.native import TB_ROBOT, unbuilt_reason

needs_cpp = pytest.mark.skipif(unbuilt_reason() is not None, reason=str(unbuilt_reason()))
FUZZ = settings(max_examples=120, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
WIDTH, HEIGHT, RAYS = 20.0, 10.0, 8  # a 400 x 200 map of 5 cm cells, an 8-ray laser
OK, REFUSED = "ok", "refused"
TOP = 2**32 - 1


def frame(x, y, theta=0.0, sent=1.0, n=RAYS, step=7) -> bytes:
    return body.frame(step, x, y, theta, np.full(n, np.inf, np.float32), sent)


def py_frame(data: bytes) -> str:
    """The Python robot's verdict: its body link's parse, then check_frame."""
    try:
        msg = body.parse(data)
        if msg[0] != "frame":
            return REFUSED
        body.check_frame(msg[1], WIDTH, HEIGHT, RAYS)
    except ValueError:
        return REFUSED
    return OK


def cpp_frame(data: bytes) -> str:
    p = subprocess.run([str(TB_ROBOT), "--decode", "frame", f"{WIDTH}x{HEIGHT}", str(RAYS)],
                       input=data, capture_output=True, timeout=20)  # fmt: skip
    out = p.stdout.decode()
    assert not p.stderr, p.stderr
    assert (p.returncode, out) == (0, "ok\n") or (
        p.returncode == 1 and out.startswith("refused: ") and out.count("\n") == 1
    ), (p.returncode, out)
    return OK if p.returncode == 0 else REFUSED


# The round's frames: what each robot must do with them (docs/robot-contract.md, section 1).
HOSTILE_FRAMES = [
    ("x NaN", frame(math.nan, 1.0), REFUSED),
    ("y NaN", frame(1.0, math.nan), REFUSED),
    ("x +inf", frame(math.inf, 1.0), REFUSED),
    ("y -inf", frame(1.0, -math.inf), REFUSED),
    ("x 3.4e38", frame(3.4e38, 1.0), REFUSED),
    ("y -3.4e38", frame(1.0, -3.4e38), REFUSED),
    ("x -100", frame(-100.0, 1.0), REFUSED),
    ("y -100", frame(1.0, -100.0), REFUSED),
    ("x just off the map", frame(WIDTH + 0.01, 1.0), REFUSED),
    ("x on the far edge", frame(WIDTH, 1.0), REFUSED),
    ("y on the far edge", frame(1.0, HEIGHT), REFUSED),
    ("x one ulp below 0", frame(-1e-45, 1.0), REFUSED),
    ("theta NaN", frame(1.0, 1.0, theta=math.nan), REFUSED),
    ("sent +inf", frame(1.0, 1.0, sent=math.inf), REFUSED),
    ("sent NaN", frame(1.0, 1.0, sent=math.nan), REFUSED),
    ("no ranges", frame(1.0, 1.0, n=0), REFUSED),
    ("one ray too many", frame(1.0, 1.0, n=RAYS + 1), REFUSED),
    ("on the map", frame(1.0, 1.0), OK),
    ("the origin", frame(0.0, 0.0), OK),
    ("minus zero", frame(-0.0, -0.0), OK),
    ("just inside the far corner", frame(19.99, 9.99), OK),
    ("a heading of 1e30", frame(1.0, 1.0, theta=1e30), OK),
    ("sent 0 (not given)", frame(1.0, 1.0, sent=0.0), OK),
    ("ranges of 1e30 and NaN", body.frame(7, 1.0, 1.0, 0.0, np.array(
        [1e30, -1e30, np.nan, -np.inf, 3.4e38, 0, -0.0, 1.0], np.float32), 1.0), OK),
]  # fmt: skip


@pytest.mark.parametrize(("name", "data", "verdict"), HOSTILE_FRAMES,
                         ids=[c[0] for c in HOSTILE_FRAMES])  # fmt: skip
def test_the_rounds_frames_python(name, data, verdict):
    assert py_frame(data) == verdict


@needs_cpp
@pytest.mark.parametrize(("name", "data", "verdict"), HOSTILE_FRAMES,
                         ids=[c[0] for c in HOSTILE_FRAMES])  # fmt: skip
def test_the_rounds_frames_cpp(name, data, verdict):
    assert cpp_frame(data) == verdict


coordinate = st.one_of(
    st.floats(width=32),
    st.sampled_from([0.0, -0.0, WIDTH, HEIGHT, -1e-45, 1e-45, 19.999998, 9.999999, -100.0]),
    st.floats(-1.0, WIDTH + 1.0, width=32),
)


@needs_cpp
@FUZZ
@given(coordinate, coordinate, st.floats(width=32), st.floats(),
       st.sampled_from([0, RAYS - 1, RAYS, RAYS + 1]))  # fmt: skip
@example(math.nan, 1.0, 0.0, 1.0, RAYS)
@example(3.4e38, 1.0, 0.0, 1.0, RAYS)
def test_both_robots_take_or_refuse_the_same_frames(x, y, theta, sent, n):
    data = frame(x, y, theta, sent, n)
    assert cpp_frame(data) == py_frame(data)


def test_the_body_link_refuses_a_frame_off_the_map_once_told_the_map(tmp_path):
    """BodyClient.recv after expect(): the frame check's ValueError, which the motion loop
    counts as malformed; before expect() (the display's link) only parse's."""
    path = str(tmp_path / "body.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    srv.bind(path)
    srv.listen(1)
    client = body.BodyClient(path, 1)
    conn, _ = srv.accept()
    try:
        conn.send(frame(-100.0, 1.0))
        assert client.recv(timeout=5)[0] == "frame"  # not told the map yet
        client.expect(WIDTH, HEIGHT, RAYS)
        for data in (frame(-100.0, 1.0), frame(3.4e38, 1.0), frame(1.0, 1.0, n=3)):
            conn.send(data)
            with pytest.raises(ValueError):
                client.recv(timeout=5)
        conn.send(frame(math.nan, 1.0))
        with pytest.raises(ValueError, match="not finite"):
            client.recv(timeout=5)
        conn.send(frame(2.0, 3.0))
        got = client.recv(timeout=5)
        assert got[0] == "frame" and (got[1].x, got[1].y) == (2.0, 3.0)
    finally:
        client.close()
        conn.close()
        srv.close()


# Flood sequence numbers (docs/robot-contract.md, section 2).


def py_seqs(pairs: list[tuple[int, int]]) -> list[str]:
    cache = flood.DuplicateCache()
    return [cache.check(o, s) for o, s in pairs]


def cpp_seqs(pairs: list[tuple[int, int]]) -> list[str]:
    text = "".join(f"{o} {s}\n" for o, s in pairs).encode()
    p = subprocess.run([str(TB_ROBOT), "--decode", "floodseq"], input=text,
                       capture_output=True, timeout=20)  # fmt: skip
    assert p.returncode == 0 and not p.stderr, (p.returncode, p.stderr)
    return p.stdout.decode().split()


W = flood.SEQ_WINDOW
SEQ_CASES = [
    # The issue's forgery: 2^32 - 1 from origin 2, then origin 2's real 1 and 2.
    ("forged top, then the real ones", [(2, TOP), (2, 1), (2, 2)], ["new", "new", "new"]),
    # After the real ones, the forgery again: older than the highest (wrap-around).
    ("forged top after", [(2, 1), (2, 2), (2, TOP), (2, 3)], ["new", "new", "new", "new"]),
    ("half the space away", [(2, 2**31), (2, 1), (2, 2)], ["forged", "new", "new"]),
    ("far ahead of the highest", [(2, 5), (2, 5 + W + 1), (2, 6)], ["new", "forged", "new"]),
    ("the edge of the window", [(2, W), (2, W + 1), (3, W + 1)], ["new", "new", "forged"]),
    ("far behind", [(2, W), (2, 1)], ["new", "duplicate"]),
    ("a repeat", [(4, 9), (4, 9), (4, 8), (4, 8)], ["new", "duplicate", "new", "duplicate"]),
    ("older than the 256 kept", [(4, 300), (4, 44), (4, 45)], ["new", "duplicate", "new"]),
    ("wrapping", [(5, TOP - 1), (5, TOP), (5, 0), (5, 1), (5, TOP)],
     ["new", "new", "new", "new", "duplicate"]),
    ("zero first", [(6, 0), (6, 0), (6, 1)], ["new", "duplicate", "new"]),
]  # fmt: skip


@pytest.mark.parametrize(("name", "pairs", "want"), SEQ_CASES, ids=[c[0] for c in SEQ_CASES])
def test_the_rounds_sequence_numbers_python(name, pairs, want):
    assert py_seqs(pairs) == want


@needs_cpp
@pytest.mark.parametrize(("name", "pairs", "want"), SEQ_CASES, ids=[c[0] for c in SEQ_CASES])
def test_the_rounds_sequence_numbers_cpp(name, pairs, want):
    assert cpp_seqs(pairs) == want


seq = st.one_of(
    st.integers(0, 600),
    st.integers(0, TOP),
    st.sampled_from([TOP, TOP - 1, 2**31, 2**31 - 1, 2**31 + 1, W, W + 1, W - 1, W + 257]),
    st.integers(TOP - 600, TOP),
)


@needs_cpp
@FUZZ
@given(st.lists(st.tuples(st.integers(1, 3), seq), max_size=60))
def test_both_robots_flood_filters_give_the_same_verdicts(pairs):
    assert cpp_seqs(pairs) == py_seqs(pairs)


@FUZZ
@given(st.integers(0, TOP), st.integers(0, TOP))
def test_seq_diff_is_rfc_3561s(a, b):
    d = flood.seq_diff(a, b)
    assert -(2**31) <= d < 2**31 and (b + d) % 2**32 == a
    assert d == struct.unpack("!i", struct.pack("!I", (a - b) % 2**32))[0]


def test_the_window_is_stated_once_and_covers_a_run():
    from testbed.files.runconfig import MAX_STEPS

    assert MAX_STEPS < flood.SEQ_WINDOW < 2**31
    contract = (Path(PROJECT_ROOT) / "docs" / "robot-contract.md").read_text()
    assert contract.count("2^24 = 16,777,216") == 1
    assert flood.SEQ_WINDOW == 16_777_216
    header = (Path(PROJECT_ROOT) / "native" / "robot" / "flood.h").read_text()
    assert "using gen::SEQ_WINDOW;" in header  # node.constgen's, from flood.SEQ_WINDOW
    assert "constexpr int64_t SEQ_WINDOW = INT64_C(16777216);" in constgen.header()


def test_a_forged_flood_is_counted_and_silences_nobody():
    """Through a real Flooder on the loopback: origin 2's real floods 1 and 2 get through
    after floods claiming 2^32 - 1 and 2^31; the one not believed is counted."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    f = flood.Flooder(1, port, iface=None)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for s in (TOP, 2**31, 1, 2):
            h = wire.FloodHeader(wire.KIND_BEACON, 1, 2, s, 5, 3, ())
            tx.sendto(wire.pack_flood(h, wire.pack_beacon(1.0, 1.0)), ("127.0.0.1", port))
        got: list[bytes] = []
        for _ in range(200):
            got += f.receive_raw()
            if len(got) == 3 and f.counts["forged"]:
                break
            select.select([f.fileno()], [], [], 0.05)
        seqs = [wire.flood_ids(d)[2] for d in got]
        assert seqs == [TOP, 1, 2]
        assert f.counts["forged"] == 1 and f.counts["malformed"] == 1
        assert f.counts["duplicate"] == 0
    finally:
        tx.close()
        f.close()
