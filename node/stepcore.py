"""The per-step work in compiled code, loaded when it was built, numpy otherwise.

Theory of operation: native/stepcore/stepcore.cc holds compiled twins of the functions that run
every step or every plan (the world's laser cast, a scan into the robot's maps, classifying
and merging maps, and the planner); native/stepcore/bodylink.cc the world's share of its body
links each step (testbed.world.bodylink calls it). `make setup` builds it with g++ into
build/libstepcore.so; this module loads it with ctypes (a plain C ABI: no Python headers, no
binding library, no compiler at run time) and wraps each function so that it takes and
returns what its numpy twin does. The numpy functions stay the reference: the unit tests
hold the two equal cell for cell, and the callers (node.grid, node.planner, node.robot,
testbed.world) use the compiled one only when `NATIVE` is set.

`TESTBED_STEPCORE=numpy` in the environment makes every process of a run use numpy (to
compare the two, or where the library cannot be built); `kind()` says which one runs, and
a run records it.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from common import envswitch
from common.paths import PROJECT_ROOT
from node.rays import _BUCKETS, _FRAC

# TESTBED_STEPCORE_LIBRARY: another build of it in build/ (the sanitized one its test loads).
LIBRARY = envswitch.library("TESTBED_STEPCORE_LIBRARY") or (
    Path(PROJECT_ROOT) / "build" / "libstepcore.so"
)
VERSION = 3  # sc_version() of the source this wrapper was written for

_P = ctypes.c_void_p
_I = ctypes.c_int
_L = ctypes.c_int64
_F = ctypes.c_float
_D = ctypes.c_double

_SIGNATURES = {
    "sc_version": (_I, []),
    "sc_window_marks": (_I, [_P, _P, _P, _I, _I, _I, _F, _F, _I, _I, _P, _P, _P]),
    "sc_cast_window": (_I, [_P, _P, _P, _I, _I, _D, _F, _F, _I, _I, _P, _P, _L, _I, _P, _P]),
    "sc_world_cast": (
        _L,
        [_I, _P, _P, _D, _D, _I, _I, _I, _P, _P, _P, _I, _I, _D, _I, _I, _I, _P, _P, _P, _P]
        + [_P, _P, _P, _L, _L, _P, _P, _L, _L, _P, _P, _P],
    ),  # fmt: skip
    "sc_world_cast_moved": (
        _L,
        [_P, _P, _P, _P, _I, _P, _P, _D, _D, _I, _I, _I, _P, _P, _P, _I, _I, _D, _I, _I, _I, _P]
        + [_P, _P, _P, _P, _P, _P, _L, _L, _P, _P, _L, _L, _P, _P, _P],
    ),  # fmt: skip
    "sc_scan_into": (
        None,
        [_P, _P, _P, _I, _I, _F, _I, _F, _F, _I, _I, _P, _P, _P, _L, _L, _L, _F, _F, _F, _P, _P]
        + [_P, _P, _P, _I],
    ),  # fmt: skip
    "sc_mark_table": (None, [_P, _I, _P, _P, _I, _F, _F, _I, _I, _P, _L, _I]),
    "sc_classify": (None, [_P, _I, _I, _L, _F, _P]),
    "sc_merge_ternary": (_L, [_P, _L, _P, _I, _I, _F, _F]),
    "sc_count_and": (_L, [_P, _P, _L]),
    "sc_pool": (None, [_P, _I, _I, _I, _P]),
    "sc_traversable": (None, [_P, _I, _I, _I, _P]),
    "sc_frontier_goals": (None, [_P, _P, _I, _I, _P]),
    "sc_wavefront": (_I, [_P, _P, _P, _I, _I, _I, _I, _P, _P]),
    "sc_plan": (_I, [_P, _I, _I, _I, _I, _D, _D, _D, _P, _I, _D, _I, _P, _P, _I]),
    "sc_body_take": (_L, [_I, _P, _P, _P, _P, _P, _P, _P, _L, _P]),  # testbed.world.bodylink's
    "sc_body_frames": (_I, [_I, _P, _P, _L, _P, _D, _P, _P, _I]),
}


def bind(lib: ctypes.CDLL, signatures: dict) -> bool:
    """Give each function `signatures` names its (result, arguments) types; False when the
    library lacks one of them (an older build)."""
    for name, (res, args) in signatures.items():
        fn = getattr(lib, name, None)
        if fn is None:
            return False
        fn.restype, fn.argtypes = res, args
    return True


def _load() -> ctypes.CDLL | None:
    if envswitch.value("TESTBED_STEPCORE") == "numpy":
        return None
    try:
        lib = ctypes.CDLL(str(LIBRARY))
    except OSError:
        return None
    if not bind(lib, _SIGNATURES):
        return None
    if lib.sc_version() != VERSION:
        return None
    return lib


lib = _load()
NATIVE = lib is not None


class _CastPack(ctypes.Structure):
    """native/stepcore/worldstep.h's sc_cast_pack: sc_world_cast_moved's arguments."""

    _fields_ = [
        ("n", _L), ("xyt", _P), ("has_out", _P), ("xy", _P), ("want", _P),
        ("map_cell", _D), ("laser_cell", _D), ("bias", _L), ("pad", _L), ("w", _L),
        ("dx", _P), ("dy", _P), ("mark", _P), ("n_rays", _L), ("n_samples", _L), ("step", _D),
        ("tabled", _L), ("frac", _L), ("buckets", _L), ("sures", _P), ("odxs", _P),
        ("odys", _P), ("n_opens", _P), ("occ", _P), ("seen", _P), ("free_pad", _P),
        ("ph", _L), ("pw", _L), ("open_space", _P), ("skip", _P), ("mh", _L), ("mw", _L),
        ("ranges_out", _P), ("hit_out", _P), ("fallbacks", _L),
    ]  # fmt: skip


def _cast_step():
    """sc_world_cast_step (worldstep.cc: the world's casts of a step, their arguments in one
    struct), or None where the library has it not."""
    fn = getattr(lib, "sc_world_cast_step", None) if lib is not None else None
    if fn is not None:
        fn.restype, fn.argtypes = _L, [_P, _P]
    return fn


_CAST_STEP = _cast_step()


def kind() -> str:
    """Which implementation of the per-step work this process runs: native or numpy."""
    return "native" if NATIVE else "numpy"


def ptr(a: np.ndarray) -> int:
    """The address of an array's first element (the array must stay alive during the call)."""
    return a.ctypes.data


