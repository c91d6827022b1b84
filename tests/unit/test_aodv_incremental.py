"""The AODV core's incremental bookkeeping (aodv/routes.py, aodv/neighbors.py) against the
full passes it replaces: after every event the core compares only the routing entries the
event touched with the kernel, and keeps heaps of the routes' and neighbours' deadlines. Two
cores take the same random events (HELLOs, RREQs, RREPs, RERRs, RREP-ACKs from a handful of
neighbours, data without a route, route use, lost links, timers); one of them is made to
take the full pass after every event. Their actions must be equal, list for list, and the
incremental core's next deadline must be the minimum a full scan finds."""

from hypothesis import given, settings
from hypothesis import strategies as st

from aodv.actions import DeleteRoute, InstallRoute
from aodv.core import AodvCore
from aodv.packet import Rerr, Rrep, RrepAck, Rreq
from aodv.params import profile
from aodv.routes import RoutingTable

ME = "10.0.0.1"
PEERS = [f"10.0.0.{k}" for k in range(2, 9)]


class FullPassTable(RoutingTable):
    """A table that reports every entry touched after every event: the old full pass."""

    def take_touched(self):
        self._touched = None
        return super().take_touched()


addr = st.sampled_from(PEERS)
seq = st.integers(0, 12)
hops = st.integers(0, 6)

hello = st.builds(lambda a, s: ("ctl", a, 1, Rrep(a, s, a, 2000, 0, hello_interval_ms=1000)),
                  addr, seq)  # fmt: skip
rreq = st.builds(
    lambda src, rid, dest, dseq, orig, oseq, h, ttl, unknown: (
        "ctl", src, ttl, Rreq(rid, dest, dseq, orig, oseq, h, unknown_seq=unknown)),
    addr, st.integers(0, 5), st.sampled_from([ME, *PEERS]), seq, addr, seq, hops,
    st.integers(1, 5), st.booleans(),
)  # fmt: skip
rrep = st.builds(
    lambda src, dest, dseq, orig, life, h, ack: (
        "ctl", src, 3, Rrep(dest, dseq, orig, life, h, ack_required=ack)),
    addr, addr, seq, st.sampled_from([ME, *PEERS]), st.integers(0, 6000), hops, st.booleans(),
)  # fmt: skip
rerr = st.builds(
    lambda src, dests, nd: ("ctl", src, 1, Rerr(tuple(dests), nd)),
    addr, st.lists(st.tuples(addr, seq), min_size=1, max_size=3), st.booleans(),
)  # fmt: skip
ack = st.builds(lambda src: ("ctl", src, 1, RrepAck()), addr)
no_route = st.builds(lambda src, dst: ("noroute", src, dst), st.sampled_from([ME, *PEERS]), addr)
used = st.builds(lambda a: ("used", a), addr)
lost = st.builds(lambda a: ("lost", a), addr)
timer = st.just(("timer",))
event = st.one_of(hello, hello, rreq, rrep, rerr, ack, no_route, used, lost, timer)
step = st.tuples(st.floats(0.0, 1.5, allow_nan=False), event)


def apply(core: AodvCore, now: float, ev: tuple) -> list:
    kind = ev[0]
    if kind == "ctl":
        return core.on_control(now, ev[1], ev[2], ev[3])
    if kind == "noroute":
        return core.on_no_route(now, ev[1], ev[2], b"data")
    if kind == "used":
        return core.on_route_used(now, ev[1])
    if kind == "lost":
        return core.on_link_lost(now, ev[1])
    return core.on_timer(now)


def full_scan_deadline(core: AodvCore) -> float:
    """next_deadline as the core computed it before the heaps: a scan of every entry."""
    dp = core.p.delete_period
    t = core.next_hello
    lifetimes = [r.lifetime for r in core.table.peek_all()]
    nbrs = []
    for n in core.neighbors._n.values():
        if n.last_hello is None:
            continue
        monitored = n.last_hello >= n.last_heard + n.timeout - dp
        nbrs.append(n.last_heard + n.timeout if monitored else n.last_heard + dp)
    for c in (min(lifetimes, default=None), min(nbrs, default=None), core.reboot_until):
        if c is not None and c < t:
            t = c
    for d in core.discoveries.values():
        t = min(t, d.deadline)
    if core.pending_acks:
        t = min(t, *core.pending_acks.values())
    return t


@settings(max_examples=300, deadline=None)
@given(st.lists(step, min_size=1, max_size=80), st.sampled_from(["rfc", "ns3"]))
def test_incremental_bookkeeping_acts_as_the_full_pass(steps, prof):
    p = profile(prof)
    now = 100.0
    fast = AodvCore(ME, p, now)
    full = AodvCore(ME, p, now)
    full.table = FullPassTable()
    for dt, ev in steps:
        now += dt
        # Timers when due, as the daemon's loop calls them, then the event.
        for _ in range(10):
            if fast.next_deadline() > now:
                break
            assert fast.on_timer(now) == full.on_timer(now)
        assert apply(fast, now, ev) == apply(full, now, ev), ev
        assert fast.routes() == full.routes()
        assert fast.next_deadline() == full_scan_deadline(fast) == full.next_deadline()


def kernel_after(actions: list, kernel: dict) -> dict:
    """The kernel routes (dest: (next hop, hops)) once `actions` are carried out."""
    for a in actions:
        if isinstance(a, InstallRoute):
            kernel[a.dest] = (a.next_hop, a.hops)
        elif isinstance(a, DeleteRoute):
            kernel.pop(a.dest, None)
    return kernel


@settings(max_examples=200, deadline=None)
@given(st.lists(step, max_size=60), st.lists(addr, min_size=1, max_size=8),
       st.lists(step, max_size=20))  # fmt: skip
def test_route_uses_in_one_event_end_as_one_event_each(before, uses, after):
    """The daemon hands a poll's route uses to the core in one event (on_routes_used): the
    routing table, the kernel's routes and the next deadline end as with one on_route_used
    each, and the two cores go on alike."""
    p = profile("rfc")
    now = 100.0
    one, each = AodvCore(ME, p, now), AodvCore(ME, p, now)
    k_one: dict = {}
    k_each: dict = {}
    for dt, ev in before:
        now += dt
        k_one = kernel_after(apply(one, now, ev), k_one)
        k_each = kernel_after(apply(each, now, ev), k_each)
    kernel_after(one.on_routes_used(now, uses), k_one)
    for a in uses:
        kernel_after(each.on_route_used(now, a), k_each)
    assert k_one == k_each
    assert one.routes() == each.routes()
    assert one.next_deadline() == each.next_deadline()
    for dt, ev in after:
        now += dt
        assert apply(one, now, ev) == apply(each, now, ev), ev
