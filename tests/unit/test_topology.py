"""topology without the kernel: names, spec validation, layouts, range models, diffs, state."""

import os
import subprocess
import sys

import pytest

from topology import names, state
from topology.kernel.impair import nft_loss_rules, nft_unloss_rules
from topology.radio import ranges
from topology.spec import Impairment, NetworkSpec, layout_positions


def test_names_round_trip_and_fit_in_15_characters():
    assert names.robot_addr(1) == "10.0.0.1" and names.robot_addr(254) == "10.0.0.254"
    assert names.robot_addr(255) == "10.0.1.1"
    for k in (1, 7, 254, 255, 999):
        assert names.robot_of_addr(names.robot_addr(k)) == k
    assert names.robot_of_addr("10.0.0.0") is None and names.robot_of_addr("192.168.0.1") is None
    assert names.parse_ns(names.robot_ns("ab1", 12)) == ("ab1", "r12")
    assert names.parse_ns(names.medium_ns("ab1")) == ("ab1", "m")
    assert names.parse_ns("tb-AB-m") is None and names.parse_ns("other-ns") is None
    for ifname in (names.bridge(999), names.robot_port(999), names.link_end(998, 999)):
        assert len(ifname) <= 15
    assert names.parse_link_end(names.link_end(3, 12)) == (3, 12)
    with pytest.raises(ValueError):
        names.check_name("Has-Caps")
    with pytest.raises(ValueError):
        names.check_name("waytoolongname")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"positions": ()}, "at least one robot"),
        ({"comm_range": 0}, "positive"),
        ({"comm_range": -3}, "positive"),
        ({"comm_range": float("nan")}, "positive"),
        ({"routing": "olsr"}, "unknown routing"),
        ({"range_model": "cone"}, "unknown range model"),
        ({"time_scale": 0}, "time scale"),
    ],
)
def test_spec_rejects_bad_values(kwargs, message):
    base = {"name": "t1", "positions": ((0, 0),), "comm_range": 5.0}
    with pytest.raises(ValueError, match=message):
        NetworkSpec(**{**base, **kwargs})


def test_impairment_validation_scaling_and_combination():
    with pytest.raises(ValueError):
        Impairment(loss_pct=101)
    with pytest.raises(ValueError):
        Impairment(delay_ms=-1)
    imp = Impairment(loss_pct=10, delay_ms=50, jitter_ms=4, rate_kbit=100)
    fast = imp.scaled(5)
    assert (fast.delay_ms, fast.jitter_ms, fast.rate_kbit, fast.loss_pct) == (10, 0.8, 500, 10)
    both = Impairment(loss_pct=10).combined(Impairment(loss_pct=20, rate_kbit=50))
    assert both.loss_pct == pytest.approx(28.0) and both.rate_kbit == 50
    assert Impairment().is_none and not Impairment(loss_pct=1).is_none


def test_layouts():
    assert layout_positions("chain", 3, 8) == [(0, 0), (8, 0), (16, 0)]
    assert layout_positions("grid", 4, 2) == [(0, 0), (2, 0), (0, 2), (2, 2)]
    a = layout_positions("random", 10, 5, seed=3)
    assert a == layout_positions("random", 10, 5, seed=3) != layout_positions("random", 10, 5, 4)
    side = 5 * 10**0.5
    assert all(0 <= x <= side and 0 <= y <= side for x, y in a)
    with pytest.raises(ValueError, match="unknown layout"):
        layout_positions("hex", 3, 1)
    with pytest.raises(ValueError):
        layout_positions("chain", 0, 1)


def test_disc_model_links_exactly_within_range_inclusive():
    pos = [(0, 0), (10, 0), (20.001, 0), (0, 10)]
    assert set(ranges.wanted_links(pos, 10.0)) == {(1, 2), (1, 4)}
    assert all(imp.is_none for imp in ranges.wanted_links(pos, 10.0).values())


