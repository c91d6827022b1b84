"""The feed against careless input, end to end on a real network: a last line without its
newline, coordinates that are not finite or absurd, a line without end."""

import os
import subprocess
import sys
import time

import pytest

from topology import state

TESTBED = [sys.executable, "-m", "testbed.cli"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def tb(*args, **kw) -> subprocess.CompletedProcess:
    kw.setdefault("capture_output", True)
    kw.setdefault("cwd", REPO)
    return subprocess.run(TESTBED + list(args), **kw)


@pytest.fixture
def net_up(tb_name):
    """Two robots, r1 at (0, 0) and r2 at (8, 0), no routing; down at the end."""
    r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10", text=True)
    assert r.returncode == 0, r.stderr
    yield tb_name
    assert tb("net", "down", tb_name).returncode == 0


def positions(name: str) -> list[list[float]]:
    return state.read(name).positions


def test_a_last_line_without_newline_is_that_line_and_never_joined_to_itself(net_up):
    r = tb("net", "feed", net_up, input=b"2 12 0", text=False)
    assert r.returncode == 0, r.stderr
    assert positions(net_up) == [[0.0, 0.0], [12.0, 0.0]]
    r = tb("net", "feed", net_up, input=b"1 5", text=False)  # two fields: refused
    assert r.returncode == 2 and b"2 fields" in r.stderr and b"Traceback" not in r.stderr
    assert positions(net_up) == [[0.0, 0.0], [12.0, 0.0]]  # r1 was not moved to (51, 5)


@pytest.mark.parametrize("line", [b"1 -1e308 1e308\n", b"1 nan 0\n", b"1 3e7 0\n"])
def test_coordinates_that_are_not_finite_or_absurd_are_refused(net_up, line):
    r = tb("net", "feed", net_up, input=line, text=False)
    assert r.returncode == 2 and b"Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert positions(net_up) == [[0.0, 0.0], [8.0, 0.0]]


def test_a_100_mb_line_is_refused_at_once(net_up):
    t0 = time.monotonic()
    r = tb("net", "feed", net_up, input=b"7" * (100 << 20), text=False, timeout=30)
    assert r.returncode == 2 and b"longer than 4096 bytes" in r.stderr, r.stderr
    assert time.monotonic() - t0 < 10  # joining the buffer to every read took 73 s of CPU
