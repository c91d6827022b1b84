"""Motion control, the robot's main thread (node.robot): a frame from the body link in, a
motion command out.

Theory of operation. For every frame (step, pose, scan) the body link delivers, motion control
first keeps the step order (`_keep_step_order`: the frame waits, at most three quarters of a
step, until the timer and the planner finished the previous step's work), puts the scan into
the map and the local map (in compiled code when node.stepcore has it, the same cells), keeps
it in the scans archive, steers along the current plan (`_follow`: the next waypoint, skipping
one the body refuses to reach) and answers the frame with a motion command; a frame with a
newer one already waiting is skipped. It then counts the step for the timer (`_tick`) and
records its latencies and lateness.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from common import sched
from node import body, stepcore
from node.grid import FREE, OCC
from node.rays import _BIAS
from node.robotcore import PRIORITY, STUCK_FRAMES, RobotCore

# The robot's log lines name node.robot whichever part writes them (docs/robot-contract.md;
# the C++ robot writes the same name).
log = logging.getLogger("node.robot")

# A waypoint is reached within WAYPOINT_TOL_M plus this share of a step's move.
WAYPOINT_TOL_M = 1e-3
WAYPOINT_TOL_SPEEDS = 0.01


def _grow_box(a, b):
    if a is None:
        return b
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


class MotionControl(RobotCore):
    """The motion control part: frames in, commands out (see the module docstring)."""

    def _motion(self) -> None:
        # A robot's motion control answers every frame within its step while, on this shared
        # machine, other robots' merges and inboxes compete for the CPU: on hardware a control
        # loop has its own. So this thread runs at real-time priority 1, one below the world's
        # clock (it works a fraction of a millisecond per frame, then blocks on the next one),
        # else at nice -5; without root, at the default. So do the planner and the timer.
        PRIORITY["motion"] = sched.raise_priority(*sched.DEADLINE_PRIORITY)
        started = False
        last_xy = None
        # A frame off the map or of another ray count is refused as malformed (node.body).
        h, w = self.cfg.shape
        self.link.expect(w * self.cfg.cell, h * self.cfg.cell, self.laser.n_rays)
        while not self.stopping.is_set():
            try:
                msg = self.link.recv(timeout=0.5)
            except ValueError as e:
                self.malformed += 1
                log.warning("dropped a malformed body message: %s", e)
                continue
            if msg is None:
                continue
            if msg[0] == "end":
                log.info("the world ended the run at step %d", self.s.step)
                return
            if msg[0] != "frame":
                continue
            f: body.Frame = msg[1]
            self.frames += 1
            self._keep_step_order(f)
            t_frame = time.thread_time()
            t_in = time.monotonic()
            # A robot standing still sees nothing new (the world is static): skip the update.
            moved = (f.x, f.y) != last_xy
            last_xy = (f.x, f.y)
            if moved and not stepcore.NATIVE:
                r0, c0, free, occ = self.laser.scan_window(f.x, f.y, f.ranges)
            behind = self.link.pending()
            with self.lock:
                s = self.s
                if moved:
                    if stepcore.NATIVE:
                        self._put_scan_native(f)
                    else:
                        self._put_scan(f, r0, c0, free, occ)
                    s.dirty = _grow_box(s.dirty, self._footprint(f.x, f.y))
                s.pose = (f.x, f.y)
                s.step = f.step
                s.scans.append((f.step, f.x, f.y, f.ranges))
                target = None if behind else self._follow(moved)
                if not behind and s.plan_fresh is not None:
                    self._plan_applied(f.step)
            if behind:
                self.skipped += 1  # a newer frame is waiting: act on that one
            else:
                self.link.send(body.cmd(f.step, target))
            self.busy["motion"] += time.thread_time() - t_frame
            t_out = time.monotonic()
            if f.sent > 0:
                self.latency["delivery"].append(t_in - f.sent)
                if not behind:
                    lag_ms = (t_out - f.sent) * 1000 * self.cfg.timing.time_scale
                    self.lateness["frame_answer_ms"].add(lag_ms)
            self.latency["answer"].append(t_out - t_in)
            self._tick(f.step)
            if not started:
                started = True
                self.request("start")

    def _plan_applied(self, step: int) -> None:
        """The fresh plan is applied at frame `step` (lock held): its age, in the verdict's
        measure unless the middleware held the planner when the plan was asked for."""
        s = self.s
        age = "plan_age_blocked_steps" if s.plan_fresh_waited else "plan_age_steps"
        assert s.plan_fresh is not None  # the caller checks
        self.lateness[age].add(step - s.plan_fresh - 1)
        s.plan_fresh = None

    def _keep_step_order(self, f: body.Frame) -> None:
        """Hold frame `f` until the robot's other threads finished the previous step's work.

        At time scale 1 a robot's timer has handled step s, and the plan asked for at step s
        is installed, long before frame s + 1 arrives (a plan takes 1-2 ms of a 100 ms step).
        Dilated, a step lasts a few wall milliseconds and those threads may not have run yet;
        acting on frame s + 1 without them applies the plan a step late, from another pose,
        and the robot's path changes (docs/architecture.md, "Time dilation and fidelity").
        So motion control waits for them, but only until three quarters of a step after the
        world sent the frame (RobotTimings.step_order_wait_s), so that its answer can still
        make the world's deadline: past that it goes on as it would have, and the plan or the
        timer counts as late, which the fidelity verdict sees. Each wait is recorded
        (`order_wait_ms`, emulated ms)."""
        s = self.s

        def caught_up() -> bool:
            if self.stopping.is_set() or s.step < 0:
                return True
            # A plan the planner cannot start while its send waits on the middleware would
            # not come sooner at time scale 1 either: no point holding the frame for it.
            waiting = s.plan_pending and s.plan_asked < f.step and not s.planner_sending
            return self.timer_seen >= s.step and not waiting

        with self.lock:
            if caught_up():
                return
            t0 = time.monotonic()
            until = (f.sent if f.sent > 0 else t0) + self.cfg.timing.step_order_wait_s
            ok = self.caught_up.wait_for(caught_up, timeout=max(0.0, until - t0))
        self.lateness["order_wait_ms"].add(
            (time.monotonic() - t0) * 1000 * self.cfg.timing.time_scale
        )
        if not ok:
            self.order_timeouts += 1

    def _put_scan_native(self, f: body.Frame) -> None:
        """`_put_scan` in compiled code (node.stepcore), the same cells; numpy at the edge."""
        s = self.s
        if not stepcore.scan_into(self.laser, f.x, f.y, f.ranges, s.grid.Lp, s.own,
                                  s.grid.params, _BIAS):  # fmt: skip
            self._put_scan(f, *self.laser.scan_window(f.x, f.y, f.ranges))

    def _put_scan(self, f: body.Frame, r0: int, c0: int, free, occ) -> None:
        """Put one scan (as Laser.scan_window gives it) into the map and the local map."""
        s = self.s
        h, w = free.shape
        own = s.own[r0 : r0 + h, c0 : c0 + w]
        if own.shape != free.shape or r0 < 0 or c0 < 0:
            # At the very edge of the map the window sticks out: the per-cell form.
            free, occ = self.laser.scan_cells(f.x, f.y, f.ranges, s.grid.Lp.shape[1])
            s.grid.update_cells(free, occ)
            flat = s.own.reshape(-1)
            flat[free] = FREE
            flat[occ] = OCC
            return
        s.grid.update_window(r0, c0, free, occ)
        own[free] = FREE
        own[np.divmod(occ, w)] = OCC

    def _footprint(self, x: float, y: float) -> tuple[int, int, int, int]:
        """The map window (r0, c0, r1, c1) a scan from (x, y) can touch."""
        c, rng = self.cfg.cell, self.cfg.laser_range
        h, w = self.cfg.shape
        return (
            max(0, int((y - rng) / c) - 1), max(0, int((x - rng) / c) - 1),
            min(h, int((y + rng) / c) + 2), min(w, int((x + rng) / c) + 2),
        )  # fmt: skip

    def _follow(self, moved: bool) -> tuple[float, float] | None:
        """The next waypoint of the current plan (lock held), None when there is none.

        A robot that has not moved for STUCK_FRAMES frames while driving (its body refused the
        move: a wall closer than the map showed) gives up that waypoint for the next one."""
        s = self.s
        if s.finished or s.plan is None:
            return None
        path = s.plan.path
        tol = WAYPOINT_TOL_M + WAYPOINT_TOL_SPEEDS * self.cfg.speed
        while s.wp < len(path) and math.dist(s.pose, path[s.wp]) <= tol:
            s.wp += 1
        self.stuck = 0 if moved or s.wp >= len(path) else self.stuck + 1
        if self.stuck >= STUCK_FRAMES:
            self.stuck = 0
            s.wp += 1
            log.info("stuck at %s: skipping a waypoint", tuple(round(v, 2) for v in s.pose))
        return path[s.wp] if s.wp < len(path) else None
