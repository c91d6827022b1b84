"""Bring your own robots, end to end: an ns-2 trace and a live feed drive the links."""

import csv
import json
import os
import subprocess
import sys
import time

from topology import state
from topology.inputs import feed

TESTBED = [sys.executable, "-m", "testbed.cli"]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Range 10. r3 comes in at 9 m/s from x=30 (t=1) and stops at x=12 (t=3): within 10 of r2
# (x=5) from t=2.667, so at the tick 2.7. r2 leaves upward at 20 m/s at t=4: out of r3's
# range at t=4.357 (tick 4.4), of r1's at t=4.433 (tick 4.5); it stops at (5, 40) at t=6.
TRACE = """\
$node_(0) set X_ 0.0
$node_(0) set Y_ 0.0
$node_(0) set Z_ 0.0
$node_(1) set X_ 5.0
$node_(1) set Y_ 0.0
$node_(2) set X_ 30.0
$node_(2) set Y_ 0.0
$ns_ at 1.0 "$node_(2) setdest 12.0 0.0 9.0"
$ns at 4.0 "$node_(1) setdest 5.0 40.0 20.0"
"""
TIMELINE = [["0", "add", "1", "2"], ["2.7", "add", "2", "3"], ["4.4", "remove", "2", "3"],
            ["4.5", "remove", "1", "2"]]  # fmt: skip


def tb(*args, **kw) -> subprocess.CompletedProcess:
    kw.setdefault("capture_output", True)
    kw.setdefault("text", True)
    kw.setdefault("cwd", REPO)
    return subprocess.run(TESTBED + list(args), **kw)


def links(name: str) -> set[tuple[int, int]]:
    r = tb("net", "links", name)
    assert r.returncode == 0, r.stderr
    return {tuple(int(v) for v in line.split()) for line in r.stdout.splitlines()}


def rows(path) -> list[list[str]]:
    try:
        with open(path) as f:
            return list(csv.reader(f))[1:]
    except FileNotFoundError:
        return []


def wait_for(cond, timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_ns2_trace_drives_the_links_exactly(tb_name, tmp_path):
    trace = tmp_path / "three.ns2"
    trace.write_text(TRACE)
    out = tmp_path / "links.csv"
    # Time scale 0.5: emulated time runs at half speed, so the trace lasts 12 s of wall time.
    up = tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10",
            "--links-out", str(out), "--time-scale", "0.5")  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert "3 robots, 1 links" in up.stdout
        # Between t=2.7 and t=4.4 (3.4 s of wall time) both links are up.
        assert wait_for(lambda: len(rows(out)) >= 2)
        assert links(tb_name) == {(1, 2), (2, 3)}
        assert wait_for(lambda: len(rows(out)) >= 4)
        st = state.read(tb_name)
        player = [p for p in st.processes if p.role == "mobility"]
        assert len(player) == 1
        assert wait_for(lambda: not state.is_alive(player[0].pid, player[0].start))
        assert rows(out) == TIMELINE  # the applied timeline, exactly the trace's ticks
        assert links(tb_name) == set()  # after the end: r2 at (5, 40), r3 at (12, 0)
        assert state.read(tb_name).positions == [[0.0, 0.0], [5.0, 40.0], [12.0, 0.0]]
    finally:
        assert tb("net", "down", tb_name).returncode == 0


# CORE's shape (its GUI's sample1.scen): a comment header, nodes numbered from 6, X_ Y_ Z_.
# Range 10: 6-7 (7 m) and 7-8 (8 m) are linked, 9 is 25 m from 8. Node 9 comes in at 8 m/s
# from t=1 and is within 10 of node 8 from t=2.875 (tick 2.9); node 6 leaves downward at
# 10 m/s from t=2 and is out of node 7's range from t=2.714 (tick 2.8); it stops at t=5.
CORE_SCEN = """\
#
# nodes: 4, max time: 5.000000, max x: 40.00, max y: 30.00
# nominal range: 10.00 link bw: 54000000.00
# pause: 0.00, min speed 8.00 max speed: 10.00

$node_(6) set X_ 0.0
$node_(6) set Y_ 0.0
$node_(6) set Z_ 0.00
$node_(7) set X_ 7.0
$node_(7) set Y_ 0.0
$node_(7) set Z_ 0.00
$node_(8) set X_ 15.0
$node_(8) set Y_ 0.0
$node_(8) set Z_ 0.00
$node_(9) set X_ 40.0
$node_(9) set Y_ 0.0
$node_(9) set Z_ 0.00
$ns_ at 2.00 "$node_(6) setdest 0.0 -30.0 10.0"
$ns_ at 1.00 "$node_(9) setdest 24.0 0.0 8.0"
"""


def test_a_core_file_numbered_from_six_plays_with_its_mapping_stated(tb_name, tmp_path):
    trace = tmp_path / "core.scen"
    trace.write_text(CORE_SCEN)
    out, cap = tmp_path / "links.csv", tmp_path / "cap"
    up = tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10",
            "--routing", "none", "--links-out", str(out), "--capture", str(cap))  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert "4 robots, 2 links" in up.stdout
        assert "trace nodes 6..9 -> r1..r4" in up.stdout.splitlines()[-1], up.stdout
        about = json.loads((cap / "daemons" / "network.json").read_text())
        assert about["mobility"] == {
            "file": str(trace), "robot_of_node": {"6": 1, "7": 2, "8": 3, "9": 4},
        }  # fmt: skip
        (player,) = [p for p in state.read(tb_name).processes if p.role == "mobility"]
        assert wait_for(lambda: not state.is_alive(player.pid, player.start))
        assert rows(out) == [["0", "add", "1", "2"], ["0", "add", "2", "3"],
                             ["2.8", "remove", "1", "2"], ["2.9", "add", "3", "4"]]  # fmt: skip
        assert links(tb_name) == {(2, 3), (3, 4)}
        assert state.read(tb_name).positions == [[0.0, -30.0], [7.0, 0.0], [15.0, 0.0],
                                                 [24.0, 0.0]]  # fmt: skip
    finally:
        assert tb("net", "down", tb_name).returncode == 0


