"""The two coordination modes (node.coordination) on small hand-made situations."""

import numpy as np
import pytest

from node import coordination
from node.grid import FREE, OCC, UNKNOWN
from node.planner import PlannerParams, plan

LIT = PlannerParams(cell=1.0, factor=1, robot_radius=0.0)  # one cell = one metre
LASER = 2.0


def grid(rows: list[str]) -> np.ndarray:
    m = {"#": OCC, ".": FREE, "?": UNKNOWN}
    return np.array([[m[c] for c in r] for r in rows], dtype=np.uint8)


# A corridor: the only unknown is at its right end.
CORRIDOR = grid(["##########", "#.......??", "##########"])
FRONTIER = (7.5, 1.5)  # the free cell next to the unknown


@pytest.mark.parametrize("mode", coordination.MODES)
def test_two_robots_same_frontier_the_nearer_asks_the_farther_to_replan(mode):
    # Both robots pick the corridor's one frontier; r2 (at x=6.5) is nearer than r1 (x=1.5).
    p1 = plan(CORRIDOR, (1.5, 1.5), [], LASER, LIT)
    p2 = plan(CORRIDOR, (6.5, 1.5), [], LASER, LIT)
    assert p1.goal == p2.goal == FRONTIER and p2.cost < p1.cost
    # r2 hears r1's goal: it has the higher priority, so it detects the conflict and asks.
    assert coordination.on_goal(mode, 2, p2.goal, p2.cost, 1, p1.goal, p1.cost, False,
                                LASER) == "request"  # fmt: skip
    # r1 hears r2's goal: it has the lower priority, so it does nothing and waits.
    assert coordination.on_goal(mode, 1, p1.goal, p1.cost, 2, p2.goal, p2.cost, False,
                                LASER) == "none"  # fmt: skip
    # r1 re-plans on the request, avoiding r2's goal, which it now holds.
    assert coordination.on_request(mode, p1.goal, p2.goal, LASER)
    # Equal costs: the lower robot number wins.
    assert coordination.on_goal(mode, 1, FRONTIER, 3.0, 2, FRONTIER, 3.0, False,
                                LASER) == "request"  # fmt: skip


def test_goals_farther_apart_than_the_laser_range_do_not_conflict():
    for mode in coordination.MODES:
        assert coordination.on_goal(mode, 1, (1.0, 1.0), 1.0, 2, (3.5, 1.0), 5.0, False,
                                    LASER) == "none"  # fmt: skip


def test_every_frontier_near_a_teammates_goal_paper_waits_ours_falls_back():
    teammate_goal = [FRONTIER]
    paper = plan(CORRIDOR, (1.5, 1.5), teammate_goal, LASER, LIT,
                 fallback=coordination.allows_fallback("paper"))  # fmt: skip
    assert paper.status == "blocked" and paper.goal is None and paper.path == []
    ours = plan(CORRIDOR, (1.5, 1.5), teammate_goal, LASER, LIT,
                fallback=coordination.allows_fallback("ours"))  # fmt: skip
    assert ours.status == "fallback" and ours.goal == FRONTIER
    # A fallback goal is never asked to move in ours: there is nothing better to offer.
    assert coordination.on_goal("ours", 2, FRONTIER, 1.0, 1, FRONTIER, 6.0, True,
                                LASER) == "none"  # fmt: skip


def test_blocked_is_not_done():
    # With no frontier at all, both modes are done, whatever the teammates' goals.
    closed = grid(["#####", "#...#", "#####"])
    for mode in coordination.MODES:
        p = plan(closed, (1.5, 1.5), [(2.5, 1.5)], LASER, LIT,
                 fallback=coordination.allows_fallback(mode))  # fmt: skip
        assert p.status == "done"


def test_a_request_after_the_loser_already_replanned():
    winner_goal = FRONTIER
    replanned = (1.5, 1.5)  # the loser's new goal, far from the winner's
    # paper: "forces the robot with a lower priority to choose another goal": it re-plans.
    assert coordination.on_request("paper", replanned, winner_goal, LASER)
    assert coordination.on_request("paper", None, winner_goal, LASER)
    # ours: the request is about a goal it no longer has: stale, ignored.
    assert not coordination.on_request("ours", replanned, winner_goal, LASER)
    assert not coordination.on_request("ours", None, winner_goal, LASER)
    # ...but a request about its current goal is obeyed in both.
    assert coordination.on_request("ours", (7.0, 1.5), winner_goal, LASER)


def test_timer_paper_keeps_its_own_schedule_ours_counts_from_the_last_plan():
    # Last plan on request at step 35; the timer's schedule ticks at 20, 40, 60.
    assert coordination.timer_due("paper", 40, last_plan_step=35, next_tick=40, period=20)
    assert not coordination.timer_due("ours", 40, last_plan_step=35, next_tick=40, period=20)
    assert coordination.timer_due("ours", 55, last_plan_step=35, next_tick=60, period=20)
    assert not coordination.timer_due("paper", 55, last_plan_step=35, next_tick=60, period=20)


@pytest.mark.parametrize("mode", coordination.MODES)
def test_conflict_resolution(mode):
    g1, g2, far = (1.0, 1.0), (2.0, 1.0), (9.0, 9.0)

    def on_goal(me, mine, cost, other, theirs, their_cost):
        return coordination.on_goal(mode, me, mine, cost, other, theirs, their_cost, False, 2.0)

    assert on_goal(1, g1, 3.0, 2, far, 1.0) == "none"
    assert on_goal(1, None, 0.0, 2, g2, 1.0) == "none"
    assert on_goal(1, g1, 1.0, 2, g2, 3.0) == "request"  # I am nearer: I win
    assert on_goal(1, g1, 3.0, 2, g2, 1.0) == "none"  # I lose: I wait for its request
    # Symmetric: exactly one of the two asks the other.
    a = on_goal(1, g1, 2.0, 2, g2, 2.0)
    b = on_goal(2, g2, 2.0, 1, g1, 2.0)
    assert {a, b} == {"request", "none"}
