"""Draws office.png: a 20 x 20 m floor (0.05 m per pixel), a corridor across the middle and
four rooms on each side of it, each with a 1.2 m door onto the corridor.

    .venv/bin/python testbed/experiments/maps/make_office.py

Walls are 0.2 m thick (4 pixels), black on white. Rooms: x 0-5, 5-10, 10-15, 15-20 m; the
top row spans y 0-9 m, the corridor y 9-11 m, the bottom row y 11-20 m. The doors of the
rooms are at x 1.9-3.1, 6.9-8.1, 11.9-13.1 and 16.9-18.1 m, in both corridor walls.
"""

import os

import cv2
import numpy as np

from topology.spec import CELL_M as CELL

SIZE_M = 20.0
WALL_M = 0.2


def px(m: float) -> int:
    return round(m / CELL)


def office() -> np.ndarray:
    n = px(SIZE_M)
    t = px(WALL_M)
    img = np.full((n, n), 255, dtype=np.uint8)
    img[:t, :] = img[-t:, :] = img[:, :t] = img[:, -t:] = 0  # outer walls
    for y in (9.0, 11.0):  # the corridor's walls
        img[px(y) - t // 2 : px(y) + t // 2, :] = 0
    for x in (5.0, 10.0, 15.0):  # walls between rooms, above and below the corridor
        img[: px(9.0), px(x) - t // 2 : px(x) + t // 2] = 0
        img[px(11.0) :, px(x) - t // 2 : px(x) + t // 2] = 0
    for x0 in (1.9, 6.9, 11.9, 16.9):  # doors onto the corridor
        for y in (9.0, 11.0):
            img[px(y) - t // 2 : px(y) + t // 2, px(x0) : px(x0 + 1.2)] = 255
    return img


if __name__ == "__main__":
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "office.png")
    cv2.imwrite(out, office())
    print(out)
