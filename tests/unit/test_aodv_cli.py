"""`python -m aodv` command line: help, and bad input as one line with exit status 2."""

import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(*argv):
    return subprocess.run(
        [sys.executable, "-m", "aodv", *argv], capture_output=True, text=True, cwd=REPO
    )


def test_help():
    proc = run("--help")
    assert proc.returncode == 0
    for flag in ("--robot", "--iface", "--time-scale", "--profile", "--set", "--state"):
        assert flag in proc.stdout


@pytest.mark.parametrize(
    "argv",
    [
        [],
        ["--robot"],
        ["--robot", "r1", "--time-scale", "0"],
        ["--robot", "r1", "--time-scale", "fast"],
        ["--robot", "r1", "--log-level", "loud"],
        ["--robot", "r1", "--net", "10.0.0.300/16"],
        ["--robot", "r1", "--profile", "olsr"],
        ["--robot", "r1", "--set", "my_route_timeout_ms=6000"],  # < 2 * PATH_DISCOVERY_TIME
        ["--robot", "r1", "--set", "ttl_start=9"],  # above TTL_THRESHOLD
        ["--robot", "r1", "--set", "nonsense=1"],
        ["--robot", "r1", "--set", "ttl_start=two"],
        ["--robot", "r1", "--set", "local_repair=maybe"],
    ],
)
def test_bad_cli_is_one_line_and_status_2(argv):
    proc = run(*argv)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr


def test_every_log_line_names_the_robot_even_tracebacks():
    import logging

    from aodv.__main__ import RobotFormatter

    try:
        raise RuntimeError("boom")
    except RuntimeError:
        rec = logging.LogRecord("aodv.x", logging.ERROR, __file__, 1, "failed %s", ("x",), None)
        rec.exc_info = sys.exc_info()
    lines = RobotFormatter("r7").format(rec).splitlines()
    assert len(lines) > 3 and all(line.startswith("r7 ") for line in lines)
