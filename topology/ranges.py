"""Range models: which robots are linked, and how good each link is, given their positions.

Pure functions of positions (no kernel). `wanted_links` returns a dict from an ordered pair
(i, j), i < j, to the Impairment of that link; the medium diffs it against what it has
(STYLE.md example 6), so a step in which nothing changes costs nothing.

- disc (the paper's model): linked iff distance <= comm range; links are perfect.
- lossy: linked iff distance <= comm range, with loss growing with distance: none up to half
  the range, then rising quadratically to MAX_EDGE_LOSS_PCT at the edge (a crude but common
  stand-in for fading near the edge of radio range). Loss is rounded to whole percent so that
  small moves do not churn the kernel.
"""

import math

from topology.spec import NO_IMPAIRMENT, Impairment, Position

MAX_EDGE_LOSS_PCT = 50.0


def distance(a: Position, b: Position) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def _lossy(d: float, comm_range: float) -> Impairment:
    frac = d / comm_range
    if frac <= 0.5:
        return NO_IMPAIRMENT
    return Impairment(loss_pct=float(round(MAX_EDGE_LOSS_PCT * ((frac - 0.5) / 0.5) ** 2)))


def wanted_links(
    positions: list[Position] | tuple[Position, ...], comm_range: float, model: str = "disc"
) -> dict[tuple[int, int], Impairment]:
    """Links among robots 1..N (positions[k-1] is robot k) under the given model."""
    if model not in ("disc", "lossy"):
        raise ValueError(f"unknown range model {model!r}")
    links: dict[tuple[int, int], Impairment] = {}
    n = len(positions)
    for i in range(n):
        xi, yi = positions[i]
        for j in range(i + 1, n):
            d = math.hypot(xi - positions[j][0], yi - positions[j][1])
            if d <= comm_range:
                links[(i + 1, j + 1)] = (
                    NO_IMPAIRMENT if model == "disc" else _lossy(d, comm_range)
                )  # fmt: skip
    return links


def diff(
    current: dict[tuple[int, int], Impairment], wanted: dict[tuple[int, int], Impairment]
) -> tuple[list[tuple[int, int]], list[tuple[int, int]], list[tuple[int, int]]]:
    """(to add, to remove, to change impairment), each sorted."""
    add = sorted(set(wanted) - set(current))
    remove = sorted(set(current) - set(wanted))
    change = sorted(p for p in set(wanted) & set(current) if wanted[p] != current[p])
    return add, remove, change
