"""The step core on the most extreme inputs its callers can pass (issue 55): laser ranges of any
float32 (1e30 overflowed an int in hit_index), poses and teammates' goals of any finite size,
positions that are not finite or not a float32. The compiled functions stay equal to their
numpy twins and never convert a float out of an integer's range;
tests/integration/test_stepcore_sanitizers.py runs this file on the build with
UndefinedBehaviorSanitizer (float-cast-overflow included), where such a conversion stops the
process."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from node import planner, stepcore
from node.grid import FREE, OCC, OccupancyGrid
from node.rays import _BIAS, Laser
from tests.unit.test_stepcore import random_ternary

pytestmark = pytest.mark.skipif(
    not stepcore.NATIVE, reason="build/libstepcore.so not built (make setup builds it with g++)"
)
SETTINGS = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
EXTREME = [1e30, -1e30, 3.4e38, -3.4e38, 1e-30, -1e-30, 0.0, -0.0, math.inf, -math.inf, math.nan]
ranges_f32 = st.one_of(
    st.sampled_from(EXTREME),
    st.floats(width=32),
    st.floats(-1.0, 3.0, width=32),
)
huge = st.one_of(
    st.sampled_from([1e300, -1e300, 1e30, -1e30, 3e9, -3e9, 2.0**31, -(2.0**31), 0.0, -0.0]),
    st.floats(allow_nan=False, allow_infinity=False),
)


def test_hit_index_clamps_before_it_converts():
    laser = Laser(2.0, 8, 0.05)
    r = np.array([1e30, -1e30, 3.4e38, -3.4e38, np.nan, np.inf, -np.inf, 1.0], np.float32)
    assert laser.hit_index(r).tolist() == [80, 0, 80, 0, 80, 80, 80, 39]


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.sampled_from([(1.0, 90), (2.0, 360), (0.6, 37)]),
       st.lists(ranges_f32, min_size=1, max_size=40))  # fmt: skip
@example(0, (2.0, 360), [1e30])
@example(0, (2.0, 360), [-1e30, 3.4e38, math.nan])
def test_a_scan_with_extreme_ranges_is_the_same_in_both(seed, geometry, drawn):
    """Any float32 as a range: the compiled scan into both maps equals the numpy one."""
    rng = np.random.default_rng(seed)
    laser = Laser(geometry[0], geometry[1], 0.05)
    ranges = np.resize(np.array(drawn, dtype=np.float32), laser.n_rays)
    rng.shuffle(ranges)
    shape = (80, 90)
    x, y = rng.uniform(0.5, shape[1] * 0.05 - 0.5), rng.uniform(0.5, shape[0] * 0.05 - 0.5)
    grid_a = OccupancyGrid(shape, 0.05, pad=laser.pad)
    grid_b = OccupancyGrid(shape, 0.05, pad=laser.pad)
    own_a = np.zeros(grid_a.Lp.shape, dtype=np.uint8)
    own_b = own_a.copy()
    assert stepcore.scan_into(laser, x, y, ranges, grid_a.Lp, own_a, grid_a.params, _BIAS)
    r0, c0, fr, oc = laser.scan_window(x, y, ranges)
    grid_b.update_window(r0, c0, fr, oc)
    h, w = fr.shape
    window = own_b[r0 : r0 + h, c0 : c0 + w]
    window[fr] = FREE
    window[np.divmod(oc, w)] = OCC
    assert np.array_equal(grid_a.Lp, grid_b.Lp)
    assert np.array_equal(own_a, own_b)


@SETTINGS
@given(st.integers(0, 2**32 - 1), huge, huge, st.lists(st.tuples(huge, huge), max_size=4))
@example(0, 1e300, -1e300, [(1e300, -1e300), (3e9, 3e9)])
def test_a_plan_from_anywhere_with_goals_anywhere_is_the_same_in_both(seed, px, py, goals):
    """A pose and teammates' goals of any finite size (a goal comes from a teammate): the
    compiled planner clamps the start cell and each goal's window as Python's ints do."""
    rng = np.random.default_rng(seed)
    t = random_ternary(rng, 40, 50)
    prm = planner.PlannerParams(0.05, int(rng.integers(1, 4)), 0.15)
    ref = planner.plan_reference(t, (px, py), goals, 1.0, prm, True)
    assert planner.plan(t, (px, py), goals, 1.0, prm, True) == ref


@pytest.mark.parametrize(
    "xy",
    [(math.nan, 1.0), (1.0, math.inf), (-math.inf, 1.0), (3.4e38, 1.0), (1.0, -1e300),
     (1e30, 1e30), (-100.0, 1.0), (4.51, 1.0)],
)  # fmt: skip
def test_a_laser_anywhere_else_does_nothing(xy):
    """Not finite, not a float32, or off the map: no window fits, nothing is done."""
    laser = Laser(1.0, 90, 0.05)
    shape = (80, 90)
    grid = OccupancyGrid(shape, 0.05, pad=laser.pad)
    own = np.zeros(grid.Lp.shape, dtype=np.uint8)
    before = grid.Lp.copy()
    ranges = np.full(laser.n_rays, 0.5, dtype=np.float32)
    assert not stepcore.scan_into(laser, *xy, ranges, grid.Lp, own, grid.params, _BIAS)
    assert np.array_equal(grid.Lp, before) and not own.any()
    occ = np.zeros(grid.Lp.shape, dtype=np.uint8)
    assert stepcore.cast_window(laser, occ, occ.copy(), *xy, 0, _BIAS) is None
