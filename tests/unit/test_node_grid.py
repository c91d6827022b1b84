"""Log-odds update, classification, merging and the ternary wire form."""

import numpy as np
import pytest

from node.grid import FREE, OCC, UNKNOWN, LogOdds, OccupancyGrid, decode_ternary, encode_ternary
from node.rays import Laser, pad


def test_log_odds_update_and_clamp():
    g = OccupancyGrid((4, 4), params=LogOdds(l_free=-0.4, l_occ=0.85, l_max=1.0))
    free = np.array([0, 0, 1])  # a repeated index moves its cell once per scan
    occ = np.array([5])
    g.update_cells(free, occ)
    assert g.L.reshape(-1)[0] == pytest.approx(-0.4)
    assert g.L.reshape(-1)[1] == pytest.approx(-0.4)
    assert g.L.reshape(-1)[5] == pytest.approx(0.85)
    for _ in range(5):
        g.update_cells(free, occ)
    assert g.L.reshape(-1)[0] == pytest.approx(-1.0)
    assert g.L.reshape(-1)[5] == pytest.approx(1.0)
    t = g.ternary()
    assert t.reshape(-1)[0] == FREE and t.reshape(-1)[5] == OCC and t.reshape(-1)[2] == UNKNOWN


def test_scan_integration_matches_ground_truth():
    laser = Laser(max_range=2.0, n_rays=360)
    occ = np.zeros((80, 80), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[20:60, 50:52] = True
    occp = pad(occ, laser.pad, True)
    g = OccupancyGrid(occ.shape, pad=laser.pad)
    for x, y in [(1.0, 1.0), (2.0, 2.0), (1.0, 3.0), (2.0, 1.0)]:
        g.integrate_scan(laser, x, y, laser.cast(occp, x, y))
    t = g.ternary()
    assert ((t == FREE) & occ).sum() == 0
    assert ((t == OCC) & ~occ).sum() == 0
    assert (t == OCC).sum() > 50
    assert t[int(2.0 / 0.05), int(2.0 / 0.05)] == FREE
    assert t[40, 70] == UNKNOWN  # behind the inner wall


def test_merge_only_fills_unknown_cells():
    g = OccupancyGrid((3, 3))
    g.L[0, 0] = -3.0  # known free
    t = np.array([[OCC, FREE, UNKNOWN], [FREE, OCC, FREE], [0, 0, 0]], dtype=np.uint8)
    learnt = g.merge_ternary(t)
    assert learnt == 4
    out = g.ternary()
    assert out[0, 0] == FREE  # own knowledge kept
    assert out[0, 1] == FREE and out[1, 1] == OCC and out[0, 2] == UNKNOWN
    assert g.merge_ternary(t) == 0  # merging twice changes nothing


def test_merge_rejects_out_of_bounds():
    g = OccupancyGrid((3, 3))
    with pytest.raises(ValueError):
        g.merge_ternary(np.zeros((2, 2), dtype=np.uint8), 2, 2)


def test_ternary_round_trip_cropped():
    rng = np.random.default_rng(1)
    t = np.zeros((50, 60), dtype=np.uint8)
    t[10:23, 5:40] = rng.integers(0, 3, size=(13, 35))
    t[10, 5] = FREE
    t[22, 39] = OCC
    r0, c0, h, w, data = encode_ternary(t)
    assert (r0, c0, h, w) == (10, 5, 13, 35)
    back = decode_ternary(h, w, data)
    assert np.array_equal(back, t[10:23, 5:40])


def test_ternary_empty_and_malformed():
    assert encode_ternary(np.zeros((5, 5), dtype=np.uint8))[:4] == (0, 0, 0, 0)
    with pytest.raises(ValueError):
        decode_ternary(10, 10, b"not zlib")
    with pytest.raises(ValueError):
        decode_ternary(10**4, 10**4, b"")


def test_window_update_matches_per_cell_update():
    """scan_window + update_window leave the map exactly as scan_cells + update_cells."""
    laser = Laser(max_range=2.0, n_rays=360)
    rng = np.random.default_rng(5)
    occ = rng.random((240, 240)) < 0.01
    occ[:, 80:] = False  # open space: scans with no return at all
    occ[30:90, 60:62] = True
    occp = pad(occ, laser.pad, True)
    a = OccupancyGrid(occ.shape, pad=laser.pad)
    b = OccupancyGrid(occ.shape, pad=laser.pad)
    no_return = 0
    for _ in range(60):
        x, y = rng.uniform(0.0, 12.0, size=2)
        ranges = laser.cast(occp, x, y)
        no_return += np.isinf(ranges).all()
        a.update_cells(*laser.scan_cells(x, y, ranges, a.Lp.shape[1]))
        r0, c0, free, hit = laser.scan_window(x, y, ranges)
        b.update_window(r0, c0, free, hit)
    assert np.array_equal(a.Lp, b.Lp)
    assert (a.Lp != 0).sum() > 1000 and no_return > 0


def test_window_that_does_not_fit_is_rejected():
    laser = Laser(max_range=2.0, n_rays=36)
    g = OccupancyGrid((100, 100), pad=laser.pad)
    free = np.zeros((laser.window, laser.window), dtype=bool)
    with pytest.raises(ValueError):
        g.update_window(100, 0, free, np.zeros(0, dtype=np.intp))
