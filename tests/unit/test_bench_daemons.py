"""The benchmarks of issue 53 (the two AODV daemons): their pure parts, without a network.

- cost: a case's label names the robot and the daemon chosen; bad TESTBED_COST_DAEMONS is one
  line and exit 2; the routing daemons are a kind of their own in the CPU split.
- aodv_grid: the pairs are distinct, at least MIN_HOPS apart on the grid, each robot the
  source of one; grid_hops agrees with the grid's positions; a ping's output is read into
  sent, received and the sequence numbers lost.
- idle: /proc readers on this process; a bad window is one line and exit 2.
"""

import math
import os

import pytest

from testbed.bench import aodv_grid, cost, idle
from topology.spec import layout_positions


def test_cost_labels_name_robot_and_daemon():
    assert cost._label("ten", "default", "default") == "ten"
    assert cost._label("ten", "cpp", "default") == "ten-cpp"
    assert cost._label("ten", "cpp", "python") == "ten-cpp-aodv-python"
    assert cost._label("lone", "default", "cpp") == "lone-aodv-cpp"


def test_cost_routing_kind_is_both_daemons():
    # The Python daemon is forked and titled "rK aodv"; the compiled one runs as tb-aodv.
    for comm in ("r3 aodv", "tb-aodv", "babeld"):
        assert cost._kind(10, 10, comm, root=1) == "routing"
    assert cost._kind(10, 10, "r3 robot", root=1) == "robots"


def test_cost_bad_daemon_list_exits_2(monkeypatch, capsys):
    monkeypatch.setenv("TESTBED_COST_DAEMONS", "python,rust")
    monkeypatch.setattr(cost, "measure", lambda *a: pytest.fail("measured"))
    with pytest.raises(SystemExit) as e:
        cost.run()
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "TESTBED_COST_DAEMONS" in err


@pytest.mark.parametrize("n", [9, 100, 1000])
def test_grid_hops_match_the_positions(n):
    pos = layout_positions("grid", n, 8.0)
    for a, b in aodv_grid.pairs(n, min(20, n - 1), 1, seed=1):
        (xa, ya), (xb, yb) = pos[a - 1], pos[b - 1]
        assert aodv_grid.grid_hops(a, b, n) == max(abs(xa - xb), abs(ya - yb)) / 8.0


def test_pairs_far_enough_and_distinct_sources():
    chosen = aodv_grid.pairs(1000, 20, 2, seed=23)
    assert len(chosen) == 20
    assert len({a for a, _ in chosen}) == 20
    assert all(a != b and aodv_grid.grid_hops(a, b, 1000) >= 2 for a, b in chosen)
    assert max(aodv_grid.grid_hops(a, b, 1000) for a, b in chosen) <= math.ceil(math.sqrt(1000))


class _Done:
    def __init__(self, out: bytes):
        self.out = out

    def communicate(self):
        return self.out, None


def test_ping_output_read():
    out = b"".join(
        b"64 bytes from 10.0.0.9: icmp_seq=%d ttl=60 time=1.0 ms\n" % i for i in (1, 2, 4, 5)
    )
    out += b"--- 10.0.0.9 ping statistics ---\n5 packets transmitted, 4 received, 20% loss\n"
    r = aodv_grid._ping_result(1, 9, _Done(out))  # type: ignore[arg-type]
    assert (r["sent"], r["received"], r["lost_seq"]) == (5, 4, [3])


def test_ping_count_spans_the_window():
    assert pytest.approx(aodv_grid.PING_S) == aodv_grid.COUNT * aodv_grid.INTERVAL_S


def test_proc_readers_on_this_process():
    assert idle.cpu_s(os.getpid()) is not None
    rss, pss = idle.memory_kib(os.getpid())
    assert rss > 0 and pss > 0
    assert idle.cpu_s(2**22 + 1) is None and idle.memory_kib(2**22 + 1) == (0, 0)


@pytest.mark.parametrize("value", ["0", "-3", "soon"])
def test_idle_bad_window_exits_2(monkeypatch, capsys, value):
    monkeypatch.setenv("TESTBED_IDLE_S", value)
    with pytest.raises(SystemExit) as e:
        idle.run()
    assert e.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_grid_bad_team_exits_2(monkeypatch, capsys):
    monkeypatch.setenv("TESTBED_GRID_ROBOTS", "5000")
    with pytest.raises(SystemExit) as e:
        aodv_grid.run()
    assert e.value.code == 2
    assert "TESTBED_GRID_ROBOTS" in capsys.readouterr().err


def test_idle_targets_judged():
    idles = {"cpp": {"cpu_percent_of_core_median": 0.01, "rss_mib_median": 1.4}}
    readies = [{"robots": 1000, "daemon": "cpp", "ready_s_median": 12.0}]
    t = idle.targets(idles, readies)
    assert t["idle_cpu_percent_cpp"]["met"] and t["idle_rss_mib_cpp"]["met"]
    assert not t["ready_s_1000_cpp"]["met"]
