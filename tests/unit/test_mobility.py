"""Mobility traces (topology.inputs.mobility), feed lines (topology.inputs.feed) and the range
model's fast paths for large teams (topology.radio.ranges): pure functions, no root."""

import random

import pytest

from topology.inputs import feed, mobility
from topology.radio import ranges

NS2 = """\
# BonnMotion-style header comment
$node_(0) set X_ 0.0
$node_(0) set Y_ 0.0
$node_(0) set Z_ 0.0
$node_(1) set X_ 10.0
$node_(1) set Y_ 0.0
$ns_ at 1.0 "$node_(0) setdest 3.0 4.0 5.0"
$ns at 2.0 "$node_(1) setdest 10.0 10.0 1.0"
$ns_ at 5.0 "$node_(1) setdest 0.0 5.0 2.0"
"""


def test_ns2_initial_positions_and_legs():
    tr = mobility.parse_ns2(NS2)
    assert tr.nodes == 2
    assert tr.positions(0.0) == [(0.0, 0.0), (10.0, 0.0)]
    # node 0: leaves at 1 s, 5 m at 5 m/s: arrives at 2 s and stops exactly there.
    assert tr.positions(1.5)[0] == pytest.approx((1.5, 2.0))
    assert tr.positions(2.0)[0] == (3.0, 4.0)
    assert tr.positions(100.0)[0] == (3.0, 4.0)


def test_ns2_setdest_cuts_the_leg_in_progress():
    tr = mobility.parse_ns2(NS2)
    # node 1 heads up at 1 m/s from 2 s; at 5 s (at (10, 3)) it turns to (0, 5) at 2 m/s.
    assert tr.positions(5.0)[1] == pytest.approx((10.0, 3.0))
    d = (10.0**2 + 2.0**2) ** 0.5
    assert tr.end == pytest.approx(5.0 + d / 2.0)
    assert tr.positions(tr.end)[1] == (0.0, 5.0)
    assert tr.positions(tr.end + 1)[1] == (0.0, 5.0)


def test_ns2_speed_zero_stays():
    tr = mobility.parse_ns2(
        '$node_(0) set X_ 1\n$node_(0) set Y_ 2\n$ns_ at 1 "$node_(0) setdest 5 5 0"\n'
    )
    assert tr.positions(10.0) == [(1.0, 2.0)]


@pytest.mark.parametrize(
    "text, where",
    [
        ("$node_(0) set X_ 1\n$node_(0) set Y_ 1\nbogus line\n", "line 3: not an ns-2"),
        ("$node_(0) set X_ 1\n$node_(0) set Y_ 1\n$ns_ at -1 \"$node_(0) setdest 1 1 1\"\n",
         "line 3: time -1 is negative"),
        ("$node_(0) set X_ 1\n$node_(0) set Y_ 1\n$ns_ at 1 \"$node_(0) setdest 1 1 -2\"\n",
         "line 3: speed -2 is negative"),
        ("$node_(0) set X_ 1\n$node_(0) set Y_ 1\n$ns_ at 1 \"$node_(4) setdest 1 1 1\"\n",
         "line 3: node 4 has no initial position"),
        ("$node_(0) set X_ 1\n", "node 0 has no initial Y_"),
        ("$node_(6) set X_ 1\n$node_(6) set Y_ 1\n$ns_ at 1 \"$node_(5) setdest 1 1 1\"\n",
         "line 3: node 5 has no initial position"),
        ("# only a comment\n", "no node"),
    ],
)  # fmt: skip
def test_ns2_errors_name_the_line(text, where):
    with pytest.raises(mobility.TraceError, match=where):
        mobility.parse_ns2(text, "f.ns2")


# In the shape of CORE's own mobility files (its GUI's sample1.scen): a comment header,
# nodes numbered as on CORE's canvas (6..9, not from 0), X_ Y_ Z_, legs out of time order.
CORE_SCEN = """\
#
# nodes: 4, max time: 12.000000, max x: 400.00, max y: 300.00
# nominal range: 150.00 link bw: 54000000.00
# pause: 2.00, min speed 2.00 max speed: 10.00

$node_(6) set X_ 100.0
$node_(6) set Y_ 50.0
$node_(6) set Z_ 0.00
$node_(7) set X_ 160.0
$node_(7) set Y_ 50.0
$node_(7) set Z_ 0.00
$node_(8) set X_ 220.0
$node_(8) set Y_ 80.0
$node_(8) set Z_ 0.00
$node_(9) set X_ 300.0
$node_(9) set Y_ 80.0
$node_(9) set Z_ 0.00
$ns_ at 2.00 "$node_(9) setdest 300.0 200.0 10.0"
$ns_ at 1.00 "$node_(8) setdest 220.0 50.0 6.0"
$ns_ at 6.00 "$node_(6) setdest 40.0 50.0 20.0"
"""


def test_core_file_with_nodes_six_to_nine_plays_as_robots_one_to_four():
    tr = mobility.parse(CORE_SCEN, "sample.scen")
    assert tr.nodes == 4 and tr.node_ids == [6, 7, 8, 9]
    assert tr.robot_of_node() == {6: 1, 7: 2, 8: 3, 9: 4}
    assert tr.mapping_text() == "nodes 6..9 -> r1..r4"
    assert tr.positions(0.0) == [(100.0, 50.0), (160.0, 50.0), (220.0, 80.0), (300.0, 80.0)]
    # node 8 (robot 3): 30 m down at 6 m/s from t=1; node 9 (robot 4): 120 m up from t=2.
    assert tr.positions(3.5)[2:] == [(220.0, 65.0), (300.0, 95.0)]
    assert tr.positions(100.0) == [(40.0, 50.0), (160.0, 50.0), (220.0, 50.0), (300.0, 200.0)]
    assert tr.end == 14.0  # node 9 arrives at 2 + 120 / 10
    # --robots 2: the two lowest ids.
    assert tr.positions(0.0, 2) == [(100.0, 50.0), (160.0, 50.0)]
    assert tr.mapping_text(2) == "nodes 6..7 -> r1..r2"