def test_lossy_model_loss_grows_with_distance():
    pos = [(0, 0), (4, 0), (7.5, 0), (10, 0)]
    links = ranges.wanted_links(pos, 10.0, "lossy")
    assert links[(1, 2)].loss_pct == 0  # within half the range
    assert 0 < links[(1, 3)].loss_pct < links[(1, 4)].loss_pct == ranges.MAX_EDGE_LOSS_PCT


def test_diff_touches_only_what_changed():
    cur = {(1, 2): Impairment(), (2, 3): Impairment(loss_pct=5)}
    want = {(1, 2): Impairment(), (2, 3): Impairment(loss_pct=9), (3, 4): Impairment()}
    assert ranges.diff(cur, want) == ([(3, 4)], [], [(2, 3)])
    assert ranges.diff(want, want) == ([], [], [])
    assert ranges.diff(cur, {}) == ([], [(1, 2), (2, 3)], [])


def test_nft_rules_name_the_link_end_and_threshold():
    rules = nft_loss_rules("l1x2", 20)
    assert "numgen random mod 10000 < 2000" in rules and '"l1x2" : jump loss-l1x2' in rules
    assert "delete chain bridge testbed loss-l1x2" in nft_unloss_rules("l1x2")
    total = nft_loss_rules("l1x2", 100)
    assert "numgen" not in total and "counter drop" in total


def test_state_round_trip_and_ownership(tmp_path, monkeypatch):
    monkeypatch.setenv("TESTBED_STATE_DIR", str(tmp_path))
    spec = NetworkSpec(name="u1", positions=((0, 0), (3, 4)), comm_range=5.0,
                       impairment=Impairment(loss_pct=3))  # fmt: skip
    st = state.TestbedState.new(spec)
    state.create("u1", st)
    with pytest.raises(FileExistsError):
        state.create("u1", st)
    back = state.read("u1")
    assert state.spec_from_dict(back.spec) == spec
    assert not back.abandoned(), "we own it and we are alive"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    back.owner_pid, back.owner_start = dead.pid, 1
    assert back.abandoned()
    back.persistent = True
    assert not back.abandoned()
    assert state.names() == ["u1"]
    state.remove("u1")
    assert state.read("u1") is None and state.names() == []


def test_process_identity_includes_start_time():
    me = os.getpid()
    start = state.proc_start_time(me)
    assert start is not None and state.is_alive(me, start)
    assert not state.is_alive(me, start + 1), "same pid, other start time: not ours"


def test_rtnl_templates_encode_exactly_what_pyroute2_would():
    from topology.kernel import rtnl

    enslave = rtnl.Template(rtnl.link, ints=("index", "master"))
    assert enslave(index=10_001_002, master=1_000_001) == rtnl.link(10_001_002, master=1_000_001)
    up = rtnl.Template(rtnl.link, up=True)
    assert up(index=7) == rtnl.link(7, up=True)
    off = rtnl.Template(rtnl.port_state, state=rtnl.BR_STATE_DISABLED)
    assert off(index=42) == rtnl.port_state(42, rtnl.BR_STATE_DISABLED)
    veth = rtnl.Template(rtnl.veth, ints=("index", "master", "peer_index"),
                         strs={"ifname": 6, "peer_name": 6})  # fmt: skip
    direct = rtnl.veth(10_012_034, "l12x34", 1_000_012, "l34x12", 10_034_012)
    assert veth(index=10_012_034, ifname="l12x34", master=1_000_012, peer_name="l34x12",
                peer_index=10_034_012) == direct  # fmt: skip
    with pytest.raises(ValueError):
        veth(ifname="l1x2")  # another length needs another template


def test_port_state_request_marks_protinfo_nested():
    import struct

    from topology.kernel import rtnl

    msg = rtnl.port_state(5, rtnl.BR_STATE_FORWARDING)
    length, mtype = struct.unpack_from("=LH", msg)
    assert length == len(msg) and mtype == 19  # RTM_SETLINK
    assert msg[16] == 7  # AF_BRIDGE
    (nla_type,) = struct.unpack_from("=H", msg, 34)
    assert nla_type == 12 | rtnl.NLA_F_NESTED  # IFLA_PROTINFO, nested
