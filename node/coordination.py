"""How teammates agree on goals: the paper's rules read literally (`paper`), or ours (`ours`).

Theory of operation. The paper (Slyusar and Kulich 2016) gives the coordination in a few
sentences; each rule below quotes the sentence it interprets. Both modes share the goal rule
and the conflict rule; they differ where the text is silent and `ours` chose what works
better on a real network:

Shared by both modes:
- Section 4: "the closest frontier to the current position of the robot is selected as the
  goal. In addition, the selected goal should not lie in the areas of the current goals of
  the other team members, which have active communication link to the robot." Section 5.2:
  "the distance between the selected goal and goal of another robot should be greater than
  the laser range". *Active communication link* is read as: the teammate's map floods reach
  the robot (within `reach_steps`), i.e. a working route, multi-hop included, since the
  robots talk over AODV routes. A *current goal* is the last one a teammate announced, for
  as long as it keeps planning: a goal not re-announced within `goal_fresh_steps` (two plan
  periods) is no longer current (the text is silent on goals of robots that stopped).
- Section 4: "After the goal selection the robot informs the others about the selected goal
  and reports the priority for this goal." The text does not say what the priority is; here
  a shorter path to the goal is a higher priority, ties to the lower robot number
  (`planner.goal_priority`): the greedy rule makes distance the natural measure.
- Section 4: "If an other team member has the goal in the same area with a higher priority,
  it sends information about its current goal and forces the robot with a lower priority to
  choose another goal." So the robot that *detects* the conflict is the one with the higher
  priority, on hearing the other's goal; the loser waits for the request. The request carries
  the winner's goal, which the loser then avoids. A re-plan may conflict again with someone
  else: that conflict is settled by the same rule when the new goal is announced.

Where the modes differ (the text is silent, or `ours` departs from it):
1. No admissible goal (every reachable frontier lies within the laser range of a teammate's
   current goal). `paper`: "the selected goal should not lie in the areas of the current
   goals" admits no exception, so the robot selects no goal, stops, and tries again at its
   next plan generation. `ours`: it goes to the nearest frontier anyway (a *fallback* goal,
   announced as such, which nobody asks it to give up): a robot standing still explores
   nothing.
2. A request that arrives after the loser has re-planned. `paper`: "forces the robot with a
   lower priority to choose another goal and generate a new plan": it re-plans, whatever
   its current goal. `ours`: a request about a goal it no longer has is stale and ignored.
3. The timer. `paper` (Section 5.2): "A plan generation runs periodically by a timer part
   of the application ... The launching frequency of generation of the plan is 20 steps":
   the timer fires every 20 steps on its own schedule, whatever was planned on request in
   between. `ours`: 20 steps after the last plan generation of any cause.
4. A fallback goal (rule 1 of `ours`) never causes a request: there is nothing better to
   offer its robot. `paper` has no fallback goals.

Neither mode is tuned to make a claim of the paper hold or fail.
"""

from __future__ import annotations

from node import argsdecl, planner

# Declared with the robot's parameters (node.argsdecl), which the option table reads.
MODES = argsdecl.COORDINATIONS
DEFAULT = argsdecl.DEFAULT_COORDINATION


def allows_fallback(mode: str) -> bool:
    """Difference 1: may a robot go to a frontier near a teammate's goal when no other is
    left? (`planner.plan`'s `fallback`.)"""
    return mode == "ours"


def on_goal(
    mode: str,
    me: int,
    my_goal: tuple[float, float] | None,
    my_cost: float,
    other: int,
    other_goal: tuple[float, float],
    other_cost: float,
    other_fallback: bool,
    laser_range: float,
) -> str:
    """What robot `me` does on hearing `other`'s goal: "request" (I win: ask it to re-plan)
    or "none" (no conflict, or I lose and wait for its request)."""
    if mode == "ours" and other_fallback:
        return "none"  # difference 4: its robot had nowhere better to go
    if my_goal is None or not planner.goals_conflict(my_goal, other_goal, laser_range):
        return "none"
    # Both modes: the higher priority (planner.goal_priority: the smaller key) detects the
    # conflict and sends the request; the lower waits for it, so a conflict costs one plan.
    mine, theirs = planner.goal_priority(my_cost, me), planner.goal_priority(other_cost, other)
    return "request" if mine < theirs else "none"


def on_request(
    mode: str, my_goal: tuple[float, float] | None, winner_goal: tuple[float, float],
    laser_range: float,
) -> bool:  # fmt: skip
    """Whether a robot re-plans on a teammate's request to give up its goal."""
    if mode == "paper":
        return True  # difference 2: "forces the robot ... to choose another goal"
    # ours: only if the goal it is asked to give up is still mine and still conflicts.
    return my_goal is not None and planner.goals_conflict(my_goal, winner_goal, laser_range)


def timer_due(
    mode: str, step: int, last_plan_step: int, next_tick: int, period: int
) -> bool:  # fmt: skip
    """Whether the timer asks for a plan at `step` (difference 3). `next_tick` is the step
    of the timer's next tick on its own schedule (paper); `last_plan_step` the step of the
    last plan generation of any cause (ours)."""
    return step >= timer_due_step(mode, last_plan_step, next_tick, period)


def timer_due_step(mode: str, last_plan_step: int, next_tick: int, period: int) -> int:
    """The step at which the timer is due to ask for a plan (`timer_due`'s rule)."""
    if mode == "paper":
        return next_tick
    return last_plan_step + period