def test_a_long_trace_is_stopped_by_net_down(tb_name, tmp_path):
    trace = tmp_path / "slow.ns2"
    trace.write_text(TRACE.replace('20.0"', '0.01"'))  # r2 would take an hour
    assert tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10",
              "--robots", "2", cwd=tmp_path).returncode == 0  # fmt: skip
    st = state.read(tb_name)
    (player,) = [p for p in st.processes if p.role == "mobility"]
    assert tb("net", "down", tb_name).returncode == 0
    assert not state.is_alive(player.pid, player.start)


def test_a_bad_trace_is_one_line_with_its_line_number(tb_name, tmp_path):
    trace = tmp_path / "bad.ns2"
    trace.write_text(TRACE + '$ns_ at 7 "$node_(1) setdest 1 1 fast"\n')
    r = tb("net", "up", tb_name, "--mobility", str(trace), "--comm-range", "10")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "line 10" in r.stderr, r.stderr
    assert state.read(tb_name) is None


def test_feed_moves_robots_and_links_follow(tb_name):
    up = tb("net", "up", tb_name, "--robots", "3", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--feed")  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert links(tb_name) == {(1, 2), (2, 3)}
        path = feed.socket_path(tb_name)
        feed.send(path, ["3 100 0", "r2 0 5"])  # at once: r3 leaves, r2 moves next to r1
        assert wait_for(lambda: links(tb_name) == {(1, 2)})
        feed.send(path, ["# then, 1 s of emulated time from the feed's start, r3 comes back",
                         "1 3 0 -6"])  # fmt: skip
        assert wait_for(lambda: links(tb_name) == {(1, 2), (1, 3)})
        # Standard input: the same protocol; the server already runs, so this is its client.
        r = tb("net", "feed", tb_name, input="1 0 100\n")
        assert r.returncode == 0, r.stderr
        assert wait_for(lambda: links(tb_name) == set())
        assert state.read(tb_name).positions[0] == [0.0, 100.0]
        r = tb("net", "feed", tb_name, input="1 0 0\n1 2\n")
        assert r.returncode == 2 and "line 2" in r.stderr and "Traceback" not in r.stderr
        assert wait_for(lambda: links(tb_name) == {(1, 2), (1, 3)})
    finally:
        assert tb("net", "down", tb_name).returncode == 0
    assert not os.path.exists(path)


def test_feed_on_stdin_without_a_server(tb_name):
    assert tb("net", "up", tb_name, "--robots", "2", "--comm-range", "10").returncode == 0
    try:
        assert links(tb_name) == {(1, 2)}  # the default chain, spacing 8
        r = tb("net", "feed", tb_name, input="2 100 0\n")
        assert r.returncode == 0, r.stderr
        assert links(tb_name) == set()
        r = tb("net", "feed", tb_name, input="0.2 2 3 0\n")  # timed: applied before exit
        assert r.returncode == 0, r.stderr
        assert links(tb_name) == {(1, 2)}
        r = tb("net", "feed", tb_name, input="5 1 1\n")
        assert r.returncode == 2 and "r1..r2" in r.stderr
    finally:
        assert tb("net", "down", tb_name).returncode == 0


def test_metrics_of_a_captured_network_with_ping_and_iperf3(tb_name, tmp_path):
    import json
    import shutil

    import pytest

    if not (shutil.which("iperf3") and shutil.which("tshark")):
        pytest.skip("needs iperf3 and tshark")
    cap = tmp_path / "pcaps"
    up = tb("net", "up", tb_name, "--robots", "3", "--layout", "chain", "--spacing", "8",
            "--comm-range", "10", "--routing", "aodv", "--capture", str(cap))  # fmt: skip
    assert up.returncode == 0, up.stderr
    try:
        assert tb("net", "exec", tb_name, "r3", "--", "iperf3", "-s", "-D").returncode == 0
        assert wait_for(lambda: tb("net", "exec", tb_name, "r1", "--", "ping", "-c1", "-W1",
                                   "10.0.0.3").returncode == 0)  # fmt: skip
        r = tb("net", "exec", tb_name, "r1", "--", "iperf3", "-c", "10.0.0.3", "-t", "2",
               "-b", "2M")  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
    finally:
        assert tb("net", "down", tb_name).returncode == 0
    r = tb("metrics", str(cap))
    assert r.returncode == 0, r.stderr
    assert "PDF" in r.stdout
    m = json.loads((cap / "metrics.json").read_text())
    assert m["tcp_payload_bytes_transmitted"] > 400_000  # 2 s at 2 Mbit/s
    assert m["pdf"] > 0.99 and m["delay_ms_median"] is not None
    assert m["control_tx_packets"] > 0  # AODV's hellos and route discovery
    r = tb("metrics", str(tmp_path))
    assert r.returncode == 2 and "no rK.pcap" in r.stderr
