"""The timer, one of the robot's five parts (node.robot): plans asked for and local maps
flooded on time.

Theory of operation. Motion control counts each step (`_tick`) and evaluates the timer's rule
there (`_timer_rule`: a plan due when the coordination's period passed, a map flood every
`map_period` steps, both offset by the robot's phase in the first period); the timer thread
is woken only for a step with work, handles those steps in order, records how late it acted
(the fidelity verdict reads it) and says on `caught_up` which step it finished. A map flood
(`_share_map`) sends the local map's changed window, or the whole of it every `full_period`
steps and when a teammate comes back into reach.
"""

from __future__ import annotations

import time

from common import sched
from node import coordination, wire
from node.robotcore import PRIORITY, RobotCore, TimerWork


class TimerPart(RobotCore):
    """The timer part (see the module docstring)."""

    def _tick(self, step: int) -> None:
        """Count step `step` for the timer, once motion control has answered its frame.

        The timer's rule (a plan due, a map flood due) is evaluated here, on motion
        control's thread, and the timer thread is woken only for a step with work: most
        steps have none, and a thread woken every step to find nothing to do costs more than
        the rule. A step without work counts as handled at once, unless earlier work is
        still queued (the timer handles steps in order)."""
        with self.lock:
            work = self._timer_rule(step)
            if work is None and not self.timer_busy and not self.timer_work:
                self.timer_seen = step
                return
            self.timer_work.append((step, work))
            self.tick.notify_all()

    def _timer_rule(self, step: int) -> TimerWork | None:
        """What the timer does at `step` (lock held): ask for a plan when its period passed
        (node.coordination), flood the local map every `map_period` steps."""
        cfg, s, st = self.cfg, self.s, self.timer_state
        # The first timer period is longer by the robot's phase: robots booted in the same
        # step would otherwise plan (and flood) in lock-step forever.
        period = cfg.plan_period + (cfg.phase if not st.fired else 0)
        started = s.last_plan_step >= 0  # the first plan is motion control's
        if started and st.next_tick is None:
            st.next_tick = s.last_plan_step + period
        due_step = (
            None  # not started (motion control makes the first plan): nothing is due
            if st.next_tick is None
            else coordination.timer_due_step(
                cfg.coordination, s.last_plan_step, st.next_tick, period
            )
        )
        plan = step >= 0 and started and not s.finished and not s.plan_pending
        plan = plan and due_step is not None and step >= due_step
        while st.next_tick is not None and st.next_tick <= step:
            st.next_tick += cfg.plan_period
        if plan:
            st.fired = True
        flood = step >= 0 and step - st.last_map >= cfg.map_period
        flood = flood and step >= cfg.phase % cfg.map_period
        map_late = None
        if flood:
            if st.last_map >= 0:
                map_late = step - st.last_map - cfg.map_period
            st.last_map = step
        if not plan and not flood:
            return None
        return TimerWork(plan, due_step, flood, map_late)

    def _timer(self) -> None:
        """The timer part: asks for the plans and floods the maps that _tick found due, in
        step order; its lateness (the step it acted at against the step the work was due) is
        what the fidelity verdict reads, so it runs at the planner's priority."""
        PRIORITY["timer"] = sched.raise_priority(*sched.DEADLINE_PRIORITY)
        while not self.stopping.is_set():
            with self.lock:
                while not self.timer_work and not self.stopping.is_set():
                    self.tick.wait(0.5)
                if not self.timer_work:
                    continue
                step, work = self.timer_work.popleft()
                self.timer_busy = True
                now = self.s.step
            if work is not None and work.plan and work.due_step is not None:
                self.lateness["plan_timer_steps"].add(now - work.due_step)
                self.request("timer")
            if work is not None and work.flood:
                if work.map_late is not None:
                    self.lateness["map_timer_steps"].add(work.map_late + now - step)
                self._share_map(step)
            with self.lock:
                self.timer_busy = False
                self.timer_seen = max(self.timer_seen, step)
                self.caught_up.notify_all()

    def _share_map(self, step: int) -> None:
        t_cpu = time.thread_time()
        p = self.laser.pad
        h, w = self.cfg.shape
        full = self.full_wanted or step - self.last_full >= self.cfg.full_period
        self.full_wanted = False
        with self.lock:
            s = self.s
            if full:
                r0, c0, r1, c1 = 0, 0, h, w
            elif s.dirty is None:
                r0 = c0 = r1 = c1 = 0
            else:
                r0, c0, r1, c1 = s.dirty
            s.dirty = None
            t = s.own[p + r0 : p + r1, p + c0 : p + c1].copy()
            x, y = s.pose
        if full:
            self.last_full = step
        payload = wire.pack_map(x, y, t, r0, c0)
        seq = self.flooder.originate(wire.KIND_MAP, step, payload)
        self.sent["map"] += 1
        self.events.write("send", step, kind="map", seq=seq, bytes=len(payload), full=full)
        self.busy["share"] += time.thread_time() - t_cpu
