"""Map files and laser ranges a run can be asked for: a map is sized from its PNG header
before it is decoded (topology.inputs.pngmap), damaged files are one line of ours and nothing of
libpng's, and a laser's cost in `prepare` is bounded and interruptible. No root."""

import json
import os
import re
import signal
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from common.errors import UsageError
from testbed.files.runconfig import RunConfig
from testbed.run.arguments import config_from_args
from testbed.world.worldmap import empty_terrain, load_png
from topology.radio.los import MapError, Walls

REPO = Path(__file__).resolve().parents[2]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
OFFICE = REPO / "testbed" / "experiments" / "maps" / "office.png"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def huge_white_png(path: Path, side: int) -> None:
    """A side x side one-bit white PNG, compressed as it is made (a few kB on disk)."""
    z = zlib.compressobj(9)
    row = b"\x00" + b"\xff" * ((side + 7) // 8)
    block = row * 1000
    idat = b"".join(z.compress(block) for _ in range(side // 1000)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", side, side, 1, 0, 0, 0, 0)
    path.write_bytes(PNG_SIGNATURE + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat)
                     + _chunk(b"IEND", b""))  # fmt: skip


def in_child(code: str) -> tuple[dict, str]:
    """Run `code` in a fresh interpreter; (the JSON it printed last, its stderr)."""
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    return json.loads(r.stdout.strip().splitlines()[-1]), r.stderr


def test_a_huge_png_is_refused_from_its_header_without_decoding(tmp_path):
    big = tmp_path / "big.png"
    huge_white_png(big, 20000)  # 400 million pixels: 849 MB to decode
    out, err = in_child(f"""
        import json
        from common.errors import UsageError
        from testbed.world.worldmap import load_png
        from topology.radio.los import MapError, Walls
        said = []
        loads = (lambda: load_png({str(big)!r}, 0.01), lambda: Walls.from_png({str(big)!r}, 0.05))
        for load in loads:
            try:
                load()
                said.append("accepted")
            except (UsageError, MapError) as exc:
                said.append(str(exc))
        # VmHWM, not ru_maxrss: exec carries pytest's own peak over into ru_maxrss
        rss = int(open('/proc/self/status').read().split('VmHWM:')[1].split()[0]) / 1024
        print(json.dumps({{"said": said, "rss_mb": rss}}))
    """)  # fmt: skip
    refusal = f"map file {big} is 20000 x 20000 pixels, more than the 16,000,000 a map may have"
    assert out["said"] == [refusal, refusal]  # the world's map, and the los models' walls
    assert out["rss_mb"] < 250, out  # imports only: nothing was decoded
    assert err == ""


def test_the_largest_map_the_world_takes_is_stated_and_checked_before_decoding(tmp_path):
    from testbed.world.worldmap import png_cells

    big = tmp_path / "wide.png"
    huge_white_png(big, 5000)  # 25 million pixels, 5000 cells a side at 5 cm
    with pytest.raises(UsageError, match="is 5000 x 5000 pixels, more than the 16,000,000"):
        png_cells(str(big), 0.05)
    side = tmp_path / "side.png"
    cv2.imwrite(str(side), np.full((10, 4001), 255, np.uint8))
    with pytest.raises(UsageError, match=r"too large \(4001 x 10 cells of 5 cm; at most 4000"):
        load_png(str(side), 0.05)
    assert png_cells(str(OFFICE), 0.05) == (400, 400)


@pytest.mark.parametrize("cut", [0.3, 0.9, -12])
def test_a_truncated_png_is_one_line_of_ours_and_nothing_from_libpng(tmp_path, cut):
    src = tmp_path / "noise.png"
    rng = np.random.default_rng(1)
    cv2.imwrite(str(src), (rng.random((400, 400)) * 255).astype(np.uint8))
    data = src.read_bytes()
    bad = tmp_path / "cut.png"
    bad.write_bytes(data[: int(len(data) * cut)] if cut > 0 else data[:cut])
    out, err = in_child(f"""
        import json
        from common.errors import UsageError
        from testbed.world.worldmap import load_png
        try:
            load_png({str(bad)!r}, 0.05)
            print(json.dumps({{"said": "accepted"}}))
        except UsageError as exc:
            print(json.dumps({{"said": str(exc)}}))
    """)  # fmt: skip
    assert err == ""  # libpng printed "libpng error: Read Error" here
    assert out["said"] == f"map file {bad} is truncated (it ends before its IEND chunk)" or (
        re.fullmatch(
            rf"map file {re.escape(str(bad))} is truncated \(its b'IDAT' chunk is cut "
            r"short\)",
            out["said"],
        )  # fmt: skip
    )


def test_a_damaged_png_is_named_as_such(tmp_path):
    data = bytearray(OFFICE.read_bytes())
    data[100] ^= 0xFF  # inside the first IDAT
    bad = tmp_path / "crc.png"
    bad.write_bytes(bytes(data))
    with pytest.raises(UsageError, match=r"is damaged \(a CRC error in its b'IDAT' chunk\)"):
        load_png(str(bad), 0.05)


def test_a_directory_fifo_or_other_file_as_map_says_what_it_is(tmp_path):
    with pytest.raises(UsageError, match=f"map file {tmp_path} is a directory, not a PNG"):
        load_png(str(tmp_path), 0.05)
    with pytest.raises(MapError, match="is a directory, not a PNG"):
        Walls.from_png(str(tmp_path), 0.05)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(UsageError, match="is not a regular file"):
        load_png(str(fifo), 0.05)
    jpeg = tmp_path / "map.jpg"
    cv2.imwrite(str(jpeg), np.full((20, 20), 255, np.uint8))
    with pytest.raises(UsageError, match="is not a PNG"):
        load_png(str(jpeg), 0.05)
    with pytest.raises(UsageError, match="does not exist"):
        load_png(str(tmp_path / "none.png"), 0.05)


def test_the_shipped_map_loads_as_before():
    truth = load_png(str(OFFICE), 0.05)
    img = cv2.imread(str(OFFICE), cv2.IMREAD_GRAYSCALE)
    inner = truth.occupied[1:-1, 1:-1]
    assert truth.shape == img.shape and (inner == (img < 128)[1:-1, 1:-1]).all()
    assert (Walls.from_png(str(OFFICE), 0.05).occupied == (img < 128)).all()


# ---------------------------------------------------------------- the laser


def test_a_laser_beyond_30_m_or_the_maps_diagonal_is_refused():
    import argparse

    from testbed.cli import build_parser
    from testbed.run.prepare import check_laser

    with pytest.raises(UsageError, match="laser range must be at most 30, not 100"):
        build_parser(["run"]).parse_args(["run", "--robots", "1", "--comm-range", "5",
                                          "--laser-range", "100", "--out", "x"])  # fmt: skip
    with pytest.raises(UsageError, match=re.escape(
        "--laser-range 29 is longer than the map's diagonal (28.3 m on 20 x 20 m)"
    )):  # fmt: skip
        check_laser(29.0, empty_terrain().size_m)
    check_laser(28.0, empty_terrain().size_m)
    args = build_parser(["run"]).parse_args(
        ["run", "--robots", "1", "--comm-range", "5", "--laser-range", "30", "--out", "x"]
    )
    assert isinstance(args, argparse.Namespace) and config_from_args(args).laser_range == 30


def test_open_space_from_the_distance_transform_is_the_disc_dilation():
    """The cells the world takes as open (no obstacle within reach) are exactly those the
    dilation by a disc found, on random maps and reaches."""
    from testbed.world.world import open_cells

    rng = np.random.default_rng(5)
    for _ in range(30):
        occ = rng.random((rng.integers(5, 60), rng.integers(5, 60))) < rng.uniform(0.001, 0.05)
        reach = int(rng.integers(1, 40))
        blocked = np.pad(occ, reach, constant_values=True).astype(np.uint8)
        yy, xx = np.mgrid[: 2 * reach + 1, : 2 * reach + 1] - reach
        disc = ((yy * yy + xx * xx) <= reach * reach).astype(np.uint8)
        want = cv2.dilate(blocked, disc)[reach:-reach, reach:-reach] == 0
        ring = np.pad(occ, 1, constant_values=True)
        clear = cv2.distanceTransform((~ring).astype(np.uint8), cv2.DIST_L2,
                                      cv2.DIST_MASK_PRECISE)  # fmt: skip
        assert (open_cells(clear[1:-1, 1:-1], reach) == want).all()


PREPARE_WORLD = """
    import time, numpy as np
    from node.rays import Laser
    from testbed.world.world import World
    from testbed.world.worldmap import CELL, GroundTruth, free_space, start_positions
    occ = np.zeros(({side}, {side}), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    truth = GroundTruth(occ, CELL)
    starts = start_positions(truth, 2, np.random.default_rng(1), 0.15, "corner")
    print("go", flush=True)
    t = time.monotonic()
    World(truth, starts, Laser({laser}, 360, truth.cell), free_space(truth, starts))
    print(time.monotonic() - t, flush=True)
"""


def test_the_longest_laser_the_default_map_takes_is_prepared_in_bounded_time():
    code = textwrap.dedent(PREPARE_WORLD.format(side=400, laser=28))
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                         timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr[-500:]
    assert float(out.stdout.split()[-1]) < 3.0  # it was 31 s, most of it one C call


def _default_sigint():  # in the child: Python's own SIGINT handler, whatever the parent had
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_prepare_stops_at_once_on_sigint():
    """The largest map with a long laser: SIGINT in the middle of building its world stops
    it within a second or two (each step of the work is a short C call)."""
    code = textwrap.dedent(PREPARE_WORLD.format(side=4000, laser=28))
    p = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)  # fmt: skip
    try:
        assert p.stdout.readline().strip() == "go"
        # The preparation takes about 0.25 s on a quiet 2-core machine (31 s once): the signal
        # goes at once, so that it lands in the middle of the work on a fast machine too.
        time.sleep(0.02)
        p.send_signal(signal.SIGINT)
        t = time.monotonic()
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pytest.fail("still preparing 10 s after SIGINT")
        waited = time.monotonic() - t
    finally:
        p.kill()
        rest, err = p.communicate()
    assert rest == "" and "KeyboardInterrupt" in err  # interrupted, not finished by then
    assert waited < 2.0


def test_a_config_records_the_laser_bound_for_sweeps():
    from testbed.files.options import check_value
    from testbed.files.runconfig import BY_NAME

    assert (
        check_value(BY_NAME["laser_range"], 31) == "value 31 out of range (must be > 0 and <= 30)"
    )
    assert RunConfig(robots=1, comm_range=1.0, laser_range=30.0).laser_range == 30.0


def test_line_of_sight_between_far_robots_costs_what_the_map_costs():
    """Robots 1e9 m apart (a feed, a trace, --positions) across a 10 m map: the segment is
    cut to the map first, so its walls are counted in microseconds, not 2e10 samples."""
    from topology.radio.los import crossings

    occ = np.zeros((100, 100), dtype=bool)
    occ[:, 30:32] = occ[:, 60:62] = True  # two walls, at 3 m and 6 m
    walls = Walls(occ, 0.1)
    far = [((-1e9, 5.0), (1e9, 5.0)), ((1.0, 5.0), (1e12, 5.0)), ((1.0, -1e9), (1.0, 1e9)),
           ((-5.0, -5.0), (-1e6, -1e6)), ((4.5, 5.0), (4.5, 5.0))]  # fmt: skip
    t = time.perf_counter()
    assert crossings(walls, far) == [2, 2, 0, 0, 0]
    assert time.perf_counter() - t < 0.5
