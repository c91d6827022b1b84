"""Log-odds occupancy grid: the robot's map.

Theory of operation: each cell holds the log-odds L = log(p / (1 - p)) that it is occupied,
0 meaning unknown. A laser scan adds `l_free` to every cell its rays crossed and `l_occ` to the
cell each ray stopped in, clamped to [-l_max, l_max]; each cell moves at most once per scan
(numpy's buffered fancy-index add applies a repeated index once). A cell is *free* below
-threshold, *occupied* above +threshold, *unknown* in between: the ternary view planning uses
and the form in which maps travel (`FREE`, `OCC`, `UNKNOWN` as uint8).

Maps from teammates arrive ternary. Merging writes a teammate's free/occupied verdict only into
cells this robot still has as unknown: the laser is noiseless and the world static, so two
robots never disagree about a cell they both saw, and merging the same map twice is harmless.

Coordinates: cell (row, col) covers x in [col*cell, (col+1)*cell), y in [row*cell, ...).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from node import stepcore
from node.rays import Laser
from topology.spec import CELL_M

UNKNOWN = np.uint8(0)
FREE = np.uint8(1)
OCC = np.uint8(2)
MAX_CELLS = 4_000_000  # the largest map a flood may carry (rows x cols)


@dataclass(frozen=True)
class LogOdds:
    l_free: float = -0.4
    l_occ: float = 0.85
    l_max: float = 5.0
    threshold: float = 0.2
    merged: float = 1.0  # |L| written for a cell learnt from a teammate's map


class OccupancyGrid:
    """A log-odds grid of shape (rows, cols) with square cells of `cell` metres.

    `L` is the map; it is a view into `Lp`, the same map with `pad` unknown cells on every side
    so that laser rays need no bounds checks (see node.rays). Flat cell indices are
    into `Lp`.
    """

    def __init__(
        self,
        shape: tuple[int, int],
        cell: float = CELL_M,
        params: LogOdds | None = None,
        pad: int = 0,
    ):
        self.shape = (int(shape[0]), int(shape[1]))
        self.cell = float(cell)
        self.params = params or LogOdds()
        self.pad = int(pad)
        n = self.pad
        self.Lp = np.zeros((self.shape[0] + 2 * n, self.shape[1] + 2 * n), dtype=np.float32)
        self.L = self.Lp[n : n + self.shape[0], n : n + self.shape[1]]

    def update_cells(self, free: np.ndarray, occ: np.ndarray) -> None:
        """Apply one scan's observations given as flat indices into the padded grid."""
        p = self.params
        flat = self.Lp.reshape(-1)
        if free.size:
            flat[free] = np.maximum(flat[free] + p.l_free, -p.l_max)
        if occ.size:
            flat[occ] = np.minimum(flat[occ] + p.l_occ, p.l_max)

    def update_window(self, r0: int, c0: int, free: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """`update_cells` for one scan given as `Laser.scan_window` returns it; returns the
        window of `Lp` it updated (a view). Free first, then occupied, as in update_cells."""
        p = self.params
        h, w = free.shape
        win = self.Lp[r0 : r0 + h, c0 : c0 + w]
        if r0 < 0 or c0 < 0 or win.shape != free.shape:
            raise ValueError("scan window does not fit the grid")
        np.copyto(win, np.maximum(win + p.l_free, -p.l_max), where=free)
        if occ.size:
            rr, cc = np.divmod(occ, w)
            win[rr, cc] = np.minimum(win[rr, cc] + p.l_occ, p.l_max)
        return win

    def integrate_scan(
        self, laser: Laser, x: float, y: float, ranges: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Update from one scan taken at (x, y); returns the (free, occ) flat indices touched."""
        if laser.pad > self.pad:
            raise ValueError("grid padding is smaller than the laser's reach")
        free, occ = laser.scan_cells(x, y, ranges, self.Lp.shape[1])
        self.update_cells(free, occ)
        return free, occ

    def ternary(self) -> np.ndarray:
        if stepcore.NATIVE:
            return stepcore.classify(self.L, self.params.threshold)
        return classify(self.L, self.params.threshold)

    def merge_ternary(self, t: np.ndarray, r0: int = 0, c0: int = 0) -> int:
        """Merge a teammate's ternary map placed at (r0, c0); returns cells newly learnt."""
        h, w = t.shape
        if r0 < 0 or c0 < 0 or r0 + h > self.shape[0] or c0 + w > self.shape[1]:
            raise ValueError("ternary map does not fit the grid")
        view = self.L[r0 : r0 + h, c0 : c0 + w]
        if stepcore.NATIVE:
            return stepcore.merge_ternary(view, t, self.params.threshold, self.params.merged)
        learn = np.abs(view) < self.params.threshold  # unknown here...
        learn &= t != UNKNOWN  # ...and known there
        n = int(np.count_nonzero(learn))
        if n:
            m = np.float32(self.params.merged)
            view[learn] = np.where(t[learn] == FREE, -m, m)
        return n


def classify(logodds: np.ndarray, threshold: float = LogOdds.threshold) -> np.ndarray:
    """Ternary view of a log-odds array: UNKNOWN, FREE or OCC (uint8)."""
    t = np.zeros(logodds.shape, dtype=np.uint8)
    t[logodds < -threshold] = FREE
    t[logodds > threshold] = OCC
    return t


def known_bbox(t: np.ndarray) -> tuple[int, int, int, int] | None:
    """(r0, c0, r1, c1) half-open bounding box of the known cells, or None if none."""
    rows = np.flatnonzero(t.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(t.any(axis=0))
    return int(rows[0]), int(cols[0]), int(rows[-1]) + 1, int(cols[-1]) + 1


def encode_ternary(t: np.ndarray) -> tuple[int, int, int, int, bytes]:
    """Crop a ternary map to its known cells and compress it: (r0, c0, h, w, zlib bytes)."""
    box = known_bbox(t)
    if box is None:
        return 0, 0, 0, 0, b""
    r0, c0, r1, c1 = box
    crop = np.ascontiguousarray(t[r0:r1, c0:c1])
    # Two bits per cell before zlib: four cells a byte.
    flat = crop.reshape(-1)
    pad = (-flat.size) % 4
    if pad:
        flat = np.concatenate([flat, np.zeros(pad, dtype=np.uint8)])
    q = flat.reshape(-1, 4)
    packed = (q[:, 0] | (q[:, 1] << 2) | (q[:, 2] << 4) | (q[:, 3] << 6)).astype(np.uint8)
    return r0, c0, r1 - r0, c1 - c0, zlib.compress(packed.tobytes(), 1)


def decode_ternary(h: int, w: int, data: bytes, max_cells: int = MAX_CELLS) -> np.ndarray:
    """Inverse of encode_ternary's payload; raises ValueError on malformed input."""
    if h < 0 or w < 0 or h * w > max_cells:
        raise ValueError("bad ternary map size")
    if h * w == 0:
        return np.zeros((h, w), dtype=np.uint8)
    n_bytes = (h * w + 3) // 4
    try:
        raw = zlib.decompress(data, bufsize=n_bytes)
    except zlib.error as e:
        raise ValueError(f"bad ternary map payload: {e}") from None
    if len(raw) != n_bytes:
        raise ValueError("ternary map payload has the wrong length")
    packed = np.frombuffer(raw, dtype=np.uint8)
    q = np.stack([(packed >> s) & 3 for s in (0, 2, 4, 6)], axis=1).reshape(-1)[: h * w]
    if (q > 2).any():
        raise ValueError("ternary map has an invalid cell value")
    return q.reshape(h, w).astype(np.uint8)
