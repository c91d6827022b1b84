"""`net up` against careless input: a busy view port, a view asked for a robot that is not
there, and a trace's link timeline that must outlive `net down`."""

import csv
import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

from topology import state
from topology.kernel import netns

TESTBED = [sys.executable, "-m", "testbed.cli"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TRACE = """\
$node_(0) set X_ 0.0
$node_(0) set Y_ 0.0
$node_(1) set X_ 5.0
$node_(1) set Y_ 0.0
$ns_ at 0.2 "$node_(1) setdest 30.0 0.0 100.0"
"""


def tb(*args, cwd=REPO) -> subprocess.CompletedProcess:
    return subprocess.run(TESTBED + list(args), capture_output=True, text=True, cwd=cwd)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def status(url: str) -> int:
    """The HTTP status of GET url (the view is given a few seconds to listen)."""
    deadline = time.monotonic() + 10
    while True:
        try:
            return urllib.request.urlopen(url, timeout=5).status
        except urllib.error.HTTPError as e:
            return e.code
        except urllib.error.URLError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def test_a_busy_view_port_is_one_line_and_exit_2_with_nothing_made(tb_name):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10", "--view", str(port))
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "cannot listen there" in r.stderr
    assert "http://" not in r.stdout
    assert not netns.exists(f"tb-{tb_name}-m") and state.read(tb_name) is None


def test_the_view_answers_a_route_query_for_no_robot_with_http_400(tb_name):
    port = free_port()
    r = tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10", "--routing", "oracle",
           "--view", str(port))  # fmt: skip
    assert r.returncode == 0, r.stderr
    try:
        base = f"http://127.0.0.1:{port}/api/routes?to="
        for bad in ("0", "3", "99999999999999999999", "%C2%B2"):
            assert status(base + bad) == 400, bad
        assert status(base + "1") == 200
        assert json.loads(urllib.request.urlopen(base + "1", timeout=5).read()) == {"2": 1}
    finally:
        assert tb("net", "down", tb_name).returncode == 0


def test_a_traces_link_timeline_outlives_net_down_and_is_never_overwritten(tb_name, tmp_path):
    trace = tmp_path / "two.ns2"
    trace.write_text(TRACE)
    r = tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = tmp_path / f"{tb_name}-links.csv"
    assert str(out) in r.stdout
    try:
        (player,) = [p for p in state.read(tb_name).processes if p.role == "mobility"]
        deadline = time.monotonic() + 20
        while state.is_alive(player.pid, player.start) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        assert tb("net", "down", tb_name).returncode == 0
    with open(out) as f:
        rows = list(csv.reader(f))[1:]
    assert [row[1:] for row in rows] == [["add", "1", "2"], ["remove", "1", "2"]]
    # Again in the same place: the earlier timeline is kept, the new network refused.
    r = tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10", cwd=tmp_path)
    assert r.returncode == 2 and "earlier link timeline" in r.stderr, r.stderr
    assert not netns.exists(f"tb-{tb_name}-m") and state.read(tb_name) is None
    with open(out) as f:
        assert list(csv.reader(f))[1:] == rows
