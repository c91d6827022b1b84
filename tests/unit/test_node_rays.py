"""Ray casting and the scan's free/occupied cells on small hand-made grids."""

import math

import numpy as np
import pytest

from node.rays import Laser, pad


def _box(n=40, wall_col=None):
    occ = np.zeros((n, n), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    if wall_col is not None:
        occ[:, wall_col] = True
    return occ


def test_range_to_a_wall_is_exact_to_half_a_cell():
    laser = Laser(max_range=1.5, n_rays=4, cell=0.05)  # rays at 0, 90, 180, 270 degrees
    occ = _box(40, wall_col=30)  # wall face at x = 1.50 m
    r = laser.cast(pad(occ, laser.pad, True), 1.025, 1.025)
    assert r[0] == pytest.approx(1.50 - 1.025, abs=0.025)  # east: the wall at x=1.5
    assert r[2] == pytest.approx(1.025 - 0.05, abs=0.025)  # west: border cell 0 ends at 0.05
    assert r[1] == pytest.approx(1.95 - 1.025, abs=0.025)  # south (+y): border row 39


def test_no_return_beyond_range_is_inf():
    laser = Laser(max_range=1.0, n_rays=8, cell=0.05)
    occ = _box(100)
    r = laser.cast(pad(occ, laser.pad, True), 2.5, 2.5)
    assert np.isinf(r).all()


def test_outside_the_grid_counts_as_obstacle():
    laser = Laser(max_range=2.0, n_rays=4, cell=0.05)
    occ = np.zeros((20, 20), dtype=bool)  # 1 x 1 m, no walls
    r = laser.cast(pad(occ, laser.pad, True), 0.5, 0.5)
    assert np.isfinite(r).all()
    assert r[0] == pytest.approx(0.5, abs=0.03)


def test_ray_count_and_angles():
    laser = Laser(max_range=2.0, n_rays=720, cell=0.05)
    assert laser.angles()[1] == pytest.approx(math.pi / 360)
    assert laser.n_samples == 80


def test_scan_cells_free_before_hit_and_hit_occupied():
    laser = Laser(max_range=2.0, n_rays=360, cell=0.05)
    occ = _box(60, wall_col=40)
    occp = pad(occ, laser.pad, True)
    x, y = 1.0, 1.5
    r = laser.cast(occp, x, y)
    free, hit = laser.scan_cells(x, y, r, occp.shape[1])
    assert not occp.reshape(-1)[free].any()  # nothing seen free is an obstacle
    assert occp.reshape(-1)[hit].all()  # everything seen occupied is one
    assert np.intersect1d(free, hit).size == 0
    # The robot's own cell and the wall cell straight east are seen.
    w = occp.shape[1]
    p = laser.pad
    assert (int(y / 0.05) + p) * w + int(x / 0.05) + p in set(free.tolist())
    assert (int(y / 0.05) + p) * w + 40 + p in set(hit.tolist())


def test_scan_shape_mismatch_is_rejected():
    laser = Laser(n_rays=10)
    with pytest.raises(ValueError):
        laser.scan_cells(1.0, 1.0, np.ones(11, dtype=np.float32), 100)


def test_thinned_samples_mark_the_same_cells_as_all_samples():
    laser = Laser(max_range=2.0, n_rays=360, cell=0.05)
    rng = np.random.default_rng(3)
    for _ in range(50):
        x, y = rng.uniform(2.0, 3.0, 2)
        flat = laser.flat_cells(x, y, 200)
        assert set(np.unique(flat[laser.mark]).tolist()) == set(np.unique(flat).tolist())
    assert laser.mark.sum() < 0.7 * laser.mark.size


def _window_as_flat(laser, r0, c0, free, occ, padded_width):
    """scan_window's result as flat indices of the padded grid (sorted, unique)."""
    w = laser.window
    fr, fc = np.nonzero(free)
    orr, occ_c = np.divmod(occ, w)
    f = np.unique((fr + r0) * padded_width + fc + c0)
    o = np.unique((orr + r0) * padded_width + occ_c + c0)
    return f, o


@pytest.mark.parametrize("max_range", [2.0, 1.5])
def test_scan_window_equals_scan_cells_on_random_poses(max_range):
    """The fast window form marks cell for cell what the per-cell reference form marks."""
    laser = Laser(max_range=max_range, n_rays=360, cell=0.05)
    occ = _box(200)  # 10 x 10 m room with walls
    occ[60:140, 120:123] = True  # an inner wall
    occ[30:34, 30:90] = True
    occp = pad(occ, laser.pad, True)
    pw = occp.shape[1]
    rng = np.random.default_rng(11)
    kinds = 0
    for i in range(300):
        if i % 3 == 0:  # near the outer walls, where the window reaches into the padding
            x, y = rng.uniform(0.05, 2.5, 2)
            if rng.integers(2):
                x, y = 10.0 - x, 10.0 - y
        else:
            x, y = rng.uniform(0.05, 9.95, 2)
        x, y = float(np.float32(x)), float(np.float32(y))
        if occ[int(y / 0.05), int(x / 0.05)]:
            continue
        ranges = laser.cast(occp, x, y)
        if i % 5 == 0:  # arbitrary ranges too: short, beyond range, zero
            ranges = ranges.copy()
            k = rng.integers(0, 360, 40)
            ranges[k] = rng.choice([0.0, 0.01, 0.3, max_range - 0.01, max_range + 1, np.inf], 40)
        r0, c0, free, hit = laser.scan_window(x, y, ranges)
        if r0 < 0 or c0 < 0 or r0 + laser.window > occp.shape[0] or c0 + laser.window > pw:
            continue
        kinds += bool(np.isfinite(ranges).any())
        f_ref, o_ref = laser.scan_cells(x, y, ranges, pw)
        f, o = _window_as_flat(laser, r0, c0, free, hit, pw)
        assert np.array_equal(f, np.unique(f_ref))
        assert np.array_equal(o, np.unique(o_ref))
    assert kinds > 50


@pytest.mark.parametrize("max_range", [2.0, 1.5])
def test_scans_without_hits_from_tables_equal_scan_cells(max_range):
    """The pose-fraction tables (every sub-cell class, both ends of each) mark what the
    per-cell form marks, and so does the exact form near the map's low edges."""
    laser = Laser(max_range=max_range, n_rays=360, cell=0.05)
    pw = 400 + 2 * laser.pad
    none = np.full(360, np.inf, dtype=np.float32)
    rng = np.random.default_rng(5)
    poses = []
    for k in range(16):  # class boundaries: sub-cell positions k/16 and k/16 - 1/2048
        for frac in (k / 16, (k + 1) / 16 - 1 / 2048):
            c, r = rng.integers(50, 350, 2)
            poses.append(((c + frac) * 0.05, (r + rng.random()) * 0.05))
            poses.append(((c + rng.random()) * 0.05, (r + frac) * 0.05))
    poses += [tuple(rng.uniform(0.0, 20.0, 2)) for _ in range(60)]  # edges included
    for x, y in poses:
        r0, c0, free, hit = laser.scan_window(x, y, none)
        assert hit.size == 0
        f_ref, _ = laser.scan_cells(x, y, none, pw)
        f, _ = _window_as_flat(laser, r0, c0, free, hit, pw)
        assert np.array_equal(f, np.unique(f_ref))
    assert len(laser._tables) > 20
