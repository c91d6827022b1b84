"""Ground-truth maps: the paper's empty terrain, or a PNG where dark pixels are obstacles.

A map is a boolean obstacle grid at the world's cell size (5 cm). `free_space` is what
coverage is measured against: the free cells connected to where the robots start (a room
sealed off from the start can never be explored, so it does not count).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import cv2
import numpy as np

from common.errors import UsageError
from testbed.files.runconfig import START_PLACEMENTS
from topology.inputs import pngmap
from topology.spec import CELL_M as CELL  # metres


@dataclass(frozen=True)
class GroundTruth:
    occupied: np.ndarray  # bool (rows, cols); row = y / cell, col = x / cell
    cell: float = CELL
    source: str = "empty"

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) in metres."""
        return self.shape[1] * self.cell, self.shape[0] * self.cell

    def is_free_disc(self, x: float, y: float, radius: float) -> bool:
        """True when a disc of `radius` at (x, y) lies inside the map and touches no obstacle."""
        h, w = self.shape
        c = self.cell
        r0, r1 = math.floor((y - radius) / c), math.floor((y + radius) / c)
        c0, c1 = math.floor((x - radius) / c), math.floor((x + radius) / c)
        if r0 < 0 or c0 < 0 or r1 >= h or c1 >= w:
            return False
        rows = (np.arange(r0, r1 + 1) + 0.5) * c
        cols = (np.arange(c0, c1 + 1) + 0.5) * c
        # A cell touches the disc when its nearest point is within the radius.
        dy = np.maximum(np.abs(rows - y) - c / 2, 0.0)[:, None]
        dx = np.maximum(np.abs(cols - x) - c / 2, 0.0)[None, :]
        touch = dy * dy + dx * dx <= radius * radius
        return not bool((self.occupied[r0 : r1 + 1, c0 : c1 + 1] & touch).any())

    def inflated(self, radius: float) -> np.ndarray:
        """Cells whose centre is within `radius` of an obstacle cell's centre.

        A robot whose centre is in a cell that is not inflated keeps its disc off obstacles to
        within half a cell: one lookup per move instead of a disc test.
        """
        r = radius / self.cell
        n = int(math.ceil(r))
        yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
        kernel = ((yy * yy + xx * xx) <= r * r).astype(np.uint8)
        return cv2.dilate(self.occupied.astype(np.uint8), kernel) > 0


def empty_terrain(width_m: float = 20.0, height_m: float = 20.0, wall_m: float = 0.1):
    """The paper's terrain: an empty rectangle with boundary walls."""
    h, w = round(height_m / CELL), round(width_m / CELL)
    t = max(1, round(wall_m / CELL))
    occ = np.zeros((h, w), dtype=bool)
    occ[:t, :] = occ[-t:, :] = occ[:, :t] = occ[:, -t:] = True
    return GroundTruth(occ, CELL, "empty")


MAX_CELLS = 4000  # a side of the world's grid, in cells (200 m at 5 cm)


def png_cells(path: str, cell_m: float) -> tuple[int, int]:
    """(columns, rows) of the world's grid for a PNG map of `cell_m` metres a pixel, from the
    file's header and structure alone (topology.inputs.pngmap.check; nothing is decoded): what a
    sweep checks of every map before its first run. UsageError for a map it cannot use."""
    _check_cell(cell_m)
    try:
        width, height, _ = pngmap.check(path)
    except pngmap.PngError as exc:
        raise UsageError(str(exc)) from None
    return _cells(path, width, height, cell_m)


def _check_cell(cell_m: float) -> None:
    if not (cell_m > 0 and math.isfinite(cell_m)):
        raise UsageError(f"map cell size must be a positive number, not {cell_m}")


def _cells(path: str, width: int, height: int, cell_m: float) -> tuple[int, int]:
    """The grid a picture of width x height pixels becomes, if within MAX_CELLS a side."""
    w = max(1, round(width * cell_m / CELL))
    h = max(1, round(height * cell_m / CELL))
    if w > MAX_CELLS or h > MAX_CELLS:
        raise UsageError(
            f"map {path} is too large ({w} x {h} cells of {CELL * 100:g} cm; at most "
            f"{MAX_CELLS} x {MAX_CELLS})"
        )
    return w, h


