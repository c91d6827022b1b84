"""Laser ray geometry shared by the world's laser and the robot's map update.

A scan is a fan of `n_rays` rays spread evenly over 360 degrees at fixed angles in the world
frame (ray k points at k * 360 / n_rays degrees): a noiseless 360-degree laser whose robot knows
its pose exactly, so the heading adds nothing and the ray directions can be tabulated once.
Each ray is sampled every half cell out to the laser's range. The world casts a ray by finding
the first sample that falls in an occupied cell and returns its distance (+inf when no sample
within range hits anything). The robot recomputes the same samples from the same position, so
"free" is every sample before the hit and "occupied" is the hit sample's cell: with a noiseless
laser the two sides agree cell for cell.

Grids used with a `Laser` are *padded* by `Laser.pad` cells on every side, so a ray never
needs a bounds check (the world pads with obstacles, the robot's map with unknown). Sample
positions are flat indices into the padded array. Everything is vectorised over all rays and
samples at once; nothing loops per cell.
"""

from __future__ import annotations

import math

import numpy as np

# The longest laser a run may have (30 m, the range class of 2-D lidars): declared with the
# robot's parameters.
from node.argsdecl import MAX_RANGE_M as MAX_RANGE_M
from topology.spec import CELL_M

_BIAS = 4096  # makes cell coordinates positive so truncation is floor
_NO_CELLS = np.zeros(0, dtype=np.intp)
_NO_CELLS.flags.writeable = False
# Pose-fraction tables (Laser.window_marks). A float32 in [_BIAS, 2 * _BIAS) is a multiple of
# 1 / _FRAC, so a laser position is its cell plus one of _FRAC x _FRAC sub-cell positions;
# a table is kept for each of _BUCKETS x _BUCKETS classes of those.
_FRAC = 2048
_BUCKETS = 16
# The pose-fraction tables of one geometry take _BUCKETS**2 windows of window**2 bytes; they
# are built only within this budget (lasers up to 12.6 m at 5 cm cells), and a longer laser
# marks its scans without them (the way a scan with hits always does). Without the budget a
# 30 m laser's tables took 370 MB in the world and again in every robot's fork server.
_TABLE_BUDGET_BYTES = 64 << 20


_SHARED_TABLES: dict[tuple[float, int, float], dict] = {}  # geometry -> pose-fraction tables


def warm(max_range: float, n_rays: int, cell: float) -> None:
    """Build every pose-fraction table of this geometry in this process, for the processes
    forked from it later (topology.kernel.forkserver)."""
    Laser(max_range, n_rays, cell).prepare_tables()


