"""RFC 3561 rules a review found broken, one test per finding, named after the section.

Each runs AODV cores on the in-memory medium (aodv/sim.py) or one core by hand, and failed
before the fix it names (see the commit that added this file)."""

import pytest

from aodv import seqnum
from aodv.core import AodvCore, Broadcast, Unicast
from aodv.packet import MalformedPacket, Rerr, Rrep, Rreq, decode
from aodv.params import Params
from aodv.persist import CounterStore
from aodv.routes import Route
from tests.unit.test_aodv_core import A, chain, flow

N1, N2, N3, N4, N5, N6, N7 = A[:7]


def sends(actions):
    return [a for a in actions if isinstance(a, (Unicast, Broadcast))]


# -- Finding 1: sequence numbers go backwards through RERRs ---------------------------------
def test_6_1_a_rerr_from_a_node_without_an_entry_does_not_lower_sequence_numbers():
    m = chain()
    m.nodes[N5].core.seq = 7
    m.send_data(N1, N5)
    m.run_until(1.0)
    assert m.nodes[N1].core.table.get(N5).seq == 7
    # Node 4 forgets its route to 5 (as after its DELETE_PERIOD ran out) while 1 still
    # holds one through it: 4 answers the next packet with a RERR about 5 (case ii).
    m.unlink(N4, N5)
    m.run_until(1.05)  # what was on the air has landed
    four = m.nodes[N4]
    four.core.table.remove(N5)
    four.core._installed.pop(N5, None)
    four.kernel.pop(N5)
    m.send_data(N1, N5, b"second")
    m.run_until(1.1)
    assert [s for s in m.sent("RERR", src=N4) if s.time > 1.0]
    for node in (N3, N2, N1):
        entry = m.nodes[node].core.table.get(N5)
        assert not entry.valid, node
        assert entry.seq == 7, f"{node} lowered the sequence number of {N5} to {entry.seq}"
    # The next discovery asks for at least what was known, U clear.
    m.send_data(N1, N5, b"third")
    m.run_until(1.2)
    rreq = [s for s in m.sent("RREQ", src=N1) if s.time > 1.0][0]
    assert rreq.msg.dest_seq == 7 and not rreq.msg.unknown_seq


def test_6_1_an_older_number_in_a_rerr_invalidates_the_route_but_keeps_the_number():
    core = AodvCore(N2, Params(), 0.0)
    core.table.add(Route(N5, N3, 3, 9, True, 10.0))
    core.on_control(0.5, N3, 1, Rerr(((N5, 4),)))
    entry = core.table.get(N5)
    assert not entry.valid and entry.seq == 9
    core.table.add(Route(N6, N3, 3, 9, True, 10.0))
    core.on_control(0.6, N3, 1, Rerr(((N6, 12),)))
    assert core.table.get(N6).seq == 12  # newer information is taken


def test_6_11_an_invalid_entry_that_draws_a_rerr_gets_its_number_incremented():
    core = AodvCore(N4, Params(), 0.0)
    core.table.add(Route(N5, N5, 1, 7, True, 20.0, valid=False))
    out = core.on_no_route(1.0, N1, N5, b"pkt")
    (rerr,) = [a.msg for a in sends(out) if isinstance(a.msg, Rerr)]
    assert rerr.unreachable == ((N5, 8),)
    assert core.table.get(N5).seq == 8


# -- Finding 2: discovery retries lose the known sequence number ----------------------------
def test_6_4_every_retry_of_a_discovery_asks_for_the_known_number():
    core = AodvCore(N1, Params(), 0.0)
    p = core.p
    # Invalidated at 0 (kept until DELETE_PERIOD); data for it only comes at 10 s.
    core.table.add(Route(N5, N2, 4, 7, True, p.delete_period, valid=False))
    now = 10.0
    rreqs = [a.msg for a in sends(core.on_no_route(now, N1, N5, b"pkt"))]
    while N5 in core.discoveries:
        now = core.next_deadline()
        rreqs += [a.msg for a in sends(core.on_timer(now)) if isinstance(a.msg, Rreq)]
    assert now > p.delete_period + 5  # the discovery outlived the entry's first lifetime
    assert [r.rreq_id for r in rreqs] == [1, 2, 3, 4]  # TTL 4 hops + 2, then 35 three times
    assert all(r.dest_seq == 7 and not r.unknown_seq for r in rreqs), rreqs