def load_png(path: str, cell_m: float, walls: bool = True) -> GroundTruth:
    """A map from a PNG: pixels darker than mid-grey are obstacles; one pixel is `cell_m`.

    The picture is resampled to the world's 5 cm cells; a one-cell wall is added around it
    when `walls` (robots must not leave the map). Its size is checked from its header before
    it is decoded (topology.inputs.pngmap): at most MAX_CELLS a side once resampled.
    """
    _check_cell(cell_m)
    try:
        width, height, data = pngmap.check(path)
        w, h = _cells(path, width, height, cell_m)
        img = pngmap.decode_gray(path, width, height, data)
    except pngmap.PngError as exc:
        raise UsageError(str(exc)) from None
    occ = img < 128
    if (h, w) != occ.shape:
        occ = cv2.resize(occ.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    if walls:
        occ = occ.copy()
        occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    if occ.all():
        raise UsageError(f"map {path} has no free space")
    return GroundTruth(occ, CELL, os.path.basename(path))


def free_space(truth: GroundTruth, starts: list[tuple[float, float]]) -> np.ndarray:
    """Free cells 8-connected to any start position (bool)."""
    free = (~truth.occupied).astype(np.uint8)
    n, labels = cv2.connectedComponents(free, connectivity=8)
    keep = set()
    for x, y in starts:
        r, c = int(y / truth.cell), int(x / truth.cell)
        if 0 <= r < truth.shape[0] and 0 <= c < truth.shape[1] and free[r, c]:
            keep.add(int(labels[r, c]))
    return np.isin(labels, sorted(keep)) & (free > 0)


def start_positions(
    truth: GroundTruth,
    n: int,
    rng: np.random.Generator,
    radius: float,
    placement: str = "corner",
) -> list[tuple[float, float]]:
    """`n` seeded start positions.

    - corner: clustered near the map's (0, 0) corner, as a team dropped off together (the
      paper's Figs. 3 and 5 show the team starting together near a corner);
    - centre: clustered the same way around the map's centre;
    - spread: anywhere in the free space, independently uniform.

    Each position keeps the robot's disc clear of obstacles (with a margin) and at least two
    radii plus 10 cm from the others. A cluster's square grows until everyone fits.
    """
    if placement not in START_PLACEMENTS:
        raise UsageError(f"start placement {placement!r}: one of {', '.join(START_PLACEMENTS)}")
    margin = radius + 0.1
    w_m, h_m = truth.size_m
    if placement == "spread":
        return _scatter(truth, n, rng, radius, (0.0, 0.0), (w_m, h_m), grow=False)
    target = (0.0, 0.0) if placement == "corner" else (w_m / 2, h_m / 2)
    # The free cell nearest the target anchors the cluster.
    free_rows, free_cols = np.nonzero(~truth.occupied)
    cx, cy = target
    d2 = ((free_cols + 0.5) * truth.cell - cx) ** 2 + ((free_rows + 0.5) * truth.cell - cy) ** 2
    order = np.argsort(d2)
    anchor = None
    for i in order[:20000]:
        x, y = (free_cols[i] + 0.5) * truth.cell, (free_rows[i] + 0.5) * truth.cell
        if placement == "corner":  # step inwards, away from the corner's walls
            x = x + math.copysign(margin, w_m / 2 - x)
            y = y + math.copysign(margin, h_m / 2 - y)
        if truth.is_free_disc(x, y, margin):
            anchor = (x, y)
            break
    if anchor is None:
        raise UsageError(f"the map has no room to place a robot near its {placement}")
    side = max(1.0, 0.6 * math.sqrt(n))
    if placement == "corner":  # the square grows from the anchor into the map
        sx = 1.0 if anchor[0] < w_m / 2 else -1.0
        sy = 1.0 if anchor[1] < h_m / 2 else -1.0
        return _scatter(truth, n, rng, radius, anchor, (sx * side, sy * side), grow=True)
    half = (anchor[0] - side / 2, anchor[1] - side / 2)  # centred on the anchor
    return _scatter(truth, n, rng, radius, half, (side, side), grow=True)


def _scatter(
    truth: GroundTruth,
    n: int,
    rng: np.random.Generator,
    radius: float,
    origin: tuple[float, float],
    extent: tuple[float, float],
    grow: bool,
) -> list[tuple[float, float]]:
    """n positions uniform in the box origin + [0, 1) x extent, clear and apart; with `grow`
    the box grows by half every 2000 tries (a cluster too tight for its team)."""
    margin = radius + 0.1
    out: list[tuple[float, float]] = []
    ex, ey = extent
    tries = 0
    while len(out) < n:
        tries += 1
        if grow and tries % 2000 == 0:
            ex, ey = ex * 1.5, ey * 1.5
        if tries > 40000:
            raise UsageError(f"could not place {n} robots on the map")
        x = origin[0] + ex * rng.uniform(0, 1)
        y = origin[1] + ey * rng.uniform(0, 1)
        if not truth.is_free_disc(x, y, margin):
            continue
        if any(math.hypot(x - a, y - b) < 2 * radius + 0.1 for a, b in out):
            continue
        out.append((round(x, 3), round(y, 3)))
    return out