class Laser:
    """Tabulated ray geometry: `max_range` metres, `n_rays` over 360 degrees, `cell` metres."""

    def __init__(self, max_range: float = 2.0, n_rays: int = 360, cell: float = CELL_M):
        if max_range <= 0 or n_rays < 1 or cell <= 0:
            raise ValueError("laser range, ray count and cell size must be positive")
        self.max_range = float(max_range)
        self.n_rays = int(n_rays)
        self.cell = float(cell)
        self.step = self.cell / 2.0
        self.step32 = np.float32(self.step)  # the sample spacing as float32 arithmetic uses it
        self.n_samples = int(math.floor(self.max_range / self.step + 1e-9))
        self.pad = int(math.ceil(self.max_range / self.cell)) + 2
        self.window = 2 * self.pad + 1  # side of the square around the laser (window_cells)
        angles = np.arange(self.n_rays, dtype=np.float64) * (2.0 * math.pi / self.n_rays)
        r = np.arange(1, self.n_samples + 1, dtype=np.float64) * (self.step / self.cell)
        self.dx = (np.cos(angles)[:, None] * r[None, :]).astype(np.float32)
        self.dy = (np.sin(angles)[:, None] * r[None, :]).astype(np.float32)
        self._k = np.arange(self.n_samples, dtype=np.int32)[None, :]
        # Near the laser the rays crowd: to mark cells seen, ray k at sample radius r is used
        # only when k is a multiple of a power of two that keeps neighbouring used rays within
        # 0.8 cell of each other along the arc. Checked to mark exactly the same cells as all
        # samples (tests/unit/test_node_rays.py), with ~55 % of the samples.
        rr = np.arange(1, self.n_samples + 1) * self.step
        m = np.maximum(1, np.floor(self.n_rays * 0.8 * self.cell / (2 * math.pi * rr)))
        m = (2 ** np.floor(np.log2(m))).astype(np.int64)
        self.mark = (np.arange(self.n_rays)[:, None] % m[None, :]) == 0
        self._mark_dx, self._mark_dy = self.dx[self.mark], self.dy[self.mark]
        # The marked samples in that (ray-major) order: per ray how many, and each one's index
        # along its ray, so a scan keeps a prefix of each ray's samples without a 2-D mask.
        self._mark_count = self.mark.sum(axis=1)
        self._mark_s = np.nonzero(self.mark)[1].astype(np.int32)
        # Tables are read-only once built: lasers of one geometry share them (a fork server
        # builds them once for every robot it forks, see warm()).
        key = (self.max_range, self.n_rays, self.cell)
        self._tables: dict[tuple[int, int], tuple] = _SHARED_TABLES.setdefault(key, {})
        self.tabled = _BUCKETS * _BUCKETS * self.window * self.window <= _TABLE_BUDGET_BYTES
        if (2 * self.pad + 4096) ** 2 > 2**31:
            raise ValueError("laser range too long for int32 cell indices")

    def angles(self) -> np.ndarray:
        return np.arange(self.n_rays) * (2.0 * math.pi / self.n_rays)

    def flat_cells(self, x: float, y: float, padded_width: int) -> np.ndarray:
        """Flat indices, in a padded grid of row length `padded_width`, of every sample's cell.

        (x, y) must lie inside the unpadded map. Shape (n_rays, n_samples), int32 (int32
        arithmetic is several times faster here than int64).
        """
        fx = np.float32(x / self.cell + _BIAS)
        fy = np.float32(y / self.cell + _BIAS)
        cols = (self.dx + fx).astype(np.int32)
        rows = (self.dy + fy).astype(np.int32)
        base = (self.pad - _BIAS) * padded_width + (self.pad - _BIAS)
        rows *= padded_width
        rows += cols
        rows += base
        return rows

    def window_cells(self, x: float, y: float) -> tuple[int, int, np.ndarray]:
        """The same samples as `flat_cells`, as flat indices into a square window.

        Returns (r0, c0, idx): the window is rows r0..r0+W, cols c0..c0+W of the padded grid,
        W = `self.window` = 2 * pad + 1, and `idx` (n_rays, n_samples, int32) indexes its
        row-major cells. Cell for cell the same as `flat_cells` (the same float32 arithmetic).
        """
        fx = np.float32(x / self.cell + _BIAS)
        fy = np.float32(y / self.cell + _BIAS)
        cb, rb = int(fx), int(fy)
        cols = (self.dx + fx).astype(np.int32)
        rows = (self.dy + fy).astype(np.int32)
        rows *= self.window
        rows += cols
        rows += (self.pad - rb) * self.window + (self.pad - cb)
        return rb - _BIAS, cb - _BIAS, rows

    def scan_window(
        self, x: float, y: float, ranges: np.ndarray
    ) -> tuple[int, int, np.ndarray, np.ndarray]:
        """`scan_cells` as a window of the padded grid: (r0, c0, free, occ).

        `free` is a (W, W) boolean mask of the cells seen free, `occ` the flat window indices
        (intp, may repeat) of the cells seen occupied; the same cells as `scan_cells`. A dense
        mask over the ~7000 window cells is cheaper to apply than ~14000 repeated indices.

        How: only the marked samples are computed (the float32 arithmetic of `window_cells`),
        and of those each ray keeps the ones before its hit; each hit sample is computed alone.
        A scan without hits takes its cells from a table for the laser's sub-cell position
        (`_table`) plus the few samples the table leaves open. tests/unit/test_node_rays.py
        checks the result against `scan_cells` cell for cell.
        """
        if ranges.shape != (self.n_rays,):
            raise ValueError(f"scan has {ranges.shape} ranges, expected {self.n_rays}")
        return self.window_marks(
            x, y, self.hit_index(ranges) if np.isfinite(ranges).any() else None
        )

    def window_marks(
        self, x: float, y: float, idx: np.ndarray | None
    ) -> tuple[int, int, np.ndarray, np.ndarray]:
        """`scan_window` given each ray's hit sample index (`hit_index`; n_samples: no hit),
        or None when no ray hit anything."""
        w = self.window
        fx = np.float32(x / self.cell + _BIAS)
        fy = np.float32(y / self.cell + _BIAS)
        cb, rb = int(fx), int(fy)
        off = (self.pad - rb) * w + (self.pad - cb)
        # Pose-fraction table: only without hits, and only where every sample's float32
        # position lies in [_BIAS, 2 * _BIAS) (see _table).
        if (
            idx is None
            and self.tabled
            and _BIAS <= min(cb, rb) - self.pad - 1 < max(cb, rb) + self.pad + 1 < 2 * _BIAS
        ):
            size = _FRAC // _BUCKETS
            bx = int((float(fx) - cb) * _FRAC) // size
            by = int((float(fy) - rb) * _FRAC) // size
            sure, open_dx, open_dy = self._table(bx, by)
            cells = (open_dy + fy).astype(np.int32)
            cells *= w
            cells += (open_dx + fx).astype(np.int32)
            cells += off
            free = sure.copy()
            free[cells] = True
        else:
            cells = (self._mark_dy + fy).astype(np.int32)
            cells *= w
            cells += (self._mark_dx + fx).astype(np.int32)
            cells += off
            if idx is not None:  # each ray's marked samples before its hit
                cells = cells[self._mark_s < np.repeat(idx, self._mark_count)]
            # A histogram marks the cells: several times faster than a fancy assignment.
            free = np.bincount(cells, minlength=w * w) > 0
        occ = _NO_CELLS
        if idx is not None:
            rays = np.flatnonzero(idx < self.n_samples)
            if len(rays):
                at = rays * self.n_samples + idx[rays]  # the hit samples, flat
                occ = (self.dy.take(at) + fy).astype(np.intp)
                occ *= w
                occ += (self.dx.take(at) + fx).astype(np.intp)
                occ += off
        return rb - _BIAS, cb - _BIAS, free.reshape(w, w), occ

    def prepare_tables(self) -> None:
        """Build every pose-fraction table now (~0.2 s for a 2 m laser) rather than each on
        its first use (~1 ms), so that no later scan pays for one. None for a laser whose
        tables would not fit in _TABLE_BUDGET_BYTES (it does without)."""
        if not self.tabled:
            return
        for bx in range(_BUCKETS):
            for by in range(_BUCKETS):
                self._table(bx, by)

    def _table(self, bx: int, by: int) -> tuple:
        """Marks of a scan without hits for laser positions in sub-cell class (bx, by).

        Within a class a marked sample's cell, relative to the laser's cell, is either the
        same for every position in the class ("sure": both ends of the class agree, and the
        float32 sum is monotonic) or not ("open"). Returns the window mask of the sure
        samples' cells and the dx, dy of the open samples that could land outside it. Relative
        cells do not depend on which cell the laser is in while every float32 position lies
        in [_BIAS, 2 * _BIAS): all are multiples of 1 / _FRAC there, and adding a whole number
        of cells rounds the same (window_marks checks that range). Built on first use.
        """
        t = self._tables.get((bx, by))
        if t is not None:
            return t
        size = _FRAC // _BUCKETS

        base = _BIAS + self.pad + 2  # a cell where every sample stays in [_BIAS, 2 * _BIAS)

        def rel(d: np.ndarray, code: int) -> np.ndarray:  # cells from the laser's cell
            return (d + np.float32(base + code / _FRAC)).astype(np.int32) - base

        col, col1 = rel(self._mark_dx, bx * size), rel(self._mark_dx, (bx + 1) * size - 1)
        row, row1 = rel(self._mark_dy, by * size), rel(self._mark_dy, (by + 1) * size - 1)
        sure = (col == col1) & (row == row1)
        w = self.window
        at = self.pad * (w + 1)
        marks = np.bincount((at + row * w + col)[sure], minlength=w * w) > 0
        # An open sample that can land only in cells the sure samples mark anyway is dropped.
        covered = np.ones_like(sure)
        for r, c in ((row, col), (row, col1), (row1, col), (row1, col1)):
            covered &= marks[at + r * w + c]
        need = np.flatnonzero(~sure & ~covered)
        marks.flags.writeable = False
        t = (marks, self._mark_dx[need], self._mark_dy[need])
        self._tables[(bx, by)] = t
        return t

    def cast(self, occupied_padded: np.ndarray, x: float, y: float) -> np.ndarray:
        """Noiseless ranges (float32, n_rays) on a padded boolean obstacle grid; +inf: none."""
        flat = self.flat_cells(x, y, occupied_padded.shape[1])
        hit = np.take(occupied_padded.reshape(-1), flat)
        any_hit = hit.any(axis=1)
        first = hit.argmax(axis=1)
        ranges = np.full(self.n_rays, np.inf, dtype=np.float32)
        ranges[any_hit] = ((first[any_hit] + 1) * self.step).astype(np.float32)
        return ranges

    def hit_index(self, ranges: np.ndarray) -> np.ndarray:
        """Index of the hit sample on each ray, or n_samples when the ray returned nothing.

        Any float is a range (docs/robot-contract.md): a range that is not finite hit nothing;
        a finite one is clamped to [-1, n_samples + 1] sample spacings before it becomes an
        integer (1e30 would not fit one), so a negative range hits at the first sample and one
        beyond the laser's reach hits nothing: the step core's hit_index, index for index."""
        idx = np.full(ranges.shape, self.n_samples, dtype=np.int32)
        finite = np.isfinite(ranges)
        r = np.clip(ranges[finite], -self.step, (self.n_samples + 1) * self.step)
        idx[finite] = np.rint(r / self.step).astype(np.int32) - 1
        np.maximum(idx, 0, out=idx)  # np.clip's Python wrapper costs more than the work
        np.minimum(idx, self.n_samples, out=idx)
        return idx

    def scan_cells(
        self, x: float, y: float, ranges: np.ndarray, padded_width: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Flat padded indices of the cells a scan saw free and the cells it saw occupied.

        Indices may repeat; the two sets are disjoint when the ranges came from `cast` on a grid
        of the same geometry. Free cells come from the `mark` subset of samples (the same
        cells as all samples, fewer repeats); every ray's hit sample is used.
        """
        if ranges.shape != (self.n_rays,):
            raise ValueError(f"scan has {ranges.shape} ranges, expected {self.n_rays}")
        flat = self.flat_cells(x, y, padded_width)
        idx = self.hit_index(ranges)
        # Fancy indexing converts indices to intp on every use: convert once here.
        free = flat[self.mark & (self._k < idx[:, None])].astype(np.intp)
        rays = np.flatnonzero(idx < self.n_samples)
        occ = flat[rays, idx[rays]].astype(np.intp)
        return free, occ


def pad(a: np.ndarray, n: int, value) -> np.ndarray:
    """`a` with `n` cells of `value` added on every side."""
    return np.pad(a, n, mode="constant", constant_values=value)
