"""Frontier detection and path planning: pure functions of a ternary map and a pose.

Theory of operation (after m-explore's frontier_search, but on a grid with numpy):

1. *Planning grid.* The 5 cm ternary map is pooled into planning cells of `factor` x `factor`
   map cells (10 cm by default): a planning cell is occupied if any of its map cells is, free if
   all are, unknown otherwise. Planning at 10 cm keeps a plan on the 400 x 400 map to a few ms;
   the map itself stays at 5 cm.
2. *Traversable* cells are free planning cells farther than the robot's radius from every
   occupied cell (obstacles inflated by a disc). Unknown cells are never entered.
3. *Frontier* cells are traversable cells with an unknown cell among their 8 neighbours: a
   place the robot can stand at the edge of the unknown.
4. *Wavefront.* A breadth-first distance transform grows from the robot's cell through
   traversable cells, one ring per iteration (flat-index numpy rings, alternating 4- and
   8-neighbour growth, which approximates Euclidean distance by an octagon). It stops at the
   first ring that contains a wanted frontier, so the goal is the nearest reachable frontier
   by path length; unreachable frontiers are never reached.
5. *Goal rule.* Frontiers within the laser range of a teammate's current goal are not wanted;
   if every reachable frontier is, the nearest of those is taken rather than stopping. With no
   reachable frontier at all, exploration is done.
6. *Path.* From the goal, step to the neighbour nearest the start until the robot's cell, then
   shortcut the cell path with straight segments through passable cells (string pulling).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from node import stepcore
from node.grid import FREE, OCC, UNKNOWN
from topology.spec import CELL_M

_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=np.uint8)
_SQUARE = np.ones((3, 3), dtype=np.uint8)
_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


@dataclass(frozen=True)
class PlannerParams:
    cell: float = CELL_M  # map cell (m)
    factor: int = 2  # planning cell = factor map cells
    robot_radius: float = 0.15  # m

    @property
    def plan_cell(self) -> float:
        return self.cell * self.factor

    @property
    def inflate_cells(self) -> int:
        return int(np.ceil(self.robot_radius / self.plan_cell - 1e-9))


@dataclass
class Plan:
    """A planning result. `status` is "ok", "fallback" (goal near a teammate's), "blocked"
    (frontiers left, but all near teammates' goals: no goal) or "done" (no frontier left)."""

    status: str
    goal: tuple[float, float] | None = None
    path: list[tuple[float, float]] = field(default_factory=list)
    cost: float = 0.0  # path length in metres


def pool(t: np.ndarray, factor: int) -> np.ndarray:
    """Pool a ternary map into planning cells (rows/cols beyond a multiple are dropped).

    UNKNOWN < FREE < OCC, so a planning cell is OCC when the max of its cells is, FREE when the
    min is FREE (all free), UNKNOWN otherwise.
    """
    if factor == 1:
        return t.copy()
    h, w = t.shape[0] // factor, t.shape[1] // factor
    t = t[: h * factor, : w * factor]
    parts = [t[i::factor, j::factor] for i in range(factor) for j in range(factor)]
    mx = parts[0].copy()
    mn = parts[0].copy()
    for q in parts[1:]:
        np.maximum(mx, q, out=mx)
        np.minimum(mn, q, out=mn)
    out = np.where(mx == OCC, OCC, np.where(mn == FREE, FREE, UNKNOWN)).astype(np.uint8)
    return out


def disc(radius: int) -> np.ndarray:
    r = int(radius)
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    return ((yy * yy + xx * xx) <= r * r).astype(np.uint8)


def dilate(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Binary dilation of a bool array by a small odd-sized kernel; outside counts as False.

    One OR of shifted views per kernel cell (numpy only: robots need not load OpenCV).
    """
    kh, kw = kernel.shape
    ry, rx = kh // 2, kw // 2
    h, w = mask.shape
    padded = np.zeros((h + 2 * ry, w + 2 * rx), dtype=bool)
    padded[ry : ry + h, rx : rx + w] = mask
    out = np.zeros((h, w), dtype=bool)
    for dy, dx in zip(*np.nonzero(kernel), strict=True):
        out |= padded[dy : dy + h, dx : dx + w]
    return out


def traversable(p: np.ndarray, inflate: int) -> np.ndarray:
    """Free planning cells not within `inflate` cells of an occupied one (bool)."""
    occ = p == OCC
    if inflate > 0:
        occ = dilate(occ, disc(inflate))
    return (p == FREE) & ~occ


def frontiers(t: np.ndarray) -> np.ndarray:
    """Classic frontier cells of a ternary map: free cells with a 4-neighbour unknown (bool)."""
    return (t == FREE) & dilate(t == UNKNOWN, _CROSS)


def frontier_goals(p: np.ndarray, trav: np.ndarray) -> np.ndarray:
    """Cells a robot can stand at next to the unknown: traversable with an unknown 8-neighbour."""
    return trav & dilate(p == UNKNOWN, _SQUARE)


def exclusion_mask(
    shape: tuple[int, int], plan_cell: float, goals: list[tuple[float, float]], radius: float
) -> np.ndarray:
    """Planning cells whose centre lies within `radius` metres of any of `goals` (bool)."""
    mask = np.zeros(shape, dtype=bool)
    r = radius / plan_cell
    for gx, gy in goals:
        gc, gr = gx / plan_cell - 0.5, gy / plan_cell - 0.5
        if not (math.isfinite(gc) and math.isfinite(gr)):
            continue  # a teammate's goal of 1e308 m: in cells not finite, far off the map
        r0, r1 = max(0, int(np.floor(gr - r))), min(shape[0], int(np.ceil(gr + r)) + 1)
        c0, c1 = max(0, int(np.floor(gc - r))), min(shape[1], int(np.ceil(gc + r)) + 1)
        if r0 >= r1 or c0 >= c1:
            continue
        yy, xx = np.mgrid[r0:r1, c0:c1]
        mask[r0:r1, c0:c1] |= (yy - gr) ** 2 + (xx - gc) ** 2 <= r * r
    return mask


def wavefront(
    passable: np.ndarray, start: tuple[int, int], wanted: np.ndarray, fallback: np.ndarray
) -> tuple[np.ndarray, tuple[int, int] | None, str]:
    """Grow a distance transform from `start` until a `wanted` cell is reached.

    Returns (dist, cell, kind): dist is int32 (same shape as `passable`) with -1 for unreached
    cells, cell the goal cell (nearest wanted, else nearest `fallback`, else None) and kind
    "ok", "fallback" or "done". Rings alternate 4- and 8-neighbour growth; the work per ring is
    proportional to the ring, so a whole 200 x 200 grid costs a few ms.
    """
    h, w = passable.shape
    W = w + 2
    open_ = np.zeros((h + 2, W), dtype=bool)
    open_[1:-1, 1:-1] = passable
    want = np.zeros((h + 2, W), dtype=bool)
    want[1:-1, 1:-1] = wanted
    fall = np.zeros((h + 2, W), dtype=bool)
    fall[1:-1, 1:-1] = fallback
    open_f, want_f, fall_f = open_.reshape(-1), want.reshape(-1), fall.reshape(-1)
    dist = np.full((h + 2) * W, -1, dtype=np.int32)
    scratch = np.empty((h + 2) * W, dtype=np.int64)
    s = (start[0] + 1) * W + start[1] + 1
    dist[s] = 0
    open_f[s] = False

    def unpad(i: int) -> tuple[int, int]:
        return i // W - 1, i % W - 1

    def result(cell, kind):
        return dist.reshape(h + 2, W)[1:-1, 1:-1].copy(), cell, kind

    if want_f[s]:
        return result(unpad(s), "ok")
    first_fallback = s if fall_f[s] else None
    cross = np.array([-W, W, -1, 1], dtype=np.int64)
    diag = np.array([-W - 1, -W + 1, W - 1, W + 1], dtype=np.int64)
    square = np.concatenate([cross, diag])
    ring = np.array([s], dtype=np.int64)
    prev = np.empty(0, dtype=np.int64)
    k = 0
    while True:
        k += 1
        if k % 2:
            cand = (ring[:, None] + cross[None, :]).ravel()
        else:
            cand = np.concatenate(
                [(ring[:, None] + square[None, :]).ravel(), (prev[:, None] + diag[None, :]).ravel()]
            )
        cand = cand[open_f[cand]]
        if cand.size:  # drop repeats without sorting: keep each index's last occurrence
            order = np.arange(cand.size, dtype=np.int64)
            scratch[cand] = order
            cand = cand[scratch[cand] == order]
        prev, ring = ring, cand
        if cand.size == 0:
            if k % 2 and prev.size:
                continue  # the next (8-neighbour) ring still sees the diagonals of `prev`
            break
        open_f[cand] = False
        dist[cand] = k
        hit = cand[want_f[cand]]
        if hit.size:
            return result(_closest(hit, W, start), "ok")
        if first_fallback is None:
            fb = cand[fall_f[cand]]
            if fb.size:
                first_fallback = _closest(fb, W, start)
    if first_fallback is not None:
        cell = first_fallback if isinstance(first_fallback, tuple) else unpad(first_fallback)
        return result(cell, "fallback")
    return result(None, "done")


def _closest(flat: np.ndarray, W: int, start: tuple[int, int]) -> tuple[int, int]:
    """The cell of `flat` (padded flat indices) nearest to `start` in straight line."""
    rows, cols = flat // W - 1, flat % W - 1
    d2 = (rows - start[0]) ** 2 + (cols - start[1]) ** 2
    i = int(np.argmin(d2))
    return int(rows[i]), int(cols[i])


def trace_back(dist: np.ndarray, goal: tuple[int, int]) -> list[tuple[int, int]]:
    """Cells from the start (dist 0) to `goal`, each step to the neighbour nearest the start."""
    h, w = dist.shape
    path = [goal]
    r, c = goal
    d = int(dist[r, c])
    while d > 0:
        best, best_d = None, d
        for dr, dc in _NEIGHBOURS:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and 0 <= dist[rr, cc] < best_d:
                best, best_d = (rr, cc), int(dist[rr, cc])
        if best is None:  # cannot happen for a dist from wavefront(); keep the partial path
            break
        r, c = best
        d = best_d
        path.append(best)
    path.reverse()
    return path


def line_clear(ok: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    """True when every cell on the straight segment from cell a to cell b is `ok`."""
    n = 2 * max(abs(b[0] - a[0]), abs(b[1] - a[1])) + 1
    rows = np.rint(np.linspace(a[0], b[0], n)).astype(np.int64)
    cols = np.rint(np.linspace(a[1], b[1], n)).astype(np.int64)
    return bool(ok[rows, cols].all())


def smooth(cells: list[tuple[int, int]], ok: np.ndarray) -> list[tuple[int, int]]:
    """Shortcut a cell path by straight segments through `ok` cells (greedy string pulling).

    From each anchor, the farthest visible path cell is found by doubling then bisection, so the
    cost is a few segment checks per kept waypoint.
    """
    if len(cells) <= 2:
        return list(cells)
    out = [cells[0]]
    i, n = 0, len(cells)
    while i < n - 1:
        step, good = 1, i + 1
        while good + step < n and line_clear(ok, cells[i], cells[good + step]):
            good += step
            step *= 2
        lo, hi = good, min(good + step, n)  # visible at lo; not known beyond
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if line_clear(ok, cells[i], cells[mid]):
                lo = mid
            else:
                hi = mid
        out.append(cells[lo])
        i = lo
    return out


def path_length(cells: list[tuple[int, int]], plan_cell: float) -> float:
    if len(cells) < 2:
        return 0.0
    a = np.asarray(cells, dtype=np.float64)
    return float(np.hypot(*np.diff(a, axis=0).T).sum() * plan_cell)


def plan(
    t: np.ndarray,
    pose: tuple[float, float],
    teammate_goals: list[tuple[float, float]],
    exclusion_radius: float,
    params: PlannerParams | None = None,
    fallback: bool = True,
) -> Plan:
    """The goal rule and a path to it, from a ternary map and the robot's (x, y). When every
    reachable frontier is within `exclusion_radius` of a teammate's goal, the nearest one is
    the goal ("fallback") if `fallback`, else there is none ("blocked": node.coordination).

    Compiled (node.stepcore) where it was built; `plan_reference` is the same in numpy."""
    if not stepcore.NATIVE:
        return plan_reference(t, pose, teammate_goals, exclusion_radius, params, fallback)
    prm = params or PlannerParams()
    pc = prm.plan_cell
    status, cells = stepcore.plan_cells(t, pose, teammate_goals, exclusion_radius, prm.factor,
                                        prm.inflate_cells, pc, fallback)  # fmt: skip
    if not cells:
        return Plan(status)
    waypoints = [((c + 0.5) * pc, (r + 0.5) * pc) for r, c in cells]
    return Plan(status, waypoints[-1], waypoints, path_length(cells, pc))


def _start_index(v: float, n: int) -> int:
    """min(max(int(v), 0), n - 1), also for v = ±inf (1e308 m in cells), as the step core."""
    return 0 if not v > 0 else n - 1 if v >= n - 1 else int(v)


def plan_reference(
    t: np.ndarray,
    pose: tuple[float, float],
    teammate_goals: list[tuple[float, float]],
    exclusion_radius: float,
    params: PlannerParams | None = None,
    fallback: bool = True,
) -> Plan:
    """`plan` in numpy: the reference the compiled planner is held equal to."""
    prm = params or PlannerParams()
    p = pool(t, prm.factor)
    h, w = p.shape
    pc = prm.plan_cell
    sr = _start_index(pose[1] / pc, h)
    sc = _start_index(pose[0] / pc, w)
    trav = traversable(p, prm.inflate_cells)
    # Let the robot leave a start cell inside the inflation zone (e.g. pushed near a wall).
    passable = trav.copy()
    rr = prm.inflate_cells + 1
    r0, r1, c0, c1 = max(sr - rr, 0), min(sr + rr + 1, h), max(sc - rr, 0), min(sc + rr + 1, w)
    yy, xx = np.mgrid[r0:r1, c0:c1]
    near = (yy - sr) ** 2 + (xx - sc) ** 2 <= rr * rr
    passable[r0:r1, c0:c1] |= near & (p[r0:r1, c0:c1] == FREE)
    passable[sr, sc] = True
    goals = frontier_goals(p, trav)
    if not goals.any():
        return Plan("done")
    excluded = exclusion_mask(p.shape, pc, teammate_goals, exclusion_radius)
    dist, cell, kind = wavefront(passable, (sr, sc), goals & ~excluded, goals)
    if cell is None:
        return Plan("done")
    if kind == "fallback" and not fallback:
        return Plan("blocked")
    cells = smooth(trace_back(dist, cell), passable)
    waypoints = [((c + 0.5) * pc, (r + 0.5) * pc) for r, c in cells]
    return Plan(kind, waypoints[-1], waypoints, path_length(cells, pc))


def goal_priority(cost: float, robot: int) -> tuple[float, int]:
    """A goal's priority key: the shorter path wins, then the lower robot number."""
    return (round(cost, 3), robot)


def goals_conflict(a: tuple[float, float], b: tuple[float, float], laser_range: float) -> bool:
    """Two goals conflict when they are within laser range of each other."""
    return float(np.hypot(a[0] - b[0], a[1] - b[1])) <= laser_range
