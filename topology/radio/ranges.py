"""Range models: which robots are linked, and how good each link is, given their positions.

Pure functions of positions (no kernel). `wanted_links` returns a dict from an ordered pair
(i, j), i < j, to the Impairment of that link; the medium diffs it against what it has
(docs/architecture.md, "The radio medium"), so a step in which nothing changes costs nothing.

- disc (the paper's model): linked iff distance <= comm range; links are perfect.
- lossy: linked iff distance <= comm range, with loss growing with distance: none up to half
  the range, then rising quadratically to MAX_EDGE_LOSS_PCT at the edge (a crude but common
  stand-in for fading near the edge of radio range). Loss is rounded to whole percent so that
  small moves do not churn the kernel.
- los: as disc, and the straight line between the robots must cross no wall of the map
  (topology.radio.los); with `wall_loss_pct` a wall costs that much loss instead of blocking
  (losses combine as independent drops: 1 - (1-a)(1-b); 100% or more is no link).
- los-lossy: los, with the lossy model's edge loss on top.
"""

import math

import numpy as np

from topology.radio.los import Walls, crossings
from topology.spec import LOS_MODELS, NO_IMPAIRMENT, Impairment, Position

MAX_EDGE_LOSS_PCT = 50.0


def distance(a: Position, b: Position) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def _lossy(d: float, comm_range: float) -> Impairment:
    frac = d / comm_range
    if frac <= 0.5:
        return NO_IMPAIRMENT
    return Impairment(loss_pct=float(round(MAX_EDGE_LOSS_PCT * ((frac - 0.5) / 0.5) ** 2)))


def _combined_loss(a: float, b: float) -> float:
    return 100.0 * (1.0 - (1.0 - a / 100.0) * (1.0 - b / 100.0))


def _through_walls(
    links: dict[tuple[int, int], Impairment],
    positions: list[Position] | tuple[Position, ...],
    walls: Walls,
    wall_loss_pct: float | None,
) -> dict[tuple[int, int], Impairment]:
    """The links of a distance model, kept, weakened or cut by the walls between them."""
    pairs = list(links)
    counts = crossings(walls, [(positions[i - 1], positions[j - 1]) for i, j in pairs])
    out: dict[tuple[int, int], Impairment] = {}
    for pair, n in zip(pairs, counts, strict=True):
        if n == 0:
            out[pair] = links[pair]
        elif wall_loss_pct is not None:
            loss = links[pair].loss_pct
            for _ in range(n):
                loss = _combined_loss(loss, wall_loss_pct)
            if loss < 99.5:
                out[pair] = Impairment(loss_pct=float(round(loss)))
    return out


def wanted_links(
    positions: list[Position] | tuple[Position, ...],
    comm_range: float,
    model: str = "disc",
    walls: Walls | None = None,
    wall_loss_pct: float | None = None,
) -> dict[tuple[int, int], Impairment]:
    """Links among robots 1..N (positions[k-1] is robot k) under the given model. The los
    models need `walls` (no map: nothing blocks, as on the empty terrain)."""
    if model not in ("disc", "lossy", "los", "los-lossy"):
        raise ValueError(f"unknown range model {model!r}")
    if model in LOS_MODELS:
        near = wanted_links(positions, comm_range, "lossy" if model == "los-lossy" else "disc")
        return _through_walls(near, positions, walls, wall_loss_pct) if walls else near
    links: dict[tuple[int, int], Impairment] = {}
    for i, j in _candidates(positions, comm_range):
        d = math.hypot(positions[i][0] - positions[j][0], positions[i][1] - positions[j][1])
        if d <= comm_range:
            links[(i + 1, j + 1)] = NO_IMPAIRMENT if model == "disc" else _lossy(d, comm_range)
    return links


VECTOR_FROM = 48  # robots; below, the plain double loop is faster than numpy's set-up


def _near(xy: np.ndarray, rows: np.ndarray, comm_range: float) -> tuple[np.ndarray, np.ndarray]:
    """(row index, column) of every robot within the range (plus a margin) of robot rows[r]."""
    dx = np.subtract.outer(xy[rows, 0], xy[:, 0])
    dy = np.subtract.outer(xy[rows, 1], xy[:, 1])
    dx *= dx
    dy *= dy
    dx += dy
    row, col = np.nonzero(dx <= (comm_range * (1 + 1e-9) + 1e-9) ** 2)
    return row, col


def _candidates(positions, comm_range: float):
    """Index pairs (i, j), i < j, that may be in range: every pair for a small team; for a
    large one, the pairs numpy finds within the range plus a margin, in the same order (the
    caller decides each with math.hypot, so both paths give exactly the same links). At 1000
    robots the double loop costs 0.1-0.3 s per move, numpy about 10 ms."""
    n = len(positions)
    if n < VECTOR_FROM:
        return ((i, j) for i in range(n) for j in range(i + 1, n))
    xy = np.asarray(positions, dtype=float)
    i, j = _near(xy, np.arange(n), comm_range)
    keep = i < j
    return zip(i[keep].tolist(), j[keep].tolist(), strict=True)


def links_of(
    positions: list[Position] | tuple[Position, ...],
    robots: set[int],
    comm_range: float,
    model: str = "disc",
) -> dict[tuple[int, int], Impairment]:
    """The links of the distance models (disc, lossy) that involve one of `robots`: what a
    move of those robots changes, in O(moved x N) instead of O(N^2). wanted_links(...) equals
    the links of the others kept, plus these."""
    if model not in ("disc", "lossy"):
        raise ValueError(f"links_of serves the distance models, not {model!r}")
    if not robots:
        return {}
    xy = np.asarray(positions, dtype=float)
    rows = np.array(sorted(k - 1 for k in robots))
    r, col = _near(xy, rows, comm_range)
    links: dict[tuple[int, int], Impairment] = {}
    for a, b in zip(rows[r].tolist(), col.tolist(), strict=True):
        if a == b:
            continue
        d = math.hypot(positions[a][0] - positions[b][0], positions[a][1] - positions[b][1])
        if d <= comm_range:
            pair = (a + 1, b + 1) if a < b else (b + 1, a + 1)
            links[pair] = NO_IMPAIRMENT if model == "disc" else _lossy(d, comm_range)
    return links


def diff(
    current: dict[tuple[int, int], Impairment], wanted: dict[tuple[int, int], Impairment]
) -> tuple[list[tuple[int, int]], list[tuple[int, int]], list[tuple[int, int]]]:
    """(to add, to remove, to change impairment), each sorted."""
    if wanted.keys() == current.keys():  # most world steps: the same links (a singleton's
        # impairment is compared by identity first: a dataclass's == is slow)
        change = [p for p, imp in wanted.items() if imp is not current[p] and imp != current[p]]
        return [], [], sorted(change)
    add = sorted(set(wanted) - set(current))
    remove = sorted(set(current) - set(wanted))
    change = sorted(p for p in set(wanted) & set(current) if wanted[p] != current[p])
    return add, remove, change
