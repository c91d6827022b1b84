"""Ground truth: the default terrain, PNG maps, free space and seeded start positions."""

import math

import cv2
import numpy as np
import pytest

from common.errors import UsageError
from testbed.world.worldmap import empty_terrain, free_space, load_png, start_positions


def test_empty_terrain_is_the_papers():
    t = empty_terrain()
    assert t.shape == (400, 400) and t.cell == 0.05 and t.size_m == (20.0, 20.0)
    assert t.occupied[0].all() and t.occupied[:, -1].all()
    assert not t.occupied[2:-2, 2:-2].any()


def test_png_dark_pixels_are_obstacles_and_cell_size_resamples(tmp_path):
    img = np.full((40, 60), 255, dtype=np.uint8)  # 0.1 m pixels: 4 x 6 m
    img[10:30, 30] = 0  # a dark wall
    img[5, 5] = 100  # dark enough
    img[6, 6] = 200  # light: free
    p = tmp_path / "m.png"
    cv2.imwrite(str(p), img)
    t = load_png(str(p), 0.1)
    assert t.shape == (80, 120)  # resampled to 5 cm cells
    assert t.occupied[40, 60] and t.occupied[10, 10] and not t.occupied[12, 12]
    assert t.occupied[0].all()  # a boundary wall is added


@pytest.mark.parametrize("bad", ["missing.png", "notimage"])
def test_bad_map_is_a_usage_error(tmp_path, bad):
    p = tmp_path / bad
    if bad == "notimage":
        p.write_text("hello")
    with pytest.raises(UsageError):
        load_png(str(p), 0.05)


def test_free_space_excludes_sealed_rooms():
    t = empty_terrain(4, 4)
    occ = t.occupied.copy()
    occ[40:60, 40] = occ[40:60, 59] = occ[40, 40:60] = occ[59, 40:60] = True  # a sealed box
    t = type(t)(occ)
    fs = free_space(t, [(0.5, 0.5)])
    assert fs[10, 10] and not fs[50, 50] and not fs[0, 0]


def test_start_positions_seeded_near_the_corner_and_clear():
    t = empty_terrain()
    a = start_positions(t, 10, np.random.default_rng(5), 0.15)
    b = start_positions(t, 10, np.random.default_rng(5), 0.15)
    c = start_positions(t, 10, np.random.default_rng(6), 0.15)
    assert a == b and a != c
    for i, (x, y) in enumerate(a):
        assert x < 4 and y < 4  # dropped off together near the corner
        assert t.is_free_disc(x, y, 0.15)
        for x2, y2 in a[i + 1 :]:
            assert math.hypot(x - x2, y - y2) >= 0.4
