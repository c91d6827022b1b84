"""The world: ground truth the robots never see directly.

Theory of operation. The world holds the obstacle map, every robot's pose and the motion
command its process last sent. One `step()` is the paper's time unit (100 ms of emulated
time): each robot moves up to `speed` metres straight toward its commanded target and stops
short of any obstacle (a move that would put its disc into an obstacle is refused and counted
as a collision); then every robot's noiseless laser is cast from its new position. The cells
those rays cross are the union of what the team has seen, from which coverage of free space
is computed. Robots are discs that do not collide with each other (as in the paper's
simulation). The world never touches the network: `testbed.run.execute` feeds its positions to the
topology controller and its scans to the robots' body links.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from node import stepcore
from node.rays import _BIAS, Laser, pad
from testbed.world.worldmap import GroundTruth


class Bodies:
    """Every robot's simulated body, as arrays (row i: robot i, 0-based): what World.move and
    its compiled twin (testbed.world.stepfast) both read and write. `Body` is a view of a row."""

    def __init__(self, starts: list[tuple[float, float]]) -> None:
        n = len(starts)
        self.xyt = np.zeros((n, 3), dtype=np.float64)  # x, y, theta (metres, radians)
        self.xyt[:, :2] = np.asarray(starts, dtype=np.float64).reshape(n, 2)
        self.target = np.zeros((n, 2), dtype=np.float64)  # where has_target
        self.has_target = np.zeros(n, dtype=np.uint8)
        self.alive = np.ones(n, dtype=np.uint8)
        self.collisions = np.zeros(n, dtype=np.int64)
        self.path_length = np.zeros(n, dtype=np.float64)


class Body:
    """One robot's simulated body: row i of the world's `Bodies`, read and written as
    attributes (floats and ints, as Python has them)."""

    __slots__ = ("_a", "_i")

    def __init__(self, arrays: Bodies, i: int) -> None:
        self._a, self._i = arrays, i

    @property
    def x(self) -> float:
        return float(self._a.xyt[self._i, 0])

    @x.setter
    def x(self, v: float) -> None:
        self._a.xyt[self._i, 0] = v

    @property
    def y(self) -> float:
        return float(self._a.xyt[self._i, 1])

    @y.setter
    def y(self, v: float) -> None:
        self._a.xyt[self._i, 1] = v

    @property
    def theta(self) -> float:
        return float(self._a.xyt[self._i, 2])

    @theta.setter
    def theta(self, v: float) -> None:
        self._a.xyt[self._i, 2] = v

    @property
    def target(self) -> tuple[float, float] | None:
        if not self._a.has_target[self._i]:
            return None
        tx, ty = self._a.target[self._i].tolist()
        return (tx, ty)

    @target.setter
    def target(self, v: tuple[float, float] | None) -> None:
        self._a.has_target[self._i] = v is not None
        self._a.target[self._i] = (0.0, 0.0) if v is None else v

    @property
    def collisions(self) -> int:
        return int(self._a.collisions[self._i])

    @collisions.setter
    def collisions(self, v: int) -> None:
        self._a.collisions[self._i] = v

    @property
    def path_length(self) -> float:
        return float(self._a.path_length[self._i])

    @path_length.setter
    def path_length(self, v: float) -> None:
        self._a.path_length[self._i] = v

    @property
    def alive(self) -> bool:
        return bool(self._a.alive[self._i])

    @alive.setter
    def alive(self, v: bool) -> None:
        self._a.alive[self._i] = bool(v)


def open_cells(clear: np.ndarray, reach: int) -> np.ndarray:
    """Cells whose distance to the nearest obstacle (`clear`, from an exact distance
    transform) is more than `reach` cells: no obstacle cell's centre lies in the disc of
    radius `reach` around theirs. The distances are square roots of whole numbers, so they
    are compared squared and rounded, exactly."""
    return np.rint(clear.astype(np.float64) ** 2) > reach * reach


class World:
    def __init__(
        self,
        truth: GroundTruth,
        starts: list[tuple[float, float]],
        laser: Laser,
        free_space: np.ndarray,
        speed: float = 0.1,
        radius: float = 0.15,
    ):
        self.truth = truth
        self.laser = laser
        self.speed = float(speed)
        self.radius = float(radius)
        self.body_arrays = Bodies(starts)
        self.bodies = [Body(self.body_arrays, i) for i in range(len(starts))]
        self.step_no = 0
        self.occ_padded = pad(truth.occupied, laser.pad, True)
        self.seen_padded = np.zeros(self.occ_padded.shape, dtype=bool)
        # The same arrays as bytes, for the compiled cast (node.stepcore).
        self._occ_u8 = self.occ_padded.view(np.uint8)
        self._seen_u8 = self.seen_padded.view(np.uint8)
        p = laser.pad
        self.seen = self.seen_padded[p : p + truth.shape[0], p : p + truth.shape[1]]
        self.free_space = free_space
        self.free_total = max(1, int(free_space.sum()))
        free_padded = pad(free_space.astype(bool), laser.pad, False)
        self._seen_free = (self._seen_u8, free_padded.view(np.uint8))  # coverage's operands
        self._paths: list[list[tuple[float, float]]] = [[(b.x, b.y)] for b in self.bodies]
        # The compiled moves' log (robot, x, y), taken into the paths when they are read.
        self.move_log = MoveLog(max(64, 64 * len(starts)))
        self._rays = np.arange(laser.n_rays)
        self._last_scan: list = [None] * len(self.bodies)
        self._no_returns = np.full(laser.n_rays, np.inf, dtype=np.float32)
        self._no_returns.flags.writeable = False
        # Each cell's distance (in cells, centre to centre) to the nearest obstacle cell, the
        # map's outside included: an exact Euclidean distance transform, whose cost does not
        # grow with the laser's range (a dilation by a disc of the laser's range did: 17 s
        # for a 20 m laser, hours for 100 m, in one C call that no signal interrupts).
        ring = pad(truth.occupied, 1, True)
        clear = cv2.distanceTransform((~ring).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        # Cells from which no obstacle (nor the map's edge) is within laser range (+1 cell):
        # farther than `reach` (squared distances of cell centres are whole numbers).
        reach = laser.pad + 1
        self.open_space = open_cells(clear[1:-1, 1:-1], reach)
        self._k = np.arange(laser.n_samples, dtype=np.int32)[None, :]
        # Samples a cast from a cell may skip: a sample at radius rho (cells) from a laser in a
        # cell whose centre is d from the nearest obstacle cell's centre (the map's outside
        # included) can only fall in an obstacle cell when d <= rho + sqrt(2) (half a cell's
        # diagonal on each end); skipped: samples with rho = (s + 1) / 2 < d - 1.5.
        skip = np.ceil(2.0 * clear[1:-1, 1:-1].astype(np.float64) - 4.0)
        self._skip = np.clip(skip, 0, laser.n_samples).astype(np.int32)
        laser.prepare_tables()  # before the run's clock starts
        # Cells where a robot's centre may be: obstacles grown by the robot's radius.
        self.blocked = truth.inflated(radius)
        # Free cells seen so far (None: to be counted again), kept up by the compiled casts.
        self._seen_free_count: int | None = 0
        self._cast = None
        n = len(self.bodies)
        # What the robots' frames carry, kept up by cast_live (the body link sends them).
        self.frame_xyt = np.zeros((n, 3), dtype=np.float64)
        self.frame_ranges = np.full((n, laser.n_rays), np.inf, dtype=np.float32)
        self.frame_has = np.ones(n, dtype=np.int8)
        if stepcore.NATIVE:
            self._cast = stepcore.WorldCast(laser, n, truth.cell, _BIAS, self._occ_u8,
                                            self._seen_u8, self._seen_free[1], self.open_space,
                                            self._skip, self.body_arrays.xyt)  # fmt: skip
            # The compiled casts write the frames' rows in place; the poses are the bodies'.
            self.frame_xyt, self.frame_ranges = self._cast.xyt, self._cast.ranges
            self.frame_has = self._cast.has

    @property
    def n(self) -> int:
        return len(self.bodies)

    @property
    def paths(self) -> list[list[tuple[float, float]]]:
        """Each robot's positions: where it started and where each move took it."""
        self.move_log.drain(self._paths)
        return self._paths

    def positions(self) -> list[tuple[float, float]]:
        return [(x, y) for x, y in self.body_arrays.xyt[:, :2].tolist()]

    def command(self, k: int, target: tuple[float, float] | None) -> None:
        """Robot k (0-based) asks to drive toward `target` (None: stop)."""
        self.bodies[k].target = target

    def _free(self, x: float, y: float) -> bool:
        r, c = int(y / self.truth.cell), int(x / self.truth.cell)
        h, w = self.blocked.shape
        return 0 <= r < h and 0 <= c < w and not self.blocked[r, c]

    def move(self) -> None:
        """Advance every live robot by one step toward its target."""
        paths = self.paths
        for i, b in enumerate(self.bodies):
            if not b.alive or b.target is None:
                continue
            if not (math.isfinite(b.target[0]) and math.isfinite(b.target[1])):
                continue  # no way leads there (a robot's command may say anything): it stays
            dx, dy = b.target[0] - b.x, b.target[1] - b.y
            d = math.hypot(dx, dy)
            if d < 1e-9:
                continue
            s = min(self.speed, d)
            ux, uy = dx / d, dy / d
            # Straight on if the way is clear; else slide along whichever axis is (a robot
            # grazing a wall keeps going along it); else stay and count a collision.
            for mx, my in ((ux, uy), (math.copysign(1.0, ux), 0.0), (0.0, math.copysign(1.0, uy))):
                if mx * ux + my * uy <= 1e-6:
                    continue  # no progress toward the target that way
                step_len = s if (mx, my) == (ux, uy) else min(s, abs(mx * dx + my * dy))
                nx, ny = b.x + mx * step_len, b.y + my * step_len
                if self._free(nx, ny):
                    break
            else:
                b.collisions += 1
                continue
            if (mx, my) != (ux, uy):
                b.collisions += 1
            s = math.hypot(nx - b.x, ny - b.y)
            b.theta = math.atan2(dy, dx)
            b.path_length += s
            b.x, b.y = nx, ny
            paths[i].append((nx, ny))
        self.step_no += 1

    def cast_live(self, live: np.ndarray) -> None:
        """Every live robot's laser (`live`: one bool a robot) from where it stands, for its
        frame: afterwards `frame_xyt` row i holds robot i's pose (x, y, theta) and
        `frame_ranges` row i its scan where `frame_has[i]` is 1 (0: no ray returned, every
        range +inf). A robot that has not moved since its last cast keeps that cast (and saw
        nothing new). Where the step core runs, the robots that moved are cast in one
        compiled call (a call per robot cost more than its cast), which also counts the free
        cells seen for the first time; each robot is cast as `scan` casts it."""
        if self.frame_xyt is not self.body_arrays.xyt:
            self.frame_xyt[:] = self.body_arrays.xyt
        cast = self._cast
        if cast is None:
            for i in np.flatnonzero(live).tolist():
                self.frame_ranges[i] = self.scan(i)
            return
        fresh, fallbacks = cast.cast_moved(live)
        if self._seen_free_count is not None:
            self._seen_free_count += fresh
        if fallbacks:  # the laser's window sticks out of the map: scan's own path
            for i in np.flatnonzero(self.frame_has < 0).tolist():
                self.frame_ranges[i] = self.scan(i)
                self.frame_has[i] = 1

    def scan(self, k: int) -> np.ndarray:
        """Cast robot k's laser (0-based) and add what it saw to the team's seen cells."""
        b = self.bodies[k]
        cached = self._last_scan[k]
        if cached is not None and cached[0] == (b.x, b.y):
            return cached[1]  # it did not move: same scan, nothing new seen
        self._seen_free_count = None  # counted again by coverage()
        r, c = int(b.y / self.truth.cell), int(b.x / self.truth.cell)
        if stepcore.NATIVE:
            s0 = self.laser.n_samples if self.open_space[r, c] else int(self._skip[r, c])
            cast = stepcore.cast_window(self.laser, self._occ_u8, self._seen_u8, b.x, b.y, s0,
                                        _BIAS)  # fmt: skip
            if cast is not None:
                ranges = cast[0] if cast[1] else self._no_returns
                self._last_scan[k] = ((b.x, b.y), ranges)
                return ranges
        elif self.open_space[r, c]:
            # No obstacle within laser range: every ray runs out, the cast is skipped and the
            # seen cells are the robot's own free cells for a scan without returns.
            r0, c0, free, _ = self.laser.window_marks(b.x, b.y, None)
            h, w = free.shape
            seen = self.seen_padded[r0 : r0 + h, c0 : c0 + w]
            if r0 >= 0 and c0 >= 0 and seen.shape == free.shape:
                seen |= free
                self._last_scan[k] = ((b.x, b.y), self._no_returns)
                return self._no_returns
        else:
            ranges = self._cast_window(b.x, b.y, int(self._skip[r, c]))
            if ranges is not None:
                self._last_scan[k] = ((b.x, b.y), ranges)
                return ranges
        # The laser's window sticks out of the map (its very edge): flat indices of it all.
        flat = self.laser.flat_cells(b.x, b.y, self.occ_padded.shape[1])
        seen = self.seen_padded.reshape(-1)
        if not self.open_space[r, c]:
            hit = np.take(self.occ_padded.reshape(-1), flat)
            first = hit.argmax(axis=1)
            any_hit = hit[self._rays, first]
        else:  # open space where the window does not fit (the map's very edge)
            first = np.zeros(self.laser.n_rays, dtype=np.int64)
            any_hit = np.zeros(self.laser.n_rays, dtype=bool)
        if not any_hit.any():
            seen[flat[self.laser.mark]] = True
            ranges = self._no_returns
        else:
            first[~any_hit] = self.laser.n_samples
            ranges = np.full(self.laser.n_rays, np.inf, dtype=np.float32)
            ranges[any_hit] = ((first[any_hit] + 1) * self.laser.step).astype(np.float32)
            seen[flat[self.laser.mark & (self._k <= first[:, None])]] = True
            hits = np.flatnonzero(any_hit)
            seen[flat[hits, first[hits]]] = True
        self._last_scan[k] = ((b.x, b.y), ranges)
        return ranges

    def _cast_window(self, x: float, y: float, s0: int = 0) -> np.ndarray | None:
        """Cast from (x, y) on the laser's square window of the map and mark what it saw;
        None (nothing done) when the window does not fit in the padded map. Samples before
        `s0` are known to fall in free cells and are not looked at."""
        laser = self.laser
        w = laser.window
        fx = np.float32(x / laser.cell + _BIAS)
        fy = np.float32(y / laser.cell + _BIAS)
        cb, rb = int(fx), int(fy)
        r0, c0 = rb - _BIAS, cb - _BIAS
        occ = self.occ_padded[r0 : r0 + w, c0 : c0 + w]
        seen = self.seen_padded[r0 : r0 + w, c0 : c0 + w]
        if r0 < 0 or c0 < 0 or occ.shape != (w, w):
            return None
        any_hit = None
        if s0 < laser.n_samples:
            # window_cells for samples s0.. only (the same float32 arithmetic).
            loc = (laser.dy[:, s0:] + fy).astype(np.int32)
            loc *= w
            loc += (laser.dx[:, s0:] + fx).astype(np.int32)
            loc += (laser.pad - rb) * w + (laser.pad - cb)
            hit = np.take(occ.reshape(-1), loc)  # a copy of the small window, then samples
            first = hit.argmax(axis=1)
            any_hit = hit[self._rays, first]
        if any_hit is None or not any_hit.any():
            ranges, idx = self._no_returns, None
        else:
            first += s0
            first[~any_hit] = laser.n_samples
            ranges = np.full(laser.n_rays, np.inf, dtype=np.float32)
            ranges[any_hit] = ((first[any_hit] + 1) * laser.step).astype(np.float32)
            idx = first
        # Seen: the marked samples up to each ray's hit and every hit sample (scan_window's
        # free and occupied cells).
        _, _, free, hits = laser.window_marks(x, y, idx)
        seen |= free
        if len(hits):
            seen[np.divmod(hits, w)] = True
        return ranges

    def coverage(self) -> float:
        """Fraction of the free space the team's lasers have seen (the count cast_live keeps,
        or counted again after a scan)."""
        if self._seen_free_count is None:
            if stepcore.NATIVE:
                self._seen_free_count = stepcore.count_and(*self._seen_free)
            else:
                self._seen_free_count = int(np.count_nonzero(self.seen & self.free_space))
        return self._seen_free_count / self.free_total


class MoveLog:
    """The moves the compiled World.move made (testbed.world.stepfast): robot, x, y, in the
    order World.move appends them to the paths, until `drain` takes them there."""

    def __init__(self, cap: int) -> None:
        self.i = np.zeros(cap, dtype=np.int64)
        self.xy = np.zeros((cap, 2), dtype=np.float64)
        self.length = np.zeros(1, dtype=np.int64)  # the compiled step keeps its own count

    def drain(self, paths: list[list[tuple[float, float]]]) -> None:
        n = int(self.length[0])
        if not n:
            return
        for i, (x, y) in zip(self.i[:n].tolist(), self.xy[:n].tolist(), strict=True):
            paths[i].append((x, y))
        self.length[0] = 0