def test_ids_with_gaps_are_robots_in_ascending_order_of_id():
    ns2 = "".join(f"$node_({i}) set X_ {i}\n$node_({i}) set Y_ 0\n" for i in (12, 0, 2, 3, 4))
    tr = mobility.parse(ns2)
    assert tr.node_ids == [0, 2, 3, 4, 12]
    assert tr.positions(0.0) == [(0.0, 0.0), (2.0, 0.0), (3.0, 0.0), (4.0, 0.0), (12.0, 0.0)]
    assert tr.mapping_text() == "nodes 0 -> r1, 2..4 -> r2..r4, 12 -> r5"
    one = mobility.parse("0 5 1 1\n0 3 2 2\n4 5 9 1\n")
    assert one.node_ids == [3, 5] and one.positions(4.0) == [(2.0, 2.0), (9.0, 1.0)]
    assert one.mapping_text(1) == "node 3 -> r1"


def test_files_from_node_zero_keep_node_i_as_robot_i_plus_1():
    tr = mobility.parse_ns2(NS2)
    assert tr.robot_of_node() == {0: 1, 1: 2} and tr.mapping_text() == "nodes 0..1 -> r1..r2"


def test_one_trace():
    tr = mobility.parse("0 100 0 100 0 100\n0 0 0 0\n0 1 5 5\n10 0 10 0\n")
    assert tr.nodes == 2
    assert tr.positions(5.0) == [(5.0, 0.0), (5.0, 5.0)]
    assert tr.end == 10.0
    with pytest.raises(mobility.TraceError, match="line 2: expected 4 fields"):
        mobility.parse("0 0 0 0\n1 2 3\n")


def test_ticks_end_on_the_trace_end():
    assert list(mobility.ticks(0.25, 0.1)) == [0.0, 0.1, 0.2, 0.3]
    assert list(mobility.ticks(0.3, 0.1)) == [0.0, 0.1, 0.2, 0.3]
    assert list(mobility.ticks(0.0, 0.1)) == [0.0]


def test_feed_lines():
    assert feed.parse_line("3 1.5 -2") == (None, 3, 1.5, -2.0)
    assert feed.parse_line("r3 1.5 -2") == (None, 3, 1.5, -2.0)
    assert feed.parse_line("2.5 3 1 2") == (2.5, 3, 1.0, 2.0)
    assert feed.parse_line("  # comment") is None
    assert feed.parse_line("") is None
    bad_lines = [("1 2", "fields"), ("0 1 2", ">= 1"), ("x 1 2 3", "time"),
                 ("1 a 2", "two numbers"), ("1 nan 2", "finite"), ("-1 1 2 3", ">= 0")]  # fmt: skip
    for bad, what in bad_lines:
        with pytest.raises(ValueError, match=what):
            feed.parse_line(bad)


@pytest.mark.parametrize("model", ["disc", "lossy"])
@pytest.mark.parametrize("n", [5, 47, 48, 200])
def test_vectorised_links_equal_the_double_loop(monkeypatch, model, n):
    rng = random.Random(n)
    pos = [(rng.uniform(0, 60), rng.uniform(0, 60)) for _ in range(n)]
    pos[1] = (pos[0][0] + 10.0, pos[0][1])  # exactly at the range
    fast = ranges.wanted_links(pos, 10.0, model)
    monkeypatch.setattr(ranges, "VECTOR_FROM", 10**9)
    assert ranges.wanted_links(pos, 10.0, model) == fast
    assert (1, 2) in fast


@pytest.mark.parametrize("model", ["disc", "lossy"])
def test_links_of_the_moved_robots(model):
    rng = random.Random(7)
    pos = [(rng.uniform(0, 50), rng.uniform(0, 50)) for _ in range(120)]
    moved = {1, 60, 120}
    full = ranges.wanted_links(pos, 10.0, model)
    kept = {p: v for p, v in full.items() if not set(p) & moved}
    assert kept | ranges.links_of(pos, moved, 10.0, model) == full


class _NoKernel:
    """Stands in for the medium: the links' bookkeeping is what is tested here."""

    def create_pairs(self, pairs):
        pass

    def set_link_impairment(self, i, j, imp):
        pass

    def set_links(self, add, remove):
        pass


@pytest.mark.parametrize("model, loss", [("disc", 0.0), ("lossy", 5.0)])
def test_incremental_moves_keep_the_links_the_positions_call_for(model, loss):
    from topology.network import Network
    from topology.spec import Impairment, NetworkSpec, layout_positions

    spec = NetworkSpec(name="unit", positions=tuple(layout_positions("grid", 120, 8.0)),
                       comm_range=10.0, range_model=model,
                       impairment=Impairment(loss_pct=loss))  # fmt: skip
    net = Network(spec)
    net.medium = _NoKernel()
    net._apply_positions()
    rng = random.Random(3)
    for _ in range(500):
        ks = rng.sample(range(1, 121), rng.choice([1, 1, 4]))
        net.move_many({k: (net.positions[k - 1][0] + rng.uniform(-4, 4),
                           net.positions[k - 1][1] + rng.uniform(-4, 4)) for k in ks})  # fmt: skip
        assert net.current == net.wanted()