# -- Finding 3: reboot ----------------------------------------------------------------------
def test_6_13_a_restarted_node_waits_and_never_reuses_its_numbers(tmp_path):
    p = Params()
    m = chain(3)
    store = CounterStore(str(tmp_path / "n1.state"))
    assert store.load() is None  # a first start: no wait
    m.send_data(N1, N3)
    m.run_until(1.0)
    old = m.nodes[N1].core
    store.cover(old.seq, old.rreq_id)
    used_ids = {s.msg.rreq_id for s in m.sent("RREQ", src=N1)}
    # The daemon restarts: a clean exit, no kernel routes left; its saved counters say so.
    seq, rreq_id = CounterStore(store.path).load()
    t0 = m.now
    new = m.nodes[N1].core = AodvCore(N1, p, t0, rebooted=True, seq=seq, rreq_id=rreq_id)
    m.nodes[N1].kernel.clear()
    m.send_data(N1, N3, b"after")
    m.run_until(t0 + p.delete_period - 0.01)
    late = [s for s in m.sent(src=N1) if s.time >= t0 and s.kind in ("RREQ", "RREP", "RERR")]
    assert not late, "a rebooted node originated control messages within DELETE_PERIOD"
    m.run_until(t0 + p.delete_period + 1.0)
    after = [s.msg for s in m.sent("RREQ", src=N1) if s.time >= t0]
    assert after and after[0].rreq_id not in used_ids
    assert seqnum.newer(after[0].orig_seq, old.seq)
    assert m.nodes[N3].delivered[-1][2].endswith(b"after")
    assert new.reboot_until is None


def test_6_13_counter_store_resumes_above_everything_used(tmp_path):
    store = CounterStore(str(tmp_path / "s"))
    used = []
    seq = rid = 0
    for _ in range(3000):
        seq, rid = seqnum.increment(seq), seqnum.increment(rid)
        store.cover(seq, rid)  # before the message carrying them leaves
        used.append((seq, rid))
    s0, r0 = CounterStore(store.path).load()
    assert all(seqnum.newer(s0 + 1, s) and seqnum.newer(r0 + 1, r) for s, r in used)
    assert store.writes <= 3000 // store.block + 1  # a write per block, not per message


def test_6_13_corrupt_counter_file_still_counts_as_a_reboot(tmp_path):
    path = tmp_path / "s"
    path.write_text("{not json")
    assert CounterStore(str(path)).load() == (0, 0)  # a restart; the wait protects


# -- Finding 4: hostile but decodable fields -----------------------------------------------
def test_5_hop_count_255_is_dropped_not_incremented_past_a_byte():
    core = AodvCore(N2, Params(), 0.0)
    out = core.on_control(0.0, N1, 35, Rreq(1, N5, 0, N6, 1, hop_count=255))
    out += core.on_control(0.0, N1, 64, Rrep(N5, 3, N6, 1000, hop_count=255))
    for a in sends(out):
        a.msg.encode()  # everything the core emits fits the wire
    assert core.dropped["hop_count"] == 2
    assert core.table.get(N5) is None and core.table.get(N6) is None


def test_6_9_hello_interval_extremes_are_clamped():
    core = AodvCore(N2, Params(), 0.0)
    core.on_control(0.0, N1, 1, Rrep(N1, 1, N1, 2000, hello_interval_ms=0))
    core.on_timer(0.01)
    assert core.table.valid(N1) is not None, "HELLO interval 0 declared the link lost"
    core.on_control(0.0, N3, 1, Rrep(N3, 1, N3, 2000, hello_interval_ms=0xFFFFFFFF))
    assert core.table.get(N3).lifetime <= 2 * 16 * core.p.hello_interval
    # A RREQ for N3 from N1: the intermediate reply's Lifetime fits 32 bits.
    out = core.on_control(0.1, N1, 5, Rreq(7, N3, 1, N1, 5, hop_count=0))
    for a in sends(out):
        a.msg.encode()
    assert core.dropped["hello_interval_clamped"] == 2


def test_6_7_rrep_lifetime_is_bounded():
    core = AodvCore(N2, Params(), 0.0)
    core.on_control(0.0, N3, 64, Rrep(N5, 3, N2, 0xFFFFFFFF, hop_count=2))
    assert core.table.get(N5).lifetime <= 10 * core.p.my_route_timeout
    assert core.dropped["lifetime_clamped"] == 1


