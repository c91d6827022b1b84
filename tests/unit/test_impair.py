"""topology.kernel.impair's pure builders: the qdisc tree and nft commands an impairment wants, and
the requests that take a link end from what it has to that."""

import pytest

from topology.kernel.impair import (
    CLEAR,
    Plan,
    TcRequest,
    missing_feature,
    plan,
    tc_diff,
    tc_rate,
    wanted_qdiscs,
)
from topology.spec import Impairment


@pytest.mark.parametrize(
    "kbit, text",
    [(100, "100000bit"), (100.0, "100000bit"), (0.5, "500bit"), (12.3456, "12346bit"),
     (1e-9, "1bit"), (250 * 2.0, "500000bit")],
)  # fmt: skip
def test_rate_is_whole_bits_per_second(kbit, text):
    assert tc_rate(kbit) == text


def test_rate_goes_through_pyroute2s_parser():
    """The text must mean the rate to pyroute2 (bytes per second): '100.0kbit' did not."""
    from pyroute2.netlink.rtnl.tcmsg.common import get_rate

    assert get_rate(tc_rate(100.0)) == 100_000 / 8
    assert get_rate(tc_rate(100 * 3.0)) == 300_000 / 8  # a rate scaled by the time scale
    with pytest.raises(KeyError):
        get_rate(f"{100.0}kbit")  # the old formatting, for the record


@pytest.mark.parametrize("kbit", [0, -1, float("inf"), float("nan")])
def test_rate_refuses_what_no_tbf_can_do(kbit):
    with pytest.raises(ValueError):
        tc_rate(kbit)


def test_trees_without_netem():
    assert wanted_qdiscs(Impairment(), netem=False) == ()
    assert wanted_qdiscs(Impairment(loss_pct=20), netem=False) == ()  # loss is nftables'
    (tbf,) = wanted_qdiscs(Impairment(loss_pct=20, rate_kbit=100), netem=False)
    assert (tbf.kind, tbf.handle, tbf.parent) == ("tbf", "1:", None)
    assert tbf.kwargs()["rate"] == "100000bit" and "parent" not in tbf.kwargs()


def test_trees_with_netem():
    assert wanted_qdiscs(Impairment(), netem=True) == ()
    (root,) = wanted_qdiscs(Impairment(loss_pct=5, delay_ms=20, jitter_ms=2), netem=True)
    assert root.kind == "netem"
    assert root.kwargs() == {"delay": 20000, "jitter": 2000, "loss": 5, "handle": "1:"}
    root, child = wanted_qdiscs(Impairment(delay_ms=1, rate_kbit=64), netem=True)
    assert (child.kind, child.parent, child.kwargs()["rate"]) == ("tbf", "1:1", "64000bit")


def test_an_unchanged_end_needs_nothing():
    imp = Impairment(loss_pct=10, rate_kbit=100)
    for netem in (False, True):
        assert plan("l1x2", imp, imp, netem, 1.0) == Plan((), "")
        assert plan("l1x2", imp, imp, netem, 1.0).empty


def test_a_new_rate_rebuilds_a_changed_rate_replaces_in_place():
    none, slow, fast = Impairment(), Impairment(rate_kbit=100), Impairment(rate_kbit=200)
    first = plan("l1x2", none, slow, False, 1.0)
    assert [r.command for r in first.tc] == ["del", "add"] and first.nft == ""
    change = plan("l1x2", slow, fast, False, 1.0)
    assert change.tc == (TcRequest("replace", wanted_qdiscs(fast, False)[0]),)
    assert plan("l1x2", fast, none, False, 1.0).tc == (CLEAR,)


def test_netem_changes_only_the_qdisc_that_changed():
    a = Impairment(delay_ms=10, rate_kbit=100)
    b = Impairment(delay_ms=10, rate_kbit=300)
    (req,) = plan("l1x2", a, b, True, 1.0).tc
    assert req.command == "replace" and req.qdisc.kind == "tbf"
    shape_change = plan("l1x2", a, Impairment(delay_ms=10), True, 1.0).tc
    assert [r.command for r in shape_change] == ["del", "add"]


def test_loss_without_netem_is_nftables_and_only_when_it_changes():
    lossy = Impairment(loss_pct=20)
    p = plan("l1x2", Impairment(), lossy, False, 1.0)
    assert p.tc == () and "numgen random mod 10000 < 2000" in p.nft
    # A rate change leaves the loss rule alone, and the other way round.
    p = plan("l1x2", lossy, Impairment(loss_pct=20, rate_kbit=100), False, 1.0)
    assert p.nft == "" and p.tc
    p = plan("l1x2", Impairment(loss_pct=20, rate_kbit=100), Impairment(rate_kbit=100), False, 1.0)
    assert p.tc == () and "delete chain bridge testbed loss-l1x2" in p.nft
    assert plan("l1x2", lossy, lossy, True, 1.0).nft == ""
    assert plan("l1x2", Impairment(), lossy, True, 1.0).nft == ""  # netem's loss


def test_the_time_scale_scales_delays_and_rates():
    p = plan("l1x2", Impairment(), Impairment(delay_ms=50, rate_kbit=100), True, 2.0)
    root, child = (r.qdisc for r in p.tc[1:])
    assert root.kwargs()["delay"] == 25000 and child.kwargs()["rate"] == "200000bit"


def test_tc_diff_of_equal_trees_is_empty():
    tree = wanted_qdiscs(Impairment(rate_kbit=5), False)
    assert tc_diff(tree, tree) == () and tc_diff((), ()) == ()


def test_a_rate_limits_queue_holds_the_same_emulated_time_at_every_scale():
    # At time scale K the rate is K times the bits per wall second; tbf's latency (how long a
    # frame may wait in its queue) is 50 emulated ms, i.e. 50 / K wall ms, so the queue holds
    # the same bytes and the same emulated time.
    imp = Impairment(rate_kbit=100)
    for netem in (False, True):
        slow = wanted_qdiscs(imp.scaled(1.0), netem, 1.0)[-1].kwargs()
        fast = wanted_qdiscs(imp.scaled(10.0), netem, 10.0)[-1].kwargs()
        assert (slow["latency"], fast["latency"]) == (50_000, 5_000)
        assert fast["rate"] == "1000000bit"
    tc = plan("l1x2", Impairment(), imp, False, 10.0).tc
    assert tc[-1].qdisc.kwargs()["latency"] == 5_000


def test_what_each_impairment_needs_from_the_kernel_is_one_rule():
    delay, jitter = Impairment(delay_ms=5), Impairment(jitter_ms=1)
    loss, rate = Impairment(loss_pct=10), Impairment(rate_kbit=500)
    for imp in (delay, jitter):  # timed: netem or nothing
        assert "sch_netem" in missing_feature(imp, netem=False, nft=True)
        assert missing_feature(imp, netem=True, nft=False) is None
    assert missing_feature(loss, netem=False, nft=True) is None  # nftables' random drop
    assert "nftables" in missing_feature(loss, netem=False, nft=False)
    assert missing_feature(loss, netem=True, nft=False) is None
    assert missing_feature(rate, netem=False, nft=False) is None  # tbf is everywhere
    assert missing_feature(Impairment(), netem=False, nft=False) is None
