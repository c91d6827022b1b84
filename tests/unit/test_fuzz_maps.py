"""Map PNGs from anywhere (topology.inputs.pngmap) and line of sight across them
(topology.radio.los), fuzzed with Hypothesis.

A map file either decodes to a grey picture of exactly the size its header states, within
MAX_MAP_PIXELS, or is refused with a `PngError` of one printable line; and whichever it is,
nothing reaches the terminal from libpng (file descriptor 2 stays silent). Inputs: valid
PNGs mutated (bytes flipped, cut, chunks inserted), PNG headers claiming any size, and
arbitrary bytes. Line of sight: for segments inside the map, cutting segments to the map
changes nothing (the count equals the plain per-cell sampling's); for robots anywhere at
all (up to 1e12 m apart) the count is a whole number no larger than the walls there are,
found in bounded time. 750 examples in all.
"""

import struct
import time
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from topology.inputs import pngmap
from topology.radio.los import Walls, crossings

BASE = settings(deadline=2000, database=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])  # fmt: skip


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


RNG = np.random.default_rng(3)
SEEDS = [
    _png(np.full((8, 8), 255, np.uint8)),
    _png((RNG.random((40, 30)) * 255).astype(np.uint8)),
    _png((RNG.random((16, 16, 3)) * 255).astype(np.uint8)),
    _png((RNG.random((12, 20, 4)) * 65535).astype(np.uint16)),
]


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


@st.composite
def mutated_pngs(draw) -> bytes:
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["flip", "cut", "insert", "chunk"]))
        at = draw(st.integers(0, len(data)))
        if how == "flip" and at < len(data):
            data[at] ^= draw(st.integers(1, 255))
        elif how == "cut":
            del data[at:]
        elif how == "insert":
            data[at:at] = draw(st.binary(max_size=8))
        else:  # a well-formed chunk where none belongs
            kind = draw(st.sampled_from([b"IHDR", b"IDAT", b"IEND", b"tEXt", b"zzzz"]))
            data[at:at] = _chunk(kind, draw(st.binary(max_size=16)))
    return bytes(data)


@st.composite
def claimed_sizes(draw) -> bytes:
    """A PNG whose header claims any size (its pixels never match)."""
    w, h = draw(st.integers(0, 2**32 - 1)), draw(st.integers(0, 2**32 - 1))
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    idat = zlib.compress(b"\x00" * draw(st.integers(0, 64)))
    return pngmap.SIGNATURE + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


@pytest.fixture(scope="module")
def where(tmp_path_factory):
    return tmp_path_factory.mktemp("maps")


def check(where, content: bytes) -> None:
    f = where / "map.png"
    f.write_bytes(content)
    try:
        img = pngmap.read_gray(str(f))
    except pngmap.PngError as exc:
        msg = str(exc)
        assert msg.startswith(f"map file {f}") and msg.isprintable(), msg
        event("refused")
        return
    event("accepted")
    width, height = struct.unpack(">II", content[16:24])
    assert img.dtype == np.uint8 and img.shape == (height, width)
    assert width * height <= pngmap.MAX_MAP_PIXELS


@settings(BASE, max_examples=400)
@given(st.one_of(mutated_pngs(), st.sampled_from(SEEDS)))
def test_mutated_pngs(where, capfd, content):
    check(where, content)
    assert capfd.readouterr().err == ""  # libpng said nothing of its own


@settings(BASE, max_examples=100)
@given(claimed_sizes())
def test_any_claimed_size(where, capfd, content):
    t = time.perf_counter()
    check(where, content)
    assert time.perf_counter() - t < 0.5
    assert capfd.readouterr().err == ""


@settings(BASE, max_examples=100)
@given(st.binary(max_size=200).map(lambda b: pngmap.SIGNATURE + b if b[:1] == b"\x00" else b))
def test_arbitrary_bytes(where, capfd, content):
    check(where, content)
    assert capfd.readouterr().err == ""


# ---------------------------------------------------------------- line of sight


def reference_crossings(walls: Walls, pairs) -> list[int]:
    """Walls crossed, sampling every cell of each whole segment (no cutting to the map)."""
    out = []
    for a, b in pairs:
        (ax, ay), (bx, by) = np.array(a) / walls.cell, np.array(b) / walls.cell
        n = int(np.ceil(np.hypot(bx - ax, by - ay))) + 2
        t = np.arange(n) / (n - 1)
        h, w = walls.occupied.shape
        rows = np.clip(np.floor(ay + (by - ay) * t), -1, h).astype(int)
        cols = np.clip(np.floor(ax + (bx - ax) * t), -1, w).astype(int)
        hit = walls.padded[rows + 1, cols + 1]
        out.append(int(np.sum(hit & ~np.concatenate([[False], hit[:-1]]))))
    return out


OCC = np.zeros((60, 80), dtype=bool)
OCC[:, 20:23] = OCC[:, 50:52] = OCC[30:33, :] = True  # two walls across, one along
WALLS = Walls(OCC, 0.1)  # 8 x 6 m
INSIDE = st.tuples(st.floats(0, 7.99), st.floats(0, 5.99))
ANYWHERE = st.tuples(st.floats(-1e12, 1e12), st.floats(-1e12, 1e12))


@settings(BASE, max_examples=100)
@given(st.lists(st.tuples(INSIDE, INSIDE), min_size=1, max_size=8))
def test_segments_inside_the_map_count_as_before(pairs):
    assert crossings(WALLS, pairs) == reference_crossings(WALLS, pairs)


@settings(BASE, max_examples=50)
@given(st.lists(st.tuples(st.one_of(INSIDE, ANYWHERE), ANYWHERE), min_size=1, max_size=8))
def test_robots_anywhere_cost_what_the_map_costs(pairs):
    t = time.perf_counter()
    counts = crossings(WALLS, pairs)
    assert time.perf_counter() - t < 0.2
    assert all(isinstance(c, int) and 0 <= c <= 4 for c in counts)
