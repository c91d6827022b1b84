"""Line of sight through walls, for the `los` range models (topology.radio.ranges).

A radio link indoors is blocked (or weakened) by walls. `Walls` is an obstacle grid in
metres: a PNG where pixels darker than mid-grey are walls, one pixel `cell` metres, row =
y / cell and column = x / cell, the same convention as the world's ground truth (so a
testbed run and `testbed net up --map` see the same walls). `crossings(walls, pairs)`
counts, for many robot pairs at once, how many walls the straight line between them
crosses: the line is sampled once per cell, and a wall is a run of consecutive wall
samples, so a thick wall counts once and two walls twice (walls must be at least two
pixels thick, as in any map drawn for robots of more than a pixel). All pairs of a step go through
one numpy evaluation, which keeps a 10-robot step's check well under a millisecond.
"""

from __future__ import annotations

import math

import numpy as np

from topology.inputs import pngmap

Position = tuple[float, float]


class MapError(ValueError):
    """The map file is missing, unreadable or unusable."""


class Walls:
    def __init__(self, occupied: np.ndarray, cell: float) -> None:
        if not (cell > 0 and math.isfinite(cell)):
            raise MapError(f"map cell size must be a positive number, not {cell}")
        self.occupied = np.ascontiguousarray(occupied, dtype=bool)
        self.cell = float(cell)
        # The grid with a free border all round: where samples outside the map land.
        self.padded = np.pad(self.occupied, 1, constant_values=False)

    @classmethod
    def from_png(cls, path: str, cell: float) -> Walls:
        """The walls of a PNG map at its own resolution, one pixel `cell` metres; its size
        is checked from its header before it is decoded (topology.inputs.pngmap)."""
        try:
            img = pngmap.read_gray(path)
        except pngmap.PngError as exc:
            raise MapError(str(exc)) from None
        return cls(img < 128, cell)

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) in metres."""
        return self.occupied.shape[1] * self.cell, self.occupied.shape[0] * self.cell


def _clipped(a: np.ndarray, d: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """Segments a + t d, t in [0, 1] (cells), cut to the box [-1, w + 1] x [-1, h + 1]
    (Liang-Barsky); one that misses the box becomes the point (-1, -1), a free cell."""
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for axis, hi in ((0, w + 1.0), (1, h + 1.0)):
            p, lo_q, hi_q = d[:, axis], -1.0 - a[:, axis], hi - a[:, axis]
            still = p == 0
            outside = still & ((lo_q > 0) | (hi_q < 0))
            enter = np.where(still, -np.inf, np.minimum(lo_q / p, hi_q / p))
            leave = np.where(still, np.inf, np.maximum(lo_q / p, hi_q / p))
            t0 = np.maximum(t0, enter)
            t1 = np.where(outside, -1.0, np.minimum(t1, leave))
    miss = t0 > t1
    a_cut = np.where(miss[:, None], -1.0, a + t0[:, None] * d)
    d_cut = np.where(miss[:, None], 0.0, (t1 - t0)[:, None] * d)
    return a_cut, d_cut


def crossings(walls: Walls, pairs: list[tuple[Position, Position]]) -> list[int]:
    """For each (a, b), the number of walls the segment a-b crosses. Outside the map is free.

    Each segment is first cut to the map and a free cell around it (outside is free, so
    only that part can cross a wall: the cost is bounded by the map, however far apart the
    robots are), then sampled once per cell of its length (its own count, all segments in
    one flat array), which finds every wall at least two cells thick: a line crosses such a
    wall over at least two cells, so one sample lands in it."""
    if not pairs:
        return []
    ab = np.array(pairs, dtype=float) / walls.cell  # (pairs, 2 ends, x y) in cells
    h, w = walls.occupied.shape
    a, d = _clipped(ab[:, 0], ab[:, 1] - ab[:, 0], w, h)
    n = np.ceil(np.hypot(d[:, 0], d[:, 1])).astype(np.int64) + 2  # samples per segment
    offsets = np.zeros(len(n), dtype=np.int64)
    np.cumsum(n[:-1], out=offsets[1:])
    pair = np.repeat(np.arange(len(n)), n)
    t = (np.arange(int(n.sum())) - offsets[pair]) / (n - 1)[pair]
    # Cells outside the map are free: they index the extra free row and column of `padded`.
    rows = np.clip(np.floor(a[pair, 1] + d[pair, 1] * t), -1, h).astype(np.int64)
    cols = np.clip(np.floor(a[pair, 0] + d[pair, 0] * t), -1, w).astype(np.int64)
    hit = walls.padded[rows + 1, cols + 1]
    before = np.empty_like(hit)
    before[0] = False
    before[1:] = hit[:-1]
    before[offsets] = False  # a segment's first sample has nothing before it
    return np.add.reduceat(hit & ~before, offsets).tolist()
