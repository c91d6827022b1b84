"""The step clock (testbed.run.stepclock): deadlines, lateness, misses and the achieved scale,
with made-up times (the clock never reads the time itself)."""

import pytest

from testbed.files.resultfile import MAX_MISSED_STEPS_KEPT
from testbed.run.stalls import STALL_S
from testbed.run.stepclock import StepClock, no_clock

T0 = 1000.0


def test_deadlines_follow_the_period_from_the_anchor():
    c = StepClock(time_scale=10.0, robots=3, now=T0)
    assert c.period == pytest.approx(0.01)
    assert c.deadline() == pytest.approx(T0 + 0.01)  # step 0's frames are answered by then
    assert c.deadline(4) == pytest.approx(T0 + 0.05)
    assert c.late(T0 + 0.004) == pytest.approx(-0.006)
    assert c.advance() == 1 and c.step == 1
    assert c.deadline() == pytest.approx(T0 + 0.02)
    assert c.late(T0 + 0.025) == pytest.approx(0.005)


def test_a_world_overrun_counts_once_and_moves_the_schedule():
    c = StepClock(time_scale=1.0, robots=2, now=T0)  # 100 ms steps
    c.advance()
    assert c.world_done(T0 + 0.15) == 0.0  # step 1 is due at T0 + 0.2
    c.advance()
    late = c.world_done(T0 + 0.33)  # step 2 was due at T0 + 0.3
    assert late == pytest.approx(0.03)
    assert c.missed_world == 1 and c.world_missed_steps == [(2, 30.0)]
    # Shifted, not caught up: the robots get a whole period for the frames sent at T0 + 0.33.
    assert c.deadline() == pytest.approx(T0 + 0.43)
    assert c.deadline(3) == pytest.approx(T0 + 0.53)
    c.advance()
    assert c.world_done(T0 + 0.52) == 0.0  # in time on the new schedule
    assert c.missed_world == 1


def test_misses_fractions_and_host_stalls_are_computed_once_in_the_summary():
    c = StepClock(time_scale=1.0, robots=3, now=T0)
    c.woke(T0 + 0.1 + STALL_S / 2)  # a little late: no stall
    c.robots_missed(1)  # outside any stall
    c.advance()
    c.woke(T0 + 0.2 + 0.03)  # the host stopped the machine 30 ms
    c.robots_missed(2)  # these fall in the stall
    for _ in range(8):
        c.advance()
    c.stop(T0 + 1.25)
    s = c.summary()
    assert s.steps == 9 and s.loop_wall_s == pytest.approx(1.25)
    assert s.time_scale_achieved == pytest.approx(9 * 0.1 / 1.25)
    assert (s.missed_robots, s.missed_world, s.deadlines_missed) == (3, 0, 3)
    assert s.stalls == {"events": 1, "stalled_s": 0.03, "deadlines_missed": 2,
                        "granted_s": 0.03}  # fmt: skip
    assert s.miss_fraction == round(3 / (9 * 4), 5)
    # Host stalls excluded: only the miss no slower clock would have helped is left.
    assert s.miss_fraction_outside_stalls == round(1 / (9 * 4), 5)


def test_a_loop_that_did_not_end_has_no_wall_time_and_no_scale():
    c = StepClock(time_scale=2.0, robots=1, now=T0)
    c.advance()
    assert c.achieved_scale(T0 + 0.05) == pytest.approx(2.0)  # live, while it runs
    s = c.summary()
    assert (s.steps, s.loop_wall_s, s.time_scale_achieved) == (1, 0.0, 0.0)
    empty = no_clock(4)
    assert (empty.steps, empty.deadlines_missed, empty.miss_fraction) == (0, 0, 0.0)
    assert empty.stalls == {"events": 0, "stalled_s": 0.0, "deadlines_missed": 0,
                            "granted_s": 0.0}  # fmt: skip


def test_a_stall_gives_the_robots_back_their_time_and_moves_the_schedule():
    """Woken 30 ms late (period 100 ms), the world waits 30 ms more before it takes the
    step's commands, and every later deadline moves by the 60 ms; a stall longer than a
    period gives back one period; an ordinary late wake-up gives back nothing."""
    c = StepClock(time_scale=1.0, robots=1, now=T0)
    assert c.woke(T0 + 0.1 + STALL_S / 2) == 0.0
    assert c.deadline() == pytest.approx(T0 + 0.1)
    c.advance()
    assert c.woke(T0 + 0.2 + 0.03) == pytest.approx(0.03)
    assert c.deadline() == pytest.approx(T0 + 0.26)  # the commands are taken then
    c.advance()
    assert c.deadline() == pytest.approx(T0 + 0.36)  # a full period for the next step
    assert c.woke(T0 + 0.36 + 0.5) == pytest.approx(0.1)
    assert c.deadline() == pytest.approx(T0 + 0.36 + 0.5 + 0.1)
    assert c.summary().stalls["granted_s"] == pytest.approx(0.13)


def test_the_world_missed_steps_kept_are_capped():
    c = StepClock(time_scale=1.0, robots=1, now=T0)
    for _ in range(MAX_MISSED_STEPS_KEPT + 5):
        c.advance()
        c.world_done(c.deadline() + 0.001)
    assert c.missed_world == MAX_MISSED_STEPS_KEPT + 5
    assert len(c.world_missed_steps) == MAX_MISSED_STEPS_KEPT


def test_the_warm_up_wait_moves_the_schedule_and_is_counted_apart():
    """Waiting 0.4 s for the robots' first answers misses nothing and moves every later
    deadline by the wait."""
    c = StepClock(time_scale=10.0, robots=2, now=T0)
    assert c.woke(T0 + 0.01) == 0.0
    c.warmed_up(0.4)
    c.advance()
    assert c.deadline() == pytest.approx(T0 + 0.02 + 0.4)
    assert (c.warmup_s, c.missed_robots, c.missed_world) == (pytest.approx(0.4), 0, 0)
