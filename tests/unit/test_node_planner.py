"""Frontier detection, planning and the goal rules on small hand-made grids."""

import numpy as np
import pytest

from node.grid import FREE, OCC, UNKNOWN
from node.planner import (
    PlannerParams,
    frontiers,
    goal_priority,
    plan,
    pool,
    trace_back,
    traversable,
    wavefront,
)

# One map cell = one planning cell, radius 0: the grids below are read literally.
LIT = PlannerParams(cell=1.0, factor=1, robot_radius=0.0)


def grid(rows: list[str]) -> np.ndarray:
    """'#' occupied, '.' free, '?' unknown."""
    m = {"#": OCC, ".": FREE, "?": UNKNOWN}
    return np.array([[m[c] for c in r] for r in rows], dtype=np.uint8)


def test_frontier_cells_are_free_next_to_unknown():
    t = grid(
        [
            "#####",
            "#..?#",
            "#...#",
            "#####",
        ]
    )
    f = frontiers(t)
    assert set(zip(*np.nonzero(f), strict=True)) == {(1, 2), (2, 3)}  # (2, 2) only diagonally


def test_pool_any_occupied_all_free():
    t = grid(["..#.", "....", "..??", ".?.."])
    p = pool(t, 2)
    assert p.tolist() == [[FREE, OCC], [UNKNOWN, UNKNOWN]]


def test_traversable_inflates_obstacles():
    t = grid([".....", ".....", "..#..", ".....", "....."])
    trav = traversable(t, 1)
    assert not trav[1, 2] and not trav[2, 1] and trav[0, 0] and trav[1, 1] is not None


def test_nearest_frontier_by_path_not_straight_line():
    # The frontier on the right is closer in straight line but behind a wall; the one on the
    # left is nearer by path.
    t = grid(
        [
            "###########",
            "#?......#.?",
            "#.......#..",
            "#.......#..",
            "#..........",
            "###########",
        ]
    )
    p = plan(t, (6.5, 1.5), [], 0.0, LIT)
    assert p.status == "ok"
    assert p.goal == (2.5, 1.5) or p.goal == (1.5, 2.5)
    assert p.path[0] == (6.5, 1.5)


def test_unreachable_frontier_means_done():
    t = grid(
        [
            "#######",
            "#...#.?",
            "#...#..",
            "#######",
        ]
    )
    assert plan(t, (1.5, 1.5), [], 0.0, LIT).status == "done"


def test_narrow_passage_is_found():
    t = grid(
        [
            "#########",
            "#...#...?",
            "#.......#",  # one-cell gap at column 4
            "#...#...#",
            "#########",
        ]
    )
    p = plan(t, (1.5, 1.5), [], 0.0, LIT)
    assert p.status == "ok"
    assert p.goal == (7.5, 1.5)
    assert (4.5, 2.5) in p.path  # the path goes through the gap
    assert p.cost == pytest.approx(np.hypot(3, 1) + 3 + np.hypot(1, 1) * 0 + 1, abs=1.5)


def test_narrow_passage_too_narrow_for_the_robot():
    # 5 cm cells, 10 cm planning cells, robot radius 15 cm: a 20 cm gap does not let it pass.
    t = np.full((40, 80), FREE, dtype=np.uint8)
    t[0, :] = t[-1, :] = t[:, 0] = OCC
    t[:, 40:42] = OCC
    t[18:22, 40:42] = FREE  # 20 cm gap
    t[:, 79] = UNKNOWN
    prm = PlannerParams(cell=0.05, factor=2, robot_radius=0.15)
    assert plan(t, (0.5, 1.0), [], 2.0, prm).status == "done"
    t[10:30, 40:42] = FREE  # 1 m gap
    p = plan(t, (0.5, 1.0), [], 2.0, prm)
    assert p.status == "ok" and p.goal[0] > 3.8


def test_goal_separation_skips_frontiers_near_teammate_goals():
    t = grid(
        [
            "##############",
            "?............?",
            "##############",
        ]
    )
    near = plan(t, (3.5, 1.5), [], 0.0, LIT)
    assert near.goal == (1.5, 1.5)
    away = plan(t, (3.5, 1.5), [(1.0, 1.5)], 2.0, LIT)
    assert away.status == "ok" and away.goal == (12.5, 1.5)
    # Every frontier near a teammate's goal: take the nearest anyway, do not stop.
    both = plan(t, (3.5, 1.5), [(1.0, 1.5), (13.0, 1.5)], 2.0, LIT)
    assert both.status == "fallback" and both.goal == (1.5, 1.5)


def test_wavefront_distances_and_trace():
    passable = np.ones((5, 5), dtype=bool)
    passable[1:4, 2] = False
    wanted = np.zeros((5, 5), dtype=bool)
    wanted[2, 4] = True
    dist, cell, kind = wavefront(passable, (2, 0), wanted, wanted)
    assert kind == "ok" and cell == (2, 4)
    path = trace_back(dist, cell)
    assert path[0] == (2, 0) and path[-1] == (2, 4)
    assert all(passable[r, c] for r, c in path)
    steps = [max(abs(a[0] - b[0]), abs(a[1] - b[1])) for a, b in zip(path, path[1:], strict=False)]
    assert steps and max(steps) == 1


def test_priority_shorter_path_wins_then_lower_id():
    assert goal_priority(1.0, 5) < goal_priority(2.0, 1)
    assert goal_priority(1.0, 2) < goal_priority(1.0, 3)
