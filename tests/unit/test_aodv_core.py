"""Each RFC 3561 rule of the sans-IO core, on the in-memory medium with a fake clock."""

import pytest

from aodv.core import (
    AodvCore,
    Broadcast,
    DeleteRoute,
    InstallRoute,
    ReleasePackets,
    Unicast,
)
from aodv.packet import Rerr, Rrep, RrepAck, Rreq
from aodv.params import Params
from aodv.sim import Medium, data_packet

A = [f"10.0.0.{i}" for i in range(1, 11)]
N1, N2, N3, N4, N5, N6 = A[:6]
N9 = A[8]


def chain(n=5, **kw):
    m = Medium(Params(**kw))
    m.chain(A[:n])
    return m


def flow(m, src, dst, start, end, every=0.25):
    t = start
    while t < end:
        m.at(t, lambda: m.send_data(src, dst))
        t += every


# -- RFC 6.3 / 6.4 discovery --------------------------------------------------------------
def test_expanding_ring_finds_4_hop_route_and_delivers_buffered_packet():
    m = chain()
    m.send_data(N1, N5, b"first")
    m.run_until(2.0)
    assert m.nodes[N5].delivered[0][2] == data_packet(N1, N5, b"first")
    assert m.nodes[N1].kernel[N5] == (N2, 4)
    assert m.nodes[N5].kernel[N1] == (N4, 4)
    rreqs = m.sent("RREQ", src=N1)
    # TTL_START 2, +TTL_INCREMENT: 2 falls short, 4 reaches 4 hops.
    assert [s.ttl for s in rreqs] == [2, 4]
    # RING_TRAVERSAL_TIME = 2 * NODE_TRAVERSAL_TIME * (TTL + TIMEOUT_BUFFER)
    assert rreqs[1].time - rreqs[0].time == pytest.approx(0.32)
    # Each RREQ increments the RREQ ID and the originator's sequence number; U flag set.
    assert [s.msg.rreq_id for s in rreqs] == [1, 2]
    assert [s.msg.orig_seq for s in rreqs] == [1, 2]
    assert all(s.msg.unknown_seq and s.msg.dest_seq == 0 for s in rreqs)
    (done,) = m.nodes[N1].discoveries
    assert done.ok and done.round_latency < 0.02


def test_rreq_ip_ttl_and_hop_count_along_the_way():
    m = chain()
    m.send_data(N1, N5)
    m.run_until(2.0)
    last = [s for s in m.sent("RREQ") if s.msg.rreq_id == 2]
    assert [(s.src, s.ttl, s.msg.hop_count) for s in last] == [
        (N1, 4, 0),
        (N2, 3, 1),
        (N3, 2, 2),
        (N4, 1, 3),
    ]
    rreps = [s for s in m.sent("RREP") if s.msg.dest == N5]
    assert [(s.src, s.dst, s.msg.hop_count) for s in rreps] == [
        (N5, N4, 0),
        (N4, N3, 1),
        (N3, N2, 2),
        (N2, N1, 3),
    ]
    assert rreps[0].msg.lifetime_ms == 11200  # MY_ROUTE_TIMEOUT


def test_duplicate_rreq_is_forwarded_once():
    # A diamond: 1 - {2, 3} - 4 - 5; node 4 hears the same RREQ twice.
    m = Medium()
    for a in A[:5]:
        m.add_node(a)
    for a, b in [(N1, N2), (N1, N3), (N2, N4), (N3, N4), (N4, N5)]:
        m.link(a, b)
    m.send_data(N1, N5)
    m.run_until(2.0)
    assert m.nodes[N5].delivered
    fw = [(s.src, s.msg.rreq_id) for s in m.sent("RREQ") if s.src == N4]
    assert len(fw) == len(set(fw))
    assert m.nodes[N1].kernel[N5][1] == 3


