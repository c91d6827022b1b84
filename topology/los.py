"""Line of sight through walls, for the `los` range models (topology.ranges).

A radio link indoors is blocked (or weakened) by walls. `Walls` is an obstacle grid in
metres: a PNG where pixels darker than mid-grey are walls, one pixel `cell` metres, row =
y / cell and column = x / cell, the same convention as the world's ground truth (so a
testbed run and `testbed net up --map` see the same walls). `crossings(walls, pairs)`
counts, for many robot pairs at once, how many walls the straight line between them
crosses: the line is sampled every half cell, and a wall is a run of consecutive wall
samples, so a thick wall counts once and two walls twice. All pairs of a step go through
one numpy evaluation, which keeps a 10-robot step's check well under a millisecond.
"""

from __future__ import annotations

import math
import os

import numpy as np

Position = tuple[float, float]


class MapError(ValueError):
    """The map file is missing, unreadable or unusable."""


class Walls:
    def __init__(self, occupied: np.ndarray, cell: float) -> None:
        if not (cell > 0 and math.isfinite(cell)):
            raise MapError(f"map cell size must be a positive number, not {cell}")
        self.occupied = np.ascontiguousarray(occupied, dtype=bool)
        self.cell = float(cell)

    @classmethod
    def from_png(cls, path: str, cell: float) -> Walls:
        import cv2  # only the los models need it; the rest of topology starts without it

        if not os.path.isfile(path):
            raise MapError(f"map file {path} does not exist")
        img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise MapError(f"map file {path} is not an image OpenCV can read")
        return cls(img < 128, cell)

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) in metres."""
        return self.occupied.shape[1] * self.cell, self.occupied.shape[0] * self.cell


def crossings(walls: Walls, pairs: list[tuple[Position, Position]]) -> list[int]:
    """For each (a, b), the number of walls the segment a-b crosses. Outside the map is free."""
    if not pairs:
        return []
    a = np.array([p[0] for p in pairs], dtype=float)
    b = np.array([p[1] for p in pairs], dtype=float)
    longest = float(np.max(np.hypot(*(b - a).T)))
    n = max(2, int(math.ceil(longest / (walls.cell / 2))) + 1)
    t = np.linspace(0.0, 1.0, n)
    xs = a[:, 0, None] + (b[:, 0] - a[:, 0])[:, None] * t  # (pairs, n)
    ys = a[:, 1, None] + (b[:, 1] - a[:, 1])[:, None] * t
    rows = np.floor(ys / walls.cell).astype(np.int64)
    cols = np.floor(xs / walls.cell).astype(np.int64)
    h, w = walls.occupied.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    hit = np.zeros(rows.shape, dtype=bool)
    hit[inside] = walls.occupied[rows[inside], cols[inside]]
    starts = hit[:, 1:] & ~hit[:, :-1]
    return (starts.sum(axis=1) + hit[:, 0]).tolist()
