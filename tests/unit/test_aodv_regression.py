"""ns-3's aodv-regression scenario on the in-memory medium.

ns-3 src/aodv/test: a chain of 5 nodes, pings from the first to the last; at one third of
the run the middle node moves out of range. Here it also comes back at two thirds, so the
test sees discovery (RREQ/RREP), data, the break (RERR up the chain), failed rediscovery
while the chain is cut, and successful rediscovery once it is whole again.
"""

from aodv.params import Params
from aodv.sim import Medium

A = [f"10.0.0.{i}" for i in range(1, 6)]
N1, N2, N3, N4, N5 = A
T = 60.0


def run_scenario():
    m = Medium(Params())
    m.chain(A)
    t = 0.0
    while t < T:
        m.at(t, lambda: m.send_data(N1, N5))
        t += 0.5

    def leave():
        m.unlink(N2, N3)
        m.unlink(N3, N4)

    def come_back():
        m.link(N2, N3)
        m.link(N3, N4)

    m.at(T / 3, leave)
    m.at(2 * T / 3, come_back)
    m.run_until(T + 1)
    return m


def test_aodv_regression_chain_middle_node_leaves():
    m = run_scenario()
    delivered = [t for t, src, _ in m.nodes[N5].delivered if src == N1]
    kinds = [(s.time, s.kind, s.src, s.dst) for s in m.log if s.kind != "HELLO"]

    # Phase 1: discovery, then every ping delivered until the middle node leaves.
    assert kinds[0][1:3] == ("RREQ", N1)
    first_rrep = next(k for k in kinds if k[1] == "RREP")
    assert first_rrep[2] == N5
    assert len([t for t in delivered if t < T / 3]) == 40  # all pings of the first third
    assert m.nodes[N1].discoveries[0].ok

    # Phase 2: HELLO loss -> RERR from both sides of the gap, up to the ends.
    rerrs = [k for k in kinds if k[1] == "RERR"]
    assert rerrs and all(T / 3 < k[0] < T / 3 + 2.5 for k in rerrs[:4])
    assert {(k[2], k[3]) for k in rerrs} >= {(N2, N1), (N4, N5)}
    assert not [t for t in delivered if T / 3 + 0.01 < t < 2 * T / 3]
    # Rediscovery by 1 fails while the chain is cut: ICMP unreachable for its packets.
    failed = [d for d in m.nodes[N1].discoveries if not d.ok]
    assert failed and m.nodes[N1].unreachable
    rreqs_cut = [k for k in kinds if k[1] == "RREQ" and k[2] == N1 and T / 3 < k[0] < 2 * T / 3]
    assert rreqs_cut

    # Phase 3: the node is back; rediscovery succeeds, pings flow again over 4 hops.
    late = [t for t in delivered if t > 2 * T / 3]
    assert late and late[0] < 2 * T / 3 + 25  # at worst one failed discovery later
    assert m.nodes[N1].kernel[N5] == (N2, 4)
    assert m.nodes[N1].discoveries[-1].ok
    # The first rediscovery carries the sequence number the RERR made known (RFC 6.11:
    # incremented past the one the old route had), so no stale route can answer it.
    first_cut = [s for s in m.sent("RREQ", src=N1) if s.time > T / 3][0]
    assert not first_cut.msg.unknown_seq and first_cut.msg.dest_seq == 1


def test_warm_up_leaves_nothing_in_the_robots_log(caplog):
    """The daemon warms up on throwaway chains before its first message: their links going
    silent must not appear in the robot's log as if they were its own (10.255.0.x)."""
    import logging

    from aodv.sim import warm_up

    with caplog.at_level(logging.DEBUG):
        warm_up(Params(time_scale=4.0))  # a run's scale: its chains' links time out
        logging.getLogger("aodv.core").info("after the warm-up")
    assert [r.getMessage() for r in caplog.records] == ["after the warm-up"]


def test_the_warm_up_is_the_same_events_at_every_time_scale(monkeypatch):
    """The daemon's warm-up runs its chains for 2 s of the run's clock: at a high time scale
    it does the protocol events it does at 1, not K times as many (it did: 125 ms of each
    daemon's start at 30, against 17 ms at 1)."""
    from aodv import core
    from aodv.sim import warm_up

    def events(scale: float) -> int:
        seen = [0]
        for name in ("on_timer", "on_control"):
            real = getattr(core.AodvCore, name)

            def counted(self, *a, _real=real, **kw):
                seen[0] += 1
                return _real(self, *a, **kw)

            monkeypatch.setattr(core.AodvCore, name, counted)
        warm_up(Params(time_scale=scale))
        monkeypatch.undo()
        return seen[0]

    at_one = events(1.0)
    assert at_one > 100  # discoveries and HELLOs ran
    for scale in (7.0, 30.0):
        assert at_one * 0.8 <= events(scale) <= at_one * 1.25