def test_unreachable_destination_retries_with_backoff_then_icmp():
    m = chain(3)
    m.send_data(N1, "10.0.0.99", b"lost")
    m.run_until(60.0)
    rreqs = m.sent("RREQ", src=N1)
    # Ring 2, 4, 6 then NET_DIAMETER, retried RREQ_RETRIES = 2 times.
    assert [s.ttl for s in rreqs] == [2, 4, 6, 35, 35, 35]
    gaps = [b.time - a.time for a, b in zip(rreqs[3:], rreqs[4:], strict=False)]
    assert gaps == pytest.approx([2.8, 5.6])  # 2**k * NET_TRAVERSAL_TIME
    t_fail = rreqs[-1].time + 4 * 2.8
    (drop,) = m.nodes[N1].unreachable
    assert drop[0] == pytest.approx(t_fail) and drop[2].endswith(b"lost")
    (done,) = m.nodes[N1].discoveries
    assert not done.ok


def test_time_scale_makes_every_timer_faster():
    m = chain(3, time_scale=10)
    m.send_data(N1, "10.0.0.99")
    m.run_until(6.0)
    (drop,) = m.nodes[N1].unreachable
    ring = 2 * 0.04 * (4 + 6 + 8)  # ring timeouts for TTL 2, 4, 6
    assert drop[0] == pytest.approx((ring + 2.8 * 7) / 10, abs=0.01)


def test_rreq_rate_limit_delays_excess_requests():
    m = chain(2)
    for k in range(15):
        m.send_data(N1, f"10.0.1.{k}")
    m.run_until(0.999)
    assert len(m.sent("RREQ", src=N1)) == 10  # RREQ_RATELIMIT per second
    m.run_until(1.05)
    assert len(m.sent("RREQ", src=N1)) > 10


# -- RFC 6.5 / 6.6 / 6.7 replies -----------------------------------------------------------
def test_destination_sequence_number_and_intermediate_reply_with_gratuitous_rrep():
    m = chain()
    m.add_node(N6)
    m.link(N3, N6)
    m.send_data(N1, N5)
    m.run_until(1.0)
    m.nodes[N5].core.seq = 0  # as after the first discovery: RREP carried 0
    m.send_data(N6, N5, b"from6")
    m.run_until(2.0)
    assert m.nodes[N5].delivered[-1][2].endswith(b"from6")
    # Node 3 has a fresh route to 5 and answers for it (RFC 6.6.2)...
    rrep = [s for s in m.sent("RREP", src=N3) if s.dst == N6]
    assert rrep and rrep[0].msg.hop_count == 2 and rrep[0].msg.dest == N5
    # ... and, the G flag being set, tells 5 about 6 with a gratuitous RREP (RFC 6.6.3).
    grat = [s for s in m.sent("RREP", src=N3) if s.msg.dest == N6]
    assert grat and grat[0].dst == N4 and grat[0].msg.orig == N5
    assert m.nodes[N5].kernel[N6] == (N4, 3)
    assert not m.sent("RREQ", src=N5)
    # Precursors (RFC 6.2): 3's route to 5 now serves 2 and 6.
    assert m.nodes[N3].core.table.get(N5).precursors >= {N2, N6}


def test_d_flag_only_the_destination_answers():
    m = chain(dest_only=True)
    m.add_node(N6)
    m.link(N3, N6)
    m.send_data(N1, N5)
    m.run_until(1.0)
    m.send_data(N6, N5)
    m.run_until(2.0)
    assert not [s for s in m.sent("RREP", src=N3) if s.dst == N6]
    assert [s for s in m.sent("RREP", src=N5) if s.msg.orig == N6]
    assert all(s.msg.dest_only for s in m.sent("RREQ"))


def test_destination_takes_max_of_own_and_requested_seq():
    core = AodvCore(N5, Params(), 0.0)
    rreq = Rreq(rreq_id=1, dest=N5, dest_seq=41, orig=N1, orig_seq=9, hop_count=2)
    acts = core.on_control(0.0, N4, 30, rreq)
    (rrep,) = [a for a in acts if isinstance(a, Unicast)]
    assert rrep.dst == N4 and rrep.msg.dest_seq == 41 and rrep.msg.hop_count == 0
    assert InstallRoute(N1, N4, 3) in acts and InstallRoute(N4, N4, 1) in acts
    # Reverse route keeps the originator's sequence number, valid.
    r = core.table.get(N1)
    assert r.seq == 9 and r.valid_seq


