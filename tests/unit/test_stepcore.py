"""The compiled per-step work (node.stepcore) against its numpy reference, cell for cell, on
random maps, poses, goals and scans (Hypothesis draws the seeds and shapes; numpy draws the
cells from them)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from node import planner, stepcore
from node.grid import FREE, OCC, UNKNOWN, LogOdds, OccupancyGrid, classify
from node.rays import _BIAS, Laser

pytestmark = pytest.mark.skipif(
    not stepcore.NATIVE, reason="build/libstepcore.so not built (make setup builds it with g++)"
)
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
seeds = st.integers(0, 2**32 - 1)


def random_ternary(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """An explored-looking map: free discs in the unknown, walls and blocks, some noise."""
    t = np.zeros((h, w), dtype=np.uint8)
    yy, xx = np.mgrid[:h, :w]
    for _ in range(rng.integers(1, 8)):
        cy, cx, r = rng.integers(0, h), rng.integers(0, w), rng.integers(3, max(4, h // 2))
        t[(yy - cy) ** 2 + (xx - cx) ** 2 <= r * r] = FREE
    for _ in range(rng.integers(0, 10)):
        y0, x0 = rng.integers(0, h), rng.integers(0, w)
        t[y0 : y0 + rng.integers(1, 12), x0 : x0 + rng.integers(1, 12)] = OCC
    noise = rng.random((h, w)) < rng.choice([0.0, 0.01, 0.05])
    t[noise] = rng.integers(0, 3, noise.sum()).astype(np.uint8)
    return t


@SETTINGS
@given(seeds, st.integers(4, 120), st.integers(4, 120), st.sampled_from([1, 2, 3]))
def test_pool_traversable_frontiers(seed, h, w, factor):
    rng = np.random.default_rng(seed)
    t = random_ternary(rng, h, w)
    p = planner.pool(t, factor)
    assert np.array_equal(stepcore.pool(t, factor), p)
    for inflate in (0, 1, 2, 3):
        trav = planner.traversable(p, inflate)
        assert np.array_equal(stepcore.traversable(p, inflate), trav)
        assert np.array_equal(stepcore.frontier_goals(p, trav), planner.frontier_goals(p, trav))


@SETTINGS
@given(seeds, st.integers(3, 100), st.integers(3, 100))
def test_wavefront(seed, h, w):
    rng = np.random.default_rng(seed)
    passable = rng.random((h, w)) < rng.uniform(0.4, 1.0)
    wanted = rng.random((h, w)) < rng.choice([0.0, 0.001, 0.01, 0.1])
    fallback = wanted | (rng.random((h, w)) < rng.choice([0.0, 0.01]))
    start = (int(rng.integers(0, h)), int(rng.integers(0, w)))
    passable[start] = True
    d0, c0, k0 = planner.wavefront(passable.copy(), start, wanted, fallback)
    d1, c1, k1 = stepcore.wavefront(passable, start, wanted, fallback)
    assert (c1, k1) == (c0, k0)
    assert np.array_equal(d1, d0)


@SETTINGS
@given(seeds, st.integers(20, 200), st.integers(20, 200), st.booleans())
def test_plan(seed, h, w, fallback):
    rng = np.random.default_rng(seed)
    t = random_ternary(rng, h, w)
    prm = planner.PlannerParams(0.05, int(rng.integers(1, 4)), float(rng.choice([0.0, 0.15, 0.3])))
    free = np.argwhere(t == FREE)
    cell = free[rng.integers(len(free))] if len(free) else (h // 2, w // 2)
    pose = ((cell[1] + rng.random()) * 0.05, (cell[0] + rng.random()) * 0.05)
    goals = [
        (rng.uniform(0, w * 0.05), rng.uniform(0, h * 0.05)) for _ in range(rng.integers(0, 5))
    ]
    radius = float(rng.choice([0.5, 1.0, 2.0]))
    ref = planner.plan_reference(t, pose, goals, radius, prm, fallback)
    got = planner.plan(t, pose, goals, radius, prm, fallback)
    assert got == ref


@SETTINGS
@given(seeds, st.integers(1, 60), st.integers(1, 60), st.floats(0.01, 1.0))
def test_classify_and_merge(seed, h, w, threshold):
    rng = np.random.default_rng(seed)
    th = np.float32(threshold)
    # Values on and next to the thresholds, where float32 and float64 compares differ.
    edges = np.array([th, -th, np.nextafter(th, 1), np.nextafter(-th, -1), 0, 1, -1], np.float32)
    big = rng.uniform(-2, 2, (h + 6, w + 6)).astype(np.float32)
    mask = rng.random(big.shape) < 0.3
    big[mask] = rng.choice(edges, mask.sum())
    view = big[3 : 3 + h, 2 : 2 + w]  # a strided view, as OccupancyGrid.L is
    assert np.array_equal(stepcore.classify(view, threshold), classify(view, threshold))
    t = rng.integers(0, 3, (h, w)).astype(np.uint8)
    a, b = big.copy(), big.copy()
    ga = OccupancyGrid((h, w), params=LogOdds(threshold=threshold))
    ga.Lp[...] = a[3 : 3 + h, 2 : 2 + w]
    gb = OccupancyGrid((h, w), params=LogOdds(threshold=threshold))
    gb.Lp[...] = b[3 : 3 + h, 2 : 2 + w]
    n_native = ga.merge_ternary(t)  # the grid calls the compiled merge
    view = gb.L
    learn = (np.abs(view) < gb.params.threshold) & (t != UNKNOWN)
    view[learn] = np.where(t[learn] == FREE, -np.float32(1.0), np.float32(1.0))
    assert n_native == int(learn.sum())
    assert np.array_equal(ga.Lp, gb.Lp)


def _obstacles(rng, shape, pad_n):
    occ = np.zeros(shape, dtype=bool)
    for _ in range(rng.integers(0, 15)):
        y0, x0 = rng.integers(0, shape[0]), rng.integers(0, shape[1])
        occ[y0 : y0 + rng.integers(1, 20), x0 : x0 + rng.integers(1, 20)] = True
    return np.pad(occ, pad_n, constant_values=True)


@SETTINGS
@given(seeds, st.sampled_from([(1.0, 90), (2.0, 360), (1.5, 180), (0.6, 37)]), st.integers(0, 40))
def test_cast_and_scan_into(seed, geometry, s0):
    """The world's cast (ranges and cells seen) and the robot's scan into both of its maps."""
    rng = np.random.default_rng(seed)
    laser = Laser(geometry[0], geometry[1], 0.05)
    shape = (120, 130)
    occ = _obstacles(rng, shape, laser.pad)
    x, y = rng.uniform(0.5, shape[1] * 0.05 - 0.5), rng.uniform(0.5, shape[0] * 0.05 - 0.5)
    # Reference: every sample, first hit per ray, from node.rays' own arithmetic.
    flat = laser.flat_cells(x, y, occ.shape[1])
    hit = occ.reshape(-1)[flat]
    any_hit = hit.any(axis=1)
    s0 = min(s0, laser.n_samples)
    clear = ~hit[:, :s0].any()
    ranges = laser.cast(occ, x, y)
    seen = np.zeros(occ.shape, dtype=bool)
    got = stepcore.cast_window(laser, occ.view(np.uint8), seen.view(np.uint8), x, y,
                               s0 if clear else 0, _BIAS)  # fmt: skip
    assert got is not None
    assert np.array_equal(got[0] if got[1] else np.full_like(ranges, np.inf), ranges)
    assert got[1] == bool(any_hit.any())
    free, occ_cells = laser.scan_cells(x, y, ranges, occ.shape[1])
    want = np.zeros(occ.size, dtype=bool)
    want[free] = True
    want[occ_cells] = True
    assert np.array_equal(seen.reshape(-1), want)
    # The robot's side: log-odds and local map, against scan_window + update_window.
    grid_a = OccupancyGrid(shape, 0.05, pad=laser.pad)
    grid_b = OccupancyGrid(shape, 0.05, pad=laser.pad)
    init = rng.uniform(-5, 5, grid_a.Lp.shape).astype(np.float32)
    init[rng.random(init.shape) < 0.5] = 0
    grid_a.Lp[...] = init
    grid_b.Lp[...] = init
    own_a = rng.integers(0, 3, grid_a.Lp.shape).astype(np.uint8)
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


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_lone_exploration_is_the_same(seed, monkeypatch):
    """A whole exploration in-process: the same steps and the same path with either."""
    from testbed.bench.node import simulate_exploration

    native = simulate_exploration(seed, positions=True)
    monkeypatch.setattr(stepcore, "NATIVE", False)
    reference = simulate_exploration(seed, positions=True)
    assert native["steps"] == reference["steps"]
    assert native["positions"] == reference["positions"]
