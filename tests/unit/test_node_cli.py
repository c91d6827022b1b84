"""Bad command-line input: one line on stderr and exit status 2, never a traceback."""

import subprocess
import sys

import pytest

from testbed import PROJECT_ROOT


def run(argv):
    return subprocess.run(
        [sys.executable, *argv], capture_output=True, text=True, cwd=PROJECT_ROOT, timeout=60
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["-m", "node", "--robot", "x3", "--robots", "2", "--body", "/nonexistent"],
        ["-m", "node", "--robot", "r1", "--robots", "0", "--body", "/nonexistent"],
        ["-m", "node", "--robot", "r1", "--robots", "2", "--body", "/x", "--map-size", "4"],
        ["-m", "testbed.run.execute", "--robots", "2", "--comm-range", "-5", "--out", "/tmp/x"],
        ["-m", "testbed.run.execute", "--robots", "two", "--comm-range", "5", "--out", "/tmp/x"],
        ["-m", "testbed.run.execute", "--robots", "2", "--comm-range", "5", "--out", "/tmp/x",
         "--routing", "olsr"],
        ["-m", "testbed.run.execute", "--robots", "2", "--comm-range", "5", "--out", "/tmp/x",
         "--kill", "r9:10"],
        ["-m", "testbed.run.execute", "--robots", "2", "--comm-range", "5", "--out", "/tmp/x",
         "--map", "/nonexistent.png"],
        ["-m", "node", "--robot", "r1", "--robots", "2", "--body", "/nonexistent", "--maps",
         "pubsub", "--middleware", "zeromq"],
        ["-m", "node", "--robot", "r1", "--robots", "2", "--body", "/nonexistent", "--maps",
         "gossip"],
    ],
)  # fmt: skip
def test_bad_arguments_exit_2_with_one_line(argv):
    p = run(argv)
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "Traceback" not in p.stderr


def test_the_robot_refuses_maps_pubsub_without_a_pubsub_middleware():
    p = run(["-m", "node", "--robot", "r1", "--robots", "2", "--body", "/nonexistent",
             "--maps", "pubsub", "--middleware", "nanomsg"])  # fmt: skip
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "node: --maps pubsub needs --middleware zenoh or dds (not nanomsg): maps are published "
        "on their topics"
    ]