def test_rreq_forward_uses_max_dest_seq_without_changing_own_copy():
    core = AodvCore(N3, Params(), 0.0)
    core.on_control(
        0.0,
        N4,
        1,
        Rrep(dest=N5, dest_seq=20, orig=N1, lifetime_ms=6000, hop_count=1),
    )
    core.table.get(N5).valid = False  # known seq, no usable route
    acts = core.on_control(0.1, N2, 5, Rreq(2, N5, 10, N1, 3, hop_count=1))
    (fw,) = [a for a in acts if isinstance(a, Broadcast)]
    assert fw.ttl == 4 and fw.msg.dest_seq == 20 and fw.msg.hop_count == 2
    acts = core.on_control(0.2, N2, 5, Rreq(3, N5, 30, N1, 4, hop_count=1))
    (fw,) = [a for a in acts if isinstance(a, Broadcast)]
    assert fw.msg.dest_seq == 30 and core.table.get(N5).seq == 20


def test_rreq_with_ttl_1_is_not_forwarded_and_reverse_route_lifetime():
    p = Params()
    core = AodvCore(N3, p, 0.0)
    acts = core.on_control(0.0, N2, 1, Rreq(1, N5, 0, N1, 1, hop_count=1, unknown_seq=True))
    assert not [a for a in acts if isinstance(a, Broadcast)]
    r = core.table.get(N1)
    # MinimalLifetime = now + 2*NET_TRAVERSAL_TIME - 2*HopCount*NODE_TRAVERSAL_TIME
    assert r.lifetime == pytest.approx(2 * 2.8 - 2 * 2 * 0.04)
    assert (r.next_hop, r.hops) == (N2, 2)


def test_stale_rrep_does_not_replace_fresher_route_and_wraparound_counts():
    core = AodvCore(N1, Params(), 0.0)
    core.on_control(0.0, N2, 64, Rrep(N5, 0xFFFFFFFF, N1, 6000, hop_count=3))
    assert core.routes()[N5] == (N2, 4)
    core.on_control(0.1, N3, 64, Rrep(N5, 0xFFFFFFFE, N1, 6000, hop_count=0))
    assert core.routes()[N5] == (N2, 4)  # older sequence number: ignored
    core.on_control(0.2, N3, 64, Rrep(N5, 0, N1, 6000, hop_count=5))
    assert core.routes()[N5] == (N3, 6)  # 0 follows 2**32-1: newer wins despite hops
    core.on_control(0.3, N2, 64, Rrep(N5, 0, N1, 6000, hop_count=1))
    assert core.routes()[N5] == (N2, 2)  # same seq, fewer hops


# -- RFC 6.8 RREP-ACK and blacklist -------------------------------------------------------
def test_unidirectional_link_is_blacklisted_by_missing_rrep_ack():
    m = Medium()
    for a in A[:4]:
        m.add_node(a)
    # 1 -> 2 works, 2 -> 1 does not; 1 - 3 - 4 and 2 - 4 are bidirectional.
    m.link(N1, N2, both=False)
    m.link(N1, N3)
    m.link(N3, N4)
    m.link(N2, N4)
    m.send_data(N1, N4)
    m.run_until(1.0)
    # Both RREPs ask for an ACK; only the one over 3 is acknowledged.
    assert [s for s in m.sent("RREP", src=N2) if s.dst == N1 and s.msg.ack_required]
    assert m.nodes[N2].core.neighbors.blacklisted(N1, m.now)
    assert m.nodes[N4].delivered
    assert m.nodes[N1].kernel[N4] == (N3, 2)
    # A later RREQ from 1 is ignored by 2 while 1 is blacklisted.
    before = len(m.sent("RREQ", src=N2))
    m.send_data(N1, "10.0.0.77")
    m.run_until(1.1)
    assert len(m.sent("RREQ", src=N2)) == before