# -- Finding 5: unbounded state under a flood -----------------------------------------------
def test_6_5_a_flood_of_forged_originators_is_bounded():
    p = Params()
    core = AodvCore(N2, p, 0.0)
    forwards = 0
    for k in range(5000):
        orig = f"10.0.{1 + k // 250}.{1 + k % 250}"
        out = core.on_control(k / 5000, N1, 10, Rreq(k, N5, 0, orig, 1, hop_count=1))
        forwards += sum(isinstance(a, Broadcast) for a in out)
    assert forwards <= p.rreq_forward_ratelimit
    assert core.dropped["rreq_forward_ratelimit"] == 5000 - forwards
    assert len(core.table) <= p.route_table_limit
    assert len(core.rreq_cache) <= p.rreq_cache_limit
    assert core.dropped["route_evicted"] > 0
    # The kernel view (what the core told the daemon to install) equals the table.
    assert set(core._installed) == {r.dest for r in core.table if r.valid}


def test_6_5_the_table_bound_evicts_idle_before_active_routes():
    p = Params(route_table_limit=16)
    core = AodvCore(N2, p, 0.0)
    core.table.add(Route(N5, N3, 2, 4, True, 100.0, active_until=100.0))
    for k in range(40):
        core.on_control(0.001 * k, N1, 10, Rreq(k, N6, 0, f"10.0.9.{k + 1}", 1, hop_count=1))
    assert core.table.valid(N5) is not None


# -- Finding 6: local repair and the N flag --------------------------------------------------
def repair_net():
    """1-2-3-4-5, and a longer way round from 3: 3-6-7-5."""
    m = chain()
    for a in (N6, N7):
        m.add_node(a)
    m.link(N3, N6)
    m.link(N6, N7)
    m.link(N7, N5)
    return m


def test_6_12_local_repair_keeps_the_route_and_sends_rerr_with_n():
    m = repair_net()
    flow(m, N1, N5, 0.0, 12.0)
    m.run_until(3.0)
    assert m.nodes[N1].kernel[N5] == (N2, 4)
    m.unlink(N3, N4)
    m.run_until(12.5)
    repair = [s for s in m.sent("RREQ", src=N3) if s.msg.orig == N3 and s.msg.dest == N5]
    assert repair, "node 3 did not try a local repair"
    # TTL max(MIN_REPAIR_TTL = 2 hops, 0.5 * #hops) + LOCAL_ADD_TTL; the number went up.
    assert repair[0].ttl == 2 + 2 and not repair[0].msg.unknown_seq
    assert m.nodes[N3].kernel[N5] == (N6, 3)
    # The new way is longer: a RERR with N, passed on by 2 to 1, and nobody deleted.
    rerr_n = [s for s in m.sent("RERR") if s.msg.no_delete]
    assert {s.src for s in rerr_n} >= {N3, N2}
    assert not [s for s in m.sent("RERR") if not s.msg.no_delete and N5 in dict(s.msg.unreachable)]
    assert not [s for s in m.sent("RREQ", src=N1) if s.msg.orig == N1 and s.time > 3.0]
    assert m.nodes[N1].kernel[N5] == (N2, 4)
    delivered = [t for t, src, _ in m.nodes[N5].delivered if t > 8.0]
    assert len(delivered) >= 12  # the flow goes on through the repaired route


def test_6_12_failed_local_repair_falls_back_to_rerr():
    m = chain()
    flow(m, N1, N5, 0.0, 12.0)
    m.run_until(3.0)
    m.unlink(N3, N4)
    m.run_until(9.0)
    assert [s for s in m.sent("RREQ", src=N3) if s.msg.orig == N3 and s.msg.dest == N5]
    rerr = [s for s in m.sent("RERR", src=N3) if N5 in dict(s.msg.unreachable)]
    assert rerr and not rerr[0].msg.no_delete
    assert N5 not in m.nodes[N1].kernel or m.sent("RREQ", src=N1)


def test_6_12_local_repair_can_be_turned_off():
    m = chain(local_repair=False)
    flow(m, N1, N5, 0.0, 8.0)
    m.run_until(3.0)
    m.unlink(N3, N4)
    m.run_until(8.0)
    assert not [s for s in m.sent("RREQ", src=N3) if s.msg.orig == N3]


# -- Section 9: extensions ------------------------------------------------------------------
def test_9_extensions_of_type_128_or_more_are_not_skipped():
    rreq = Rreq(1, N5, 0, N1, 1).encode()
    assert decode(rreq + bytes((50, 2, 0, 0))).dest == N5  # < 128: skipped
    with pytest.raises(MalformedPacket, match="may not be skipped"):
        decode(rreq + bytes((200, 2, 0, 0)))