_ADDRESSES: dict[int, tuple[np.ndarray, int]] = {}


def address(a: np.ndarray) -> int:
    """`ptr` of an array that lives for the whole run (a map, the world's grids), looked up
    once: asking numpy costs more than a scan's compiled work."""
    hit = _ADDRESSES.get(id(a))
    if hit is None or hit[0] is not a:
        if len(_ADDRESSES) > 64:
            _ADDRESSES.clear()
        hit = _ADDRESSES[id(a)] = (a, a.ctypes.data)
    return hit[1]


def classify(logodds: np.ndarray, threshold: float) -> np.ndarray:
    """node.grid.classify, compiled; `logodds` may be a view with strided rows."""
    assert lib is not None  # callers check NATIVE
    a = logodds
    if a.dtype != np.float32 or a.strides[1] != 4:
        a = np.ascontiguousarray(a, dtype=np.float32)
    h, w = a.shape
    out = np.empty((h, w), dtype=np.uint8)
    lib.sc_classify(ptr(a), h, w, a.strides[0] // 4, threshold, ptr(out))
    return out


def merge_ternary(view: np.ndarray, t: np.ndarray, threshold: float, merged: float) -> int:
    """OccupancyGrid.merge_ternary's cell update on `view` (float32, unit column stride)."""
    assert lib is not None  # callers check NATIVE
    t = np.ascontiguousarray(t, dtype=np.uint8)
    h, w = t.shape
    return int(lib.sc_merge_ternary(ptr(view), view.strides[0] // 4, ptr(t), h, w,
                                    threshold, merged))  # fmt: skip


def count_and(a: np.ndarray, b: np.ndarray) -> int:
    """Cells set in both of two contiguous boolean arrays of one shape (alive for the run)."""
    assert lib is not None  # callers check NATIVE
    return int(lib.sc_count_and(address(a), address(b), a.size))


def pool(t: np.ndarray, factor: int) -> np.ndarray:
    assert lib is not None  # callers check NATIVE
    t = np.ascontiguousarray(t, dtype=np.uint8)
    out = np.empty((t.shape[0] // factor, t.shape[1] // factor), dtype=np.uint8)
    lib.sc_pool(ptr(t), t.shape[0], t.shape[1], factor, ptr(out))
    return out


def traversable(p: np.ndarray, inflate: int) -> np.ndarray:
    assert lib is not None  # callers check NATIVE
    p = np.ascontiguousarray(p, dtype=np.uint8)
    out = np.empty(p.shape, dtype=bool)
    lib.sc_traversable(ptr(p), p.shape[0], p.shape[1], inflate, ptr(out))
    return out


def frontier_goals(p: np.ndarray, trav: np.ndarray) -> np.ndarray:
    assert lib is not None  # callers check NATIVE
    p = np.ascontiguousarray(p, dtype=np.uint8)
    trav = np.ascontiguousarray(trav, dtype=bool)
    out = np.empty(p.shape, dtype=bool)
    lib.sc_frontier_goals(ptr(p), ptr(trav), p.shape[0], p.shape[1], ptr(out))
    return out


_KINDS = {0: "done", 1: "ok", 2: "fallback"}


def wavefront(passable, start, wanted, fallback):
    """node.planner.wavefront, compiled: (dist, cell or None, kind)."""
    arrs = [np.ascontiguousarray(a, dtype=bool) for a in (passable, wanted, fallback)]
    h, w = arrs[0].shape
    dist = np.empty((h, w), dtype=np.int32)
    cell = np.zeros(2, dtype=np.intc)
    k = lib.sc_wavefront(*(ptr(a) for a in arrs), h, w, int(start[0]), int(start[1]),
                         ptr(dist), ptr(cell))  # fmt: skip
    return dist, ((int(cell[0]), int(cell[1])) if k else None), _KINDS[k]


_STATUS = {0: "done", 1: "ok", 2: "fallback", 3: "blocked"}


def plan_cells(t, pose, goals, radius, factor, inflate, plan_cell, fallback):
    """node.planner.plan up to the smoothed cell path: (status, [(row, col), ...])."""
    t = np.ascontiguousarray(t, dtype=np.uint8)
    g = np.ascontiguousarray(np.asarray(goals, dtype=np.float64).reshape(-1, 2))
    status = ctypes.c_int(0)
    cap = 256
    while True:
        out = np.empty((cap, 2), dtype=np.intc)
        n = lib.sc_plan(ptr(t), t.shape[0], t.shape[1], factor, inflate, float(pose[0]),
                        float(pose[1]), plan_cell, ptr(g), len(g), float(radius),
                        1 if fallback else 0, ctypes.byref(status), ptr(out), cap)  # fmt: skip
        if n >= 0:
            return _STATUS[status.value], [(int(r), int(c)) for r, c in out[:n]]
        cap = -n


def _laser_tables(laser) -> tuple:
    """The laser's sample offsets and marks as the compiled functions take them, and scratch
    buffers for one scan: the arrays and their addresses (cached on the laser; a laser
    belongs to one thread, the world's step loop or a robot's motion control)."""
    t = getattr(laser, "_native_tables", None)
    if t is None:
        arrays = (
            np.ascontiguousarray(laser.dx, dtype=np.float32),
            np.ascontiguousarray(laser.dy, dtype=np.float32),
            np.ascontiguousarray(laser.mark, dtype=np.uint8),
            np.empty(laser.window * laser.window, dtype=np.uint8),  # a scan's free cells
            np.empty(laser.n_rays, dtype=np.int64),  # its hit cells
            np.empty(laser.n_rays, dtype=np.int32),  # each ray's hit sample
        )
        t = (arrays, tuple(ptr(a) for a in arrays))
        laser._native_tables = t
    return t


def _window(laser, x: float, y: float, bias: int) -> tuple[np.float32, np.float32, int, int] | None:
    """(fx, fy, r0, c0) of a laser at (x, y): node.rays' float32 cell coordinates and the
    top-left cell in the padded grid of the laser's window; None where a coordinate is not
    finite (no window fits it: the callers do nothing, as for one off the map)."""
    qx, qy = x / laser.cell + bias, y / laser.cell + bias
    if not (abs(qx) < 1e38 and abs(qy) < 1e38):  # not finite, or not as a float32
        return None
    fx, fy = np.float32(qx), np.float32(qy)
    return fx, fy, int(fy) - bias, int(fx) - bias


def _table(laser, fx: np.float32, fy: np.float32, bias: int):
    """Laser.window_marks' table for a scan without hits from (fx, fy), as addresses: (sure
    mask, open dx, open dy, how many open), or None where window_marks would not use one."""
    cb, rb = int(fx), int(fy)
    if not laser.tabled:  # a laser too long for its tables (node.rays) marks every sample
        return None
    if not bias <= min(cb, rb) - laser.pad - 1 < max(cb, rb) + laser.pad + 1 < 2 * bias:
        return None
    size = _FRAC // _BUCKETS
    return _class_table(laser, (int((float(fx) - cb) * _FRAC) // size,
                                int((float(fy) - rb) * _FRAC) // size))  # fmt: skip


def _class_table(laser, key: tuple[int, int]):
    """The table of pose-fraction class `key` (bx, by) as addresses (see `_table`)."""
    cache = laser.__dict__.setdefault("_native_marks", {})
    t = cache.get(key)
    if t is None:
        sure, odx, ody = laser._table(*key)
        arrays = (np.ascontiguousarray(sure, dtype=np.uint8),
                  np.ascontiguousarray(odx, dtype=np.float32),
                  np.ascontiguousarray(ody, dtype=np.float32))  # fmt: skip
        t = cache[key] = (arrays, ptr(arrays[0]), ptr(arrays[1]), ptr(arrays[2]), len(odx))
    return t[1:]


def scan_into(laser, x, y, ranges, lp: np.ndarray, own: np.ndarray, lo, bias: int) -> bool:
    """Laser.scan_window, OccupancyGrid.update_window and the local map's update in one call:
    one scan from (x, y) into the log-odds map `lp` and the ternary local map `own` (both
    padded, contiguous, one shape, alive for the run). False (nothing done) where the window
    does not fit."""
    assert lib is not None  # callers check NATIVE
    window = _window(laser, x, y, bias)
    if window is None:
        return False
    fx, fy, r0, c0 = window
    w = laser.window
    if r0 < 0 or c0 < 0 or r0 + w > lp.shape[0] or c0 + w > lp.shape[1]:
        return False
    _, (dx, dy, mark, free, occ, _idx) = _laser_tables(laser)
    if ranges.dtype != np.float32 or not ranges.flags.c_contiguous:
        ranges = np.ascontiguousarray(ranges, dtype=np.float32)
    roff, coff = laser.pad - int(fy), laser.pad - int(fx)
    table = _table(laser, fx, fy, bias) or (None, None, None, 0)
    lib.sc_scan_into(dx, dy, mark, laser.n_rays, laser.n_samples, laser.step32, w, fx, fy,
                     roff, coff, ranges.ctypes.data, address(lp), address(own), lp.shape[1],
                     r0, c0, lo.l_free, lo.l_occ, lo.l_max, free, occ, *table)  # fmt: skip
    return True


def cast_window(laser, occ: np.ndarray, seen: np.ndarray, x, y, s0: int, bias: int):
    """testbed.world's cast from (x, y) on the padded obstacle grid `occ`, samples s0.. only,
    marking what it saw in `seen` (same shape; both alive for the run): (ranges, any ray
    hit), or None where the window does not fit."""
    assert lib is not None  # callers check NATIVE
    window = _window(laser, x, y, bias)
    if window is None:
        return None
    fx, fy, r0, c0 = window
    w = laser.window
    if r0 < 0 or c0 < 0 or r0 + w > occ.shape[0] or c0 + w > occ.shape[1]:
        return None
    _, (dx, dy, mark, _free, _occ, idx) = _laser_tables(laser)
    roff, coff = laser.pad - int(fy), laser.pad - int(fx)
    at = r0 * occ.shape[1] + c0
    if s0 >= laser.n_samples:  # nothing within range, no ray can hit: the table marks
        table = _table(laser, fx, fy, bias)
        if table is not None:
            lib.sc_mark_table(table[0], w, table[1], table[2], table[3], fx, fy, roff, coff,
                              address(seen) + at, seen.shape[1], 1)  # fmt: skip
            return None, False
    ranges = np.empty(laser.n_rays, dtype=np.float32)
    hit = lib.sc_cast_window(dx, dy, mark, laser.n_rays, laser.n_samples, laser.step, fx, fy,
                             roff, coff, address(occ) + at, address(seen) + at, occ.shape[1],
                             min(s0, laser.n_samples), ranges.ctypes.data, idx)  # fmt: skip
    return ranges, bool(hit)


class WorldCast:
    """testbed.world's casts of one step, every robot's in one compiled call
    (sc_world_cast_moved): the world's grids and the laser's tables, as addresses, for the
    run. The caller writes each robot's pose in `xyt` (n x 3: x, y, theta; its own array when
    it gives one); `cast_moved(live)`
    casts each robot that is live and stands elsewhere than at its last cast (`xy`, n x 2)
    and returns (fresh, fallbacks): the cells of `free` seen for the first time, and how many
    robots it did nothing for. After it, `has[i]` says what robot i's last cast gave: 1 its
    ranges are row i of `ranges`, 0 no ray returned, -1 the call did nothing for it (its
    window sticks out of the map: World.scan's own path takes it)."""

    def __init__(self, laser, n: int, map_cell: float, bias: int, occ: np.ndarray,
                 seen: np.ndarray, free: np.ndarray, open_space: np.ndarray,
                 skip: np.ndarray, xyt: np.ndarray | None = None) -> None:  # fmt: skip
        assert lib is not None  # callers check NATIVE
        assert occ.shape == seen.shape == free.shape and occ.dtype == seen.dtype == np.uint8
        self.laser = laser
        self._grids = (occ, seen, np.ascontiguousarray(free, dtype=np.uint8),
                       np.ascontiguousarray(open_space, dtype=np.uint8),
                       np.ascontiguousarray(skip, dtype=np.int32))  # fmt: skip
        self.ranges = np.full((n, laser.n_rays), np.inf, dtype=np.float32)
        self.hit = np.empty(n, dtype=np.int8)
        self.xy = np.full((n, 2), np.nan, dtype=np.float64)  # no robot cast yet
        self.want = np.zeros(n, dtype=np.uint8)
        if xyt is None:
            xyt = np.zeros((n, 3), dtype=np.float64)
        assert xyt.shape == (n, 3) and xyt.dtype == np.float64 and xyt.flags.c_contiguous
        self.xyt = xyt  # the poses: the caller's (the world's bodies), or its own
        self.has = np.zeros(n, dtype=np.int8)
        self._fallbacks = np.zeros(1, dtype=np.int32)
        _, (dx, dy, mark, _free, _occ, idx) = _laser_tables(laser)
        keys = [(bx, by) for bx in range(_BUCKETS) for by in range(_BUCKETS)]
        tables = [_class_table(laser, key) for key in keys] if laser.tabled else []
        self._keep = [
            (ctypes.c_void_p * len(tables))(*(t[i] for t in tables)) for i in range(3)
        ]  # fmt: skip
        self._n_open = np.array([t[3] for t in tables] or [0], dtype=np.int32)
        occ, seen, free, open_space, skip = self._grids
        self._head = (dx, dy, mark, laser.n_rays, laser.n_samples, laser.step,
                      1 if laser.tabled else 0, _FRAC, _BUCKETS,
                      *(ctypes.addressof(a) for a in self._keep), ptr(self._n_open),
                      ptr(occ), ptr(seen), ptr(free), occ.shape[0], occ.shape[1], ptr(open_space),
                      ptr(skip), open_space.shape[0], open_space.shape[1], ptr(self.ranges),
                      ptr(self.hit), idx)  # fmt: skip
        self._args = (n, ptr(self.xy), ptr(self.want), map_cell, laser.cell, bias, laser.pad,
                      laser.window, *self._head)  # fmt: skip

        self._moved_head = (ptr(self.xyt), None, ptr(self.has), ptr(self._fallbacks))
        pack = self._pack = _CastPack()
        head = self._head[:-1]  # all but the scratch of each ray's hit (not needed there)
        fields = [f[0] for f in _CastPack._fields_]
        values = (n, ptr(self.xyt), ptr(self.has), ptr(self.xy), ptr(self.want), map_cell,
                  laser.cell, bias, laser.pad, laser.window, *head, 0)  # fmt: skip
        for name, value in zip(fields, values, strict=True):
            setattr(pack, name, value)
        self._pack_p = ctypes.addressof(pack)

    def cast_moved(self, live: np.ndarray) -> tuple[int, int]:
        assert lib is not None and live.dtype == np.bool_ and live.shape == self.want.shape
        if _CAST_STEP is not None:
            return _CAST_STEP(self._pack_p, address(live)), self._pack.fallbacks
        xyt, _, has, fallbacks = self._moved_head
        fresh = lib.sc_world_cast_moved(xyt, address(live), has, fallbacks, *self._args)
        return fresh, int(self._fallbacks[0])