def test_late_rrep_ack_lifts_the_blacklist():
    core = AodvCore(N2, Params(), 0.0)
    core.on_control(0.0, N1, 5, Rreq(1, N3, 0, N1, 1, unknown_seq=True))
    core.on_control(0.01, N3, 64, Rrep(N3, 1, N1, 6000))
    assert N1 in core.pending_acks
    core.on_timer(0.2)  # NEXT_HOP_WAIT (50 ms) passed without RREP-ACK
    assert core.neighbors.blacklisted(N1, 0.2)
    assert not [
        a for a in core.on_control(0.3, N1, 5, Rreq(2, N4, 0, N1, 2)) if isinstance(a, Broadcast)
    ]
    core.on_control(0.4, N1, 64, RrepAck())
    assert not core.neighbors.blacklisted(N1, 0.4)
    assert [
        a for a in core.on_control(0.5, N1, 5, Rreq(3, N4, 0, N1, 3)) if isinstance(a, Broadcast)
    ]


# -- RFC 6.9 / 6.10 HELLO -----------------------------------------------------------------
def test_hellos_only_on_active_routes_and_create_neighbor_routes():
    m = chain(3)
    m.run_until(5.0)
    assert not m.sent("HELLO")
    m.send_data(N1, N3)
    m.run_until(3.0 + 5.0)
    hellos = m.sent("HELLO")
    assert {s.src for s in hellos} == {N1, N2, N3}
    assert all(s.ttl == 1 and s.msg.hello_interval_ms == 1000 for s in hellos)
    assert all(s.msg.lifetime_ms == 2000 for s in hellos)
    # Gaps between broadcasts of one node never exceed HELLO_INTERVAL.
    t2 = [s.time for s in m.log if s.src == N2 and s.dst == "255.255.255.255"]
    assert max(b - a for a, b in zip(t2, t2[1:], strict=False)) <= 1.0 + 1e-9


def test_bystander_sends_no_hello_and_hellos_stop_when_routes_idle():
    m = chain(3)
    m.add_node(N6)
    m.link(N1, N6)  # hears 1's RREQ, is on no route
    m.send_data(N1, N3)
    m.run_until(30.0)
    hellos = m.sent("HELLO")
    assert hellos and N6 not in {s.src for s in hellos}
    # MY_ROUTE_TIMEOUT 11.2 s, then neighbour routes held by HELLOs run out: silence.
    assert max(s.time for s in hellos) < 16.0
    assert not any(m.nodes[a].kernel for a in (N1, N2, N3, N6))


def test_link_loss_after_allowed_hello_loss_sends_rerr_to_precursors():
    m = chain(local_repair=False)  # RFC 6.11 alone (local repair: test_aodv_rfc.py)
    flow(m, N1, N5, 0.0, 20.0)
    m.run_until(5.0)
    assert m.nodes[N1].kernel[N5] == (N2, 4)
    m.unlink(N3, N4)
    m.run_until(5.0 + 2.0 + 1.1)
    rerrs = m.sent("RERR")
    first = [s for s in rerrs if s.src == N3][0]
    assert first.src == N3 and first.dst == N2 and first.ttl == 1
    assert N5 in dict(first.msg.unreachable)
    # 2 propagates to its precursor 1; 4 tells 5 that 1 is gone.
    assert [s for s in rerrs if s.src == N2 and s.dst == N1]
    assert [s for s in rerrs if s.src == N4 and N1 in dict(s.msg.unreachable)]
    # Loss detected between ALLOWED_HELLO_LOSS and ALLOWED_HELLO_LOSS+1 hello intervals.
    last_hello_4 = max(s.time for s in m.log if s.src == N4 and s.time < 5.0)
    assert 2.0 < first.time - last_hello_4 <= 2.0 + 0.01
    # Sequence number incremented on invalidation (RFC 6.11 case i).
    seq3 = m.nodes[N3].core.table.get(N5).seq
    assert dict(first.msg.unreachable)[N5] == seq3


def test_rerr_on_forwarded_data_without_route():
    m = chain()
    m.send_data(N1, N5)
    m.run_until(1.0)
    # Node 3 loses its route to 5 (as after a reboot of its table); data keeps coming.
    core3 = m.nodes[N3].core
    core3.table.remove(N5)
    m.nodes[N3].kernel.pop(N5)
    core3._installed.pop(N5)
    m.send_data(N1, N5, b"orphan")
    m.run_until(1.1)
    (rerr,) = [s for s in m.sent("RERR") if s.src == N3]
    assert rerr.msg.unreachable == ((N5, 0),) and rerr.dst == "255.255.255.255"
    # 2 has 3 as next hop to 5: invalidates and passes it to its precursor 1.
    assert [s for s in m.sent("RERR") if s.src == N2 and s.dst == N1]
    assert N5 not in m.nodes[N1].kernel


