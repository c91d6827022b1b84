"""Host stalls (testbed.run.stalls): which missed deadlines the host caused."""

from testbed.run.stalls import STALL_S, StallTracker


def test_a_late_wake_up_covers_the_steps_it_ate_and_one_more():
    t = StallTracker(period=0.01)
    t.late(100, 0.030)  # 30 ms: steps 100-103, plus one to catch up
    assert [s for s in range(98, 108) if t.covers(s)] == [98, 99, 100, 101, 102, 103, 104]
    t.count(104, 3)
    t.count(105, 2)  # after the stall: the load's doing
    assert t.summary() == {"events": 1, "stalled_s": 0.03, "deadlines_missed": 3,
                           "granted_s": 0.0}  # fmt: skip


def test_ordinary_wake_up_jitter_is_not_a_stall():
    t = StallTracker(period=0.005)
    for step in range(1000):
        t.late(step, STALL_S / 2)
    t.count(500, 4)
    assert t.summary() == {"events": 0, "stalled_s": 0.0, "deadlines_missed": 0,
                           "granted_s": 0.0}  # fmt: skip


def test_stalls_that_overlap_extend_the_window():
    t = StallTracker(period=0.01)
    t.late(10, 0.025)  # covers to 10 + 3 + 1 = 14
    t.late(12, 0.05)  # covers to 12 + 5 + 1 = 18
    assert t.covers(18) and not t.covers(19)
    assert t.summary()["events"] == 2
