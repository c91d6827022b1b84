"""Path planning, one of the robot's five parts (node.robot).

Theory of operation. The planner waits for a request (`request`: motion control's first, the
timer's, a teammate's re-plan request), plans on a snapshot of the map taken under the lock
(node.planner: the nearest reachable frontier not within laser range of a reachable
teammate's fresh goal), installs the plan as the current one and announces its goal to the
reachable teammates. A plan that finds no frontier left finishes the robot, and its body is
told so; a blocked one announces nothing and waits (node.coordination). While it sends, the
planner says so (`planner_sending`), so that motion control does not hold a frame for a plan
the middleware is holding up.
"""

from __future__ import annotations

import logging
import os
import queue
import time

from common import sched
from node import body, coordination, planner, wire
from node.robotcore import PRIORITY, STOP, RobotCore

# The robot's log lines name node.robot whichever part writes them (docs/robot-contract.md;
# the C++ robot writes the same name).
log = logging.getLogger("node.robot")


class Planning(RobotCore):
    """The path planning part (see the module docstring)."""

    def _planning(self) -> None:
        cfg = self.cfg
        # A test hook: wall seconds the planner waits before installing each plan, so that
        # plans arrive late in emulated time (tests of the fidelity verdict, testbed.run.fidelity).
        delay = float(os.environ.get("NODE_PLAN_DELAY_MS", "0") or 0) / 1000
        # A plan is due by the next frame (the fidelity verdict counts late ones): real-time
        # priority like motion control's, above the merges and inboxes of every robot.
        PRIORITY["planner"] = sched.raise_priority(*sched.DEADLINE_PRIORITY)
        while not self.stopping.is_set():
            try:
                cause = self.requests.get(timeout=0.5)
            except queue.Empty:
                continue
            if cause is STOP:
                break
            with self.lock:
                s = self.s
                t = s.grid.ternary()
                pose, step = s.pose, s.step
                reach = self._reachable()
                goals = [
                    tm.goal
                    for tm in (s.teammates[j] for j in reach)
                    if tm.goal is not None and step - tm.goal_step <= cfg.goal_fresh_steps
                ]
            t0 = time.perf_counter()
            p = planner.plan(t, pose, goals, cfg.laser_range, self.params,
                             fallback=coordination.allows_fallback(cfg.coordination))  # fmt: skip
            ms = (time.perf_counter() - t0) * 1000
            self.busy["plan"] += ms / 1000
            self.plan_ms.append(ms)
            if delay > 0:
                time.sleep(delay)
            if p.status == "done":  # before the plan is installed: motion control answers no
                self.link.send(body.done(step))  # later frame before the world has it
            with self.lock:
                s.plan, s.wp = p, 0
                s.plan_fresh = s.plan_asked
                s.plan_fresh_waited = s.plan_asked_while_sending
                s.last_plan_step = step
                s.plan_pending = False
                if p.status == "done":
                    s.finished = True
                self.caught_up.notify_all()
            goal = [round(v, 3) for v in p.goal] if p.goal else None
            self.events.write(
                "plan", step, cause=cause, status=p.status, goal=goal, cost=round(p.cost, 3),
                ms=round(ms, 2), avoided=len(goals),
            )  # fmt: skip
            log.info(
                "plan at step %d (%s): %s goal %s cost %.2f m, %.1f ms",
                step, cause, p.status, goal, p.cost, ms,
            )  # fmt: skip
            if p.status == "done":
                self.events.write("finish", step)
                log.info("finished at step %d: no reachable frontier left", step)
                continue
            if p.status == "blocked":
                continue  # no goal selected, nothing to announce: it waits (coordination)
            assert p.goal is not None  # every other status has one
            data = wire.goal_msg(cfg.robot, step, p.goal, p.cost, p.status == "fallback",
                                 next(self.msg_numbers))  # fmt: skip
            with self.lock:
                s.planner_sending = True
                self.caught_up.notify_all()  # a frame held for a plan need not wait for it
            try:
                for j in reach:
                    self._send(j, "goal", data, step)
            finally:
                with self.lock:
                    s.planner_sending = False
                    self.caught_up.notify_all()
