"""How far the robots may move before a link of the disc model can come or go.

Theory of operation. Under the disc model a pair of robots is linked when their distance is at
most the range. After the links are decided in full at some positions, every pair's distance
is some way from the range: the least of those gaps is the slack. A move of robots i and j
changes their distance by at most the sum of the two moves (the triangle inequality), so a
batch of moves changes any pair's distance by at most the two largest moves of the batch
together. While the moves, batch after batch, have spent less than the slack, no pair can
have crossed the range and the link set is the one decided last: a world step that moved the
robots a little need not ask the range model again (it was most of the topology controller's
time on a step). The gap is kept a micrometre short, and each move counted a part in 1e9
long, so that the rounding of the distances (math.hypot's and numpy's, each within an ulp
for coordinates within topology.spec.MAX_COORD_M) can never make the answer wrong. The moves
are counted from the positions of the last call, whoever moved the robots in between (a move
by hand decides its links itself, and they agree with the range model), so only what makes
links follow something besides the positions (isolation, a network shared through its state
file) has to switch it off.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

from topology.spec import VETH, NetworkSpec, Position

T = TypeVar("T")

MARGIN_M = 1e-6  # taken off the gap: far above any rounding of the distances
RELATIVE = 1e-9  # added to each move, for the same reason


class Slack:
    """The slack left since the last full decision (`measure`); `holds(positions)` spends the
    moves to `positions` and says whether the links are still the ones decided then. Only
    for the disc model on veth links (ns-3's channel takes every position; the other models'
    links or impairments change with any move)."""

    def __init__(self, spec: NetworkSpec) -> None:
        self.comm_range = float(spec.comm_range)
        self.applies = spec.range_model == "disc" and spec.medium == VETH
        self._left = -1.0  # negative: nothing measured, or spent
        self._last: list[Position] = []

    def measure(self, positions: list[Position]) -> None:
        """The links were just decided in full at `positions`: the least gap of any pair's
        distance from the range, less the margin."""
        if not self.applies:
            return
        self._last = list(positions)
        if len(positions) < 2:
            self._left = math.inf
            return
        xy = np.asarray(positions, dtype=np.float64)
        dx = np.subtract.outer(xy[:, 0], xy[:, 0])
        dy = np.subtract.outer(xy[:, 1], xy[:, 1])
        gap = np.abs(np.hypot(dx, dy) - self.comm_range)
        gap[np.diag_indices(len(positions))] = math.inf
        self._left = float(gap.min()) - MARGIN_M

    def measured(self, positions: list[Position], diff: T) -> T:
        """`measure(positions)` after a full decision that returned `diff`; returns it."""
        self.measure(positions)
        return diff

    def holds(self, positions: list[Position], off: bool = False) -> bool:
        """Spend the moves from the last positions to `positions`; whether every pair is
        still on the side of the range it was on at the last `measure`. `off`: the caller's
        links follow something besides the positions now (robots isolated, a network shared
        through its state file): decide in full."""
        if off or self._left < 0 or len(positions) != len(self._last):
            self._left = -1.0
            return False
        first = second = 0.0  # the two largest moves
        for (x, y), (px, py) in zip(positions, self._last, strict=True):
            d = math.hypot(x - px, y - py)
            if d > first:
                first, second = d, first
            elif d > second:
                second = d
        self._left -= (first + second) * (1 + RELATIVE)
        self._last = list(positions)
        return self._left > 0
