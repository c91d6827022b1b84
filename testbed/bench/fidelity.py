"""Benchmark of the fidelity guard: what keeping emulated-time order and recording lateness
cost a robot per step, against the shortest step the shipped sweep files use.

Per robot-step the guard adds, on motion control's thread: one check that the timer and the
planner finished the previous step's work (node.motion `_keep_step_order`: a lock and two
comparisons, when nothing is owed, which is almost always) and one or two `Lateness.add`
(the frame's answer lag; a plan's age when one is applied); the timer thread adds one more
(the map or plan timer) and a notify. Timed here on a real Robot object, REPEATS rounds of
CALLS calls each, the median round's cost per call; the sum is set against a step at the
highest time scale used (paper.toml: 30 for one robot, 3.33 ms of wall time) and, for ten
robots (6: 16.7 ms), the whole team's cost against the step (CPU on any core).
"""

import time
from typing import Any

import numpy as np

from node import body
from node.lateness import MS_BOUNDS, Lateness
from node.robot import Robot, RobotConfig
from node.timing import STEP_S, RobotTimings
from testbed.bench.common import median, write

CALLS = 20000
REPEATS = 7
SCALES = {1: 30.0, 10: 6.0}  # team size -> paper.toml's time scale


def _per_call_us(fn, calls: int = CALLS) -> float:
    rounds = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        rounds.append((time.perf_counter() - t0) / calls)
    return 1e6 * median(rounds)


def run() -> None:
    robot = Robot(RobotConfig(robot=1, robots=1, shape=(40, 40), timing=RobotTimings(30.0)),
                  # the calls measured use none of them
                  link=None, flooder=None, goals=None, events=None)  # type: ignore[arg-type]  # fmt: skip
    robot.s.step, robot.timer_seen = 10, 10
    frame = body.Frame(11, 1.0, 1.0, 0.0, np.empty(0, np.float32), time.monotonic())
    check_us = _per_call_us(lambda: robot._keep_step_order(frame))
    lateness = Lateness(MS_BOUNDS)
    add_us = _per_call_us(lambda: lateness.add(3.2))

    def timer_mark():  # what the timer thread does after each step (node.timerpart's _timer)
        with robot.lock:
            robot.timer_seen = 10
            robot.caught_up.notify_all()

    mark_us = _per_call_us(timer_mark)
    per_step_us = check_us + 3 * add_us + mark_us
    result: dict[str, Any] = {
        "calls": CALLS,
        "repeats": REPEATS,
        "order_check_us": round(check_us, 3),
        "lateness_add_us": round(add_us, 3),
        "timer_mark_us": round(mark_us, 3),
        "per_robot_step_us": round(per_step_us, 3),
    }
    for robots, scale in SCALES.items():
        step_us = 1e6 * STEP_S / scale
        result[f"robots_{robots}_at_{scale:g}"] = {
            "step_us": round(step_us, 1),
            "share_of_step": round(robots * per_step_us / step_us, 5),
        }
    write("fidelity", result)
    one, ten = result["robots_1_at_30"], result["robots_10_at_6"]
    print(f"fidelity: the guard costs {per_step_us:.2f} us per robot-step: "
          f"{one['share_of_step']:.3%} of a step for one robot at 30, "
          f"{ten['share_of_step']:.3%} for ten at 6")  # fmt: skip
