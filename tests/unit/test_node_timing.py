"""The robot's timings (node.timing): every duration derived from the step and time scale."""

import math

import pytest

from node.timing import STEP_S, RobotTimings


def test_values_at_time_scale_1_are_the_emulated_ones():
    t = RobotTimings(time_scale=1.0, map_period=10)
    assert STEP_S == 0.1
    assert t.neighbour_hold_s == pytest.approx(1.5)  # 1.5 map periods of 10 steps
    assert t.goal_send_timeout_ms == 50
    assert (t.goal_reconnect_min_ms, t.goal_reconnect_max_ms) == (50, 500)
    assert t.flood_linger_s == 0.001  # capped at 1 ms


def test_every_derived_value_follows_the_time_scale():
    slow, fast = RobotTimings(time_scale=1.0), RobotTimings(time_scale=5.0)
    assert fast.neighbour_hold_s == pytest.approx(slow.neighbour_hold_s / 5)
    assert fast.goal_send_timeout_ms == 10
    assert (fast.goal_reconnect_min_ms, fast.goal_reconnect_max_ms) == (10, 100)
    assert RobotTimings(time_scale=20.0).flood_linger_s == pytest.approx(0.0005)


def test_floors_hold_at_high_time_scales():
    assert RobotTimings(time_scale=100.0).goal_send_timeout_ms == 2
    t = RobotTimings(time_scale=1000.0)
    assert (t.goal_reconnect_min_ms, t.goal_reconnect_max_ms) == (1, 1)  # nng's whole ms


def test_the_map_period_sets_the_neighbour_hold():
    assert RobotTimings(map_period=20).neighbour_hold_s == pytest.approx(3.0)


def test_values_equal_the_formulas_they_replaced():
    for scale in (1.0, 3.75, 4.0, 15.0):
        t = RobotTimings(time_scale=scale, map_period=10)
        assert t.neighbour_hold_s == 1.5 * 10 * 0.1 / scale
        assert t.goal_send_timeout_ms == max(2, round(50 / scale))
        assert t.flood_linger_s == min(0.001, 0.01 / scale)


@pytest.mark.parametrize("scale", [0.0, -1.0, math.inf, math.nan])
def test_a_bad_time_scale_is_refused(scale):
    with pytest.raises(ValueError):
        RobotTimings(time_scale=scale)


def test_a_bad_map_period_is_refused():
    with pytest.raises(ValueError):
        RobotTimings(map_period=0)
