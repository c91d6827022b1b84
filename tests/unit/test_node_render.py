"""node.render's map picture: one colour per ternary value, nearest-neighbour scaling."""

import numpy as np

from node import render
from node.grid import FREE, OCC, UNKNOWN


def test_map_image_colours_each_cell_by_its_value():
    t = np.full((3, 4), UNKNOWN, dtype=np.uint8)
    t[0, 1] = FREE
    t[2, 3] = OCC
    img = render.map_image(t, 1)
    assert img.shape == (3, 4, 3) and img.dtype == np.uint8
    assert img[0, 1].tolist() == [255, 255, 255]
    assert img[2, 3].tolist() == [0, 0, 0]
    assert img[1, 1].tolist() == [170, 170, 170]


def test_map_image_scales_without_blending():
    t = np.array([[FREE, OCC]], dtype=np.uint8)
    img = render.map_image(t, 2)
    assert img.shape == (2, 4, 3)
    assert img[:, :2].min() == 255 and img[:, 2:].max() == 0


def test_map_image_takes_a_non_contiguous_view():
    t = np.full((4, 4), UNKNOWN, dtype=np.uint8)
    t[::2, ::2] = FREE
    assert render.map_image(t[::2, ::2], 1).min() == 255
