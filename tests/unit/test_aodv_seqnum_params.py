"""Sequence number arithmetic (RFC 3561 6.1) and section 10 parameters."""

import dataclasses

import pytest

from aodv import seqnum
from aodv.neighbors import Neighbors
from aodv.params import Params, profile
from aodv.request_queue import RequestQueue
from aodv.rreq_cache import RreqCache


def test_wraparound_compare():
    assert seqnum.newer(1, 0)
    assert not seqnum.newer(0, 1)
    assert seqnum.newer(0, 0xFFFFFFFF)  # rollover: 0 follows 2**32 - 1
    assert seqnum.newer(5, 0xFFFFFFF0)
    assert not seqnum.newer(0xFFFFFFF0, 5)
    assert seqnum.at_least(7, 7) and not seqnum.newer(7, 7)
    assert seqnum.increment(0xFFFFFFFF) == 0
    assert seqnum.newest(0xFFFFFFFE, 2) == 2


def test_rfc_defaults():
    p = Params()
    assert p.net_traversal_time == pytest.approx(2.8)
    assert p.path_discovery_time == pytest.approx(5.6)
    # Section 10 note: {[(TTL_THRESHOLD - TTL_START)/TTL_INCREMENT] + 1 + RREQ_RETRIES}
    # * NET_TRAVERSAL_TIME with the ring search: (2 + 1 + 2) * 2.8 s.
    assert p.blacklist_timeout == pytest.approx(14.0)
    assert p.delete_period == pytest.approx(15.0)
    # Section 10: MY_ROUTE_TIMEOUT "MUST be at least 2 * PATH_DISCOVERY_TIME".
    assert p.my_route_timeout == pytest.approx(11.2)
    assert p.ttl_start == 2  # "at least 2 if Hello messages are used"
    assert p.next_hop_wait == pytest.approx(0.05)
    assert p.neighbor_timeout == pytest.approx(2.0)
    assert p.ring_traversal_time(1) == pytest.approx(0.24)
    assert p.max_repair_ttl == 10


def test_derived_values_follow_their_inputs():
    p = Params(node_traversal_time_ms=20, net_diameter=10, active_route_timeout_ms=1000)
    assert p.net_traversal_time == pytest.approx(0.4)
    assert p.path_discovery_time == pytest.approx(0.8)
    assert p.my_route_timeout == pytest.approx(2.0)
    assert p.delete_period == pytest.approx(5.0)  # 5 * max(1 s, HELLO_INTERVAL 1 s)


def test_time_scale_divides_every_time():
    p1, p10 = Params(), Params(time_scale=10)
    for f in ("net_traversal_time", "delete_period", "hello_interval", "next_hop_wait"):
        assert getattr(p10, f) == pytest.approx(getattr(p1, f) / 10), f
    assert p10.ms(p10.my_route_timeout) == 11200  # wire values stay in RFC ms
    assert p10.from_ms(6000) == pytest.approx(0.6)


def test_params_are_frozen_and_checked():
    with pytest.raises(dataclasses.FrozenInstanceError):
        Params().net_diameter = 3
    with pytest.raises(ValueError):
        Params(time_scale=0)


def test_rreq_cache_expires():
    c = RreqCache()
    c.add("10.0.0.1", 7, until=5.0)
    assert c.seen("10.0.0.1", 7, 4.9)
    assert not c.seen("10.0.0.1", 8, 4.9)
    assert not c.seen("10.0.0.1", 7, 5.0)
    c.purge(5.0)
    assert len(c) == 0


def test_neighbors_lost_only_when_monitored():
    n = Neighbors()
    n.heard("10.0.0.2", 0.0)  # heard, never a HELLO: not monitored
    n.hello("10.0.0.3", 0.0, timeout=2.0)
    assert n.lost(1.9, delete_period=15) == []
    n.heard("10.0.0.3", 1.0)
    assert n.lost(2.5, delete_period=15) == []
    assert n.lost(3.01, delete_period=15) == ["10.0.0.3"]
    n.blacklist("10.0.0.4", until=1.0)
    assert n.blacklisted("10.0.0.4", 0.5) and not n.blacklisted("10.0.0.4", 1.0)


def test_request_queue_fifo_and_limit():
    q = RequestQueue(limit=2)
    assert q.push("d", b"1") is None and q.push("d", b"2") is None
    assert q.push("d", b"3") == b"1"
    assert q.pop_all("d") == [b"2", b"3"] and "d" not in q


def test_section_10_constraints_are_checked():
    assert Params().problems() == []
    assert profile("ns3").problems() == []
    bad = Params(my_route_timeout_ms=6000)  # the table's 2 * ACTIVE_ROUTE_TIMEOUT
    assert any("MY_ROUTE_TIMEOUT" in p for p in bad.problems())
    assert Params(ttl_start=9).problems()  # above TTL_THRESHOLD
    assert Params(net_diameter=300, ttl_threshold=7).problems()
    assert Params(hello_interval_ms=0).problems()


def test_ns3_profile_matches_ns3_defaults():
    p = profile("ns3")
    assert p.my_route_timeout == pytest.approx(11.2)
    assert p.blacklist_timeout == pytest.approx(5.6)
    assert p.ttl_start == 1 and not p.local_repair
    assert p.delete_period == pytest.approx(15.0) and p.next_hop_wait == pytest.approx(0.05)
    assert profile("rfc", time_scale=2).my_route_timeout == pytest.approx(5.6)
    with pytest.raises(ValueError, match="unknown AODV profile"):
        profile("olsr")


def test_lifetime_field_is_clamped_to_32_bits():
    assert Params().ms(1e12) == 0xFFFFFFFF


def test_a_neighbour_no_longer_monitored_has_no_past_deadline():
    """A neighbour whose last HELLO is older than DELETE_PERIOD but which was heard otherwise
    is not lost when its silence ends; its deadline must then be when it is forgotten, not
    the passed end of its silence (a daemon's loop spun on that deadline, 90,000 times in a
    run, each firing counted as a late expiry timer)."""
    n = Neighbors()
    n.hello("10.0.0.3", 0.0, timeout=2.0)
    n.heard("10.0.0.3", 20.0)  # data, no HELLO: silence ends at 22, last HELLO 22 s before
    assert n.next_deadline(delete_period=15) == 35.0
    assert n.lost(23.0, delete_period=15) == []
    assert n.next_deadline(delete_period=15) == 35.0  # still: nothing to do before 35
    assert n.lost(35.5, delete_period=15) == [] and n.next_deadline(delete_period=15) is None


def test_a_neighbour_monitored_when_its_silence_ended_is_lost_however_late_the_timer():
    n = Neighbors()
    n.hello("10.0.0.3", 0.0, timeout=2.0)
    assert n.next_deadline(delete_period=15) == 2.0
    # handled 20 s late (a stalled daemon): the link broke at 2, while monitored
    assert n.lost(22.0, delete_period=15) == ["10.0.0.3"]
    assert n.next_deadline(delete_period=15) is None