def test_kernel_route_lost_behind_our_back_is_reinstalled():
    core = AodvCore(N1, Params(), 0.0)
    acts = core.on_control(0.0, N2, 64, Rrep(N5, 3, N1, 6000, hop_count=3))
    assert InstallRoute(N5, N2, 4) in acts
    acts = core.on_no_route(0.1, N1, N5, b"pkt")
    assert acts[0] == InstallRoute(N5, N2, 4)
    assert acts[1:] == [ReleasePackets(N5, (b"pkt",))]
    acts = core.on_no_route(0.2, N9, N5, b"fwd")  # forwarded: same repair, no RERR
    assert acts == [InstallRoute(N5, N2, 4), ReleasePackets(N5, (b"fwd",))]


def test_rerr_from_someone_not_our_next_hop_is_ignored_and_n_flag():
    core = AodvCore(N1, Params(), 0.0)
    core.on_control(0.0, N2, 64, Rrep(N5, 3, N1, 6000, hop_count=3))
    assert core.on_control(0.1, N3, 1, Rerr(((N5, 4),))) == []
    assert core.on_control(0.1, N2, 1, Rerr(((N5, 4),), no_delete=True)) == []
    acts = core.on_control(0.2, N2, 1, Rerr(((N5, 4),)))
    assert DeleteRoute(N5) in acts and core.table.get(N5).seq == 4


def test_rerr_rate_limit():
    core = AodvCore(N3, Params(), 0.0)
    sent = []
    for k in range(25):
        sent += core.on_no_route(0.01 * k, N1, f"10.0.2.{k}", b"p")
    assert len([a for a in sent if isinstance(a.msg if hasattr(a, "msg") else None, Rerr)]) == 10
    assert core.dropped["rerr_ratelimit"] == 15


# -- RFC 6.2 lifetimes, DELETE_PERIOD -----------------------------------------------------
def test_idle_route_expires_active_route_stays_then_deleted_after_delete_period():
    m = chain(3)
    m.add_node(N4)
    m.link(N3, N4)
    flow(m, N1, N3, 0.0, 30.0, every=0.5)
    m.send_data(N1, N4)  # a single packet: this route then idles
    m.run_until(1.0)
    assert N4 in m.nodes[N1].kernel and N3 in m.nodes[N1].kernel
    m.run_until(13.0)  # MY_ROUTE_TIMEOUT (11.2 s) past, no use
    assert N4 not in m.nodes[N1].kernel
    assert N3 in m.nodes[N1].kernel  # refreshed by use
    entry = m.nodes[N1].core.table.get(N4)
    assert entry is not None and not entry.valid  # kept for DELETE_PERIOD
    m.run_until(13.0 + 15.0)
    assert m.nodes[N1].core.table.get(N4) is None


# -- RFC 6.13 reboot ----------------------------------------------------------------------
def test_rebooted_node_waits_delete_period_before_answering():
    m = Medium()
    m.add_node(N1)
    m.add_node(N2, rebooted=True)
    m.link(N1, N2)
    m.send_data(N1, N2)
    m.run_until(5.0)
    assert not m.sent("RREP", src=N2)
    assert N1 in m.nodes[N2].kernel  # routes are still learnt
    # Data for another destination: RERR and the wait restarts.
    core2 = m.nodes[N2].core
    acts = core2.on_no_route(m.now, N1, "10.0.0.50", b"x")
    assert [a for a in acts if isinstance(a, Broadcast) and isinstance(a.msg, Rerr)]
    assert core2.reboot_until == pytest.approx(m.now + 15.0)
    m.run_until(25.0)  # the wait is over and 1's first discovery has given up
    assert len(m.nodes[N1].unreachable) == 1
    m.send_data(N1, N2)
    m.run_until(26.0)
    assert m.sent("RREP", src=N2) and m.nodes[N2].delivered


def test_core_never_touches_io():
    import ast

    import aodv.core as core_mod

    tree = ast.parse(open(core_mod.__file__).read())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not names & {"socket", "time", "select", "asyncio", "os"}
