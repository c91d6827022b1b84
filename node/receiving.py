"""The robot's inbox and message processing, two of its five parts (node.robot).

Theory of operation. The inbox thread waits on the flooder's and the messenger's descriptors
(and stop()'s pipe), lingers a moment so that one wake-up drains a burst of relayed copies,
and hands each message to message processing through a bounded queue (full: dropped and
counted, never blocking). Message processing merges teammates' maps (a flood also marks its
origin as in reach, and asks for a whole map next when it was out of reach a while), records
their goals, and settles goal conflicts by node.coordination's rules: the winner asks the
loser to re-plan, and the loser re-plans on that request.
"""

from __future__ import annotations

import logging
import queue
import time

from node import coordination, wire
from node.robotcore import FLOOD, MESSAGE, STOP, RobotCore

# The robot's log lines name node.robot whichever part writes them (docs/robot-contract.md;
# the C++ robot writes the same name).
log = logging.getLogger("node.robot")


class Receiving(RobotCore):
    """The inbox and message processing parts (see the module docstring)."""

    def _inbox(self) -> None:
        import select

        flood_fd, goals_fd = self.flooder.fileno(), self.goals.fileno()  # each once: pynng
        fds = [flood_fd, goals_fd, self.wake_r]  # pynng reads its descriptor as a socket
        # option every time; wake_r is stop()'s
        while not self.stopping.is_set():
            ready, _, _ = select.select(fds, [], [], 0.5)
            if not ready:
                continue
            # Copies of a flood arrive in bursts (neighbours relay it): linger a moment so
            # that one wake-up drains the burst instead of one per datagram.
            time.sleep(self.linger)
            ready, _, _ = select.select(fds, [], [], 0)
            batch = []
            if flood_fd in ready:
                batch += [(FLOOD, data) for data in self.flooder.receive_raw()]
            if goals_fd in ready:
                batch += [(MESSAGE, data) for data in self.goals.receive()]
            for item in batch:
                try:
                    self.inbox.put_nowait(item)
                except queue.Full:
                    self.inbox_dropped += 1  # processing is stuck: drop, never block

    def _processing(self) -> None:
        while not self.stopping.is_set():
            try:
                kind, data = self.inbox.get(timeout=0.5)
            except queue.Empty:
                continue
            if kind is STOP:
                break
            try:
                if kind is FLOOD:
                    self._on_flood(data)
                else:
                    self._on_message(data)
            except ValueError as e:
                self.malformed += 1
                log.warning("dropped a malformed message: %s", e)

    def _on_flood(self, data: bytes) -> None:
        t_cpu = time.thread_time()
        h, payload = wire.unpack_flood(data)
        if h.kind not in (wire.KIND_MAP, wire.KIND_BEACON) or not (
            1 <= h.origin <= self.cfg.robots + 1
        ):
            raise ValueError(f"unexpected flood kind {h.kind} from {h.origin}")
        # Someone back in reach after a while missed our deltas: send the whole map next.
        last = self.last_heard.get(h.origin)
        with self.lock:
            now = self.s.step
        if last is None or now - last > self.cfg.reach_steps:
            self.full_wanted = True
        self.last_heard[h.origin] = now
        if h.kind == wire.KIND_BEACON:
            wire.unpack_beacon(payload)
            self.received["beacon"] += 1
            self.events.write("recv", now, kind="beacon", frm=h.origin, seq=h.seq, sent=h.step,
                              t=round(time.monotonic(), 4))  # fmt: skip
            return
        m = wire.unpack_map(payload, self.cfg.shape)
        with self.lock:
            s = self.s
            learnt = s.grid.merge_ternary(m.cells, m.r0, m.c0)
            tm = s.teammates.get(h.origin)
            if tm is not None:
                tm.heard = s.step
                tm.pos = (m.x, m.y)
            step = s.step
        self.received["map"] += 1
        self.events.write(
            "recv", step, kind="map", frm=h.origin, seq=h.seq, sent=h.step, ttl=h.ttl,
            learnt=learnt, t=round(time.monotonic(), 4),
        )  # fmt: skip
        self.busy["merge"] += time.thread_time() - t_cpu

    def _on_message(self, data: bytes) -> None:
        cfg = self.cfg
        m = wire.parse_msg(data, cfg.robots)
        j = m["from"]
        if j == cfg.robot:
            raise ValueError("a message claiming to be from myself")
        with self.lock:
            s = self.s
            step = s.step
            tm = s.teammates[j]
            tm.goal, tm.goal_step = m["goal"], step
            if m["k"] == "goal":
                tm.cost = m["cost"]
            mine = s.plan.goal if (s.plan and not s.finished) else None
            my_cost = s.plan.cost if s.plan else 0.0
        self.received[m["k"]] += 1
        self.arrivals.note(j, m["n"], m["step"], step)
        self.events.write("recv", step, kind=m["k"], frm=j, sent=m["step"],
                          t=round(time.monotonic(), 4))  # fmt: skip
        mode = cfg.coordination
        if m["k"] == "goal":
            decision = coordination.on_goal(mode, cfg.robot, mine, my_cost, j, m["goal"],
                                            m["cost"], m["fallback"], cfg.laser_range)  # fmt: skip
            if decision == "request" and mine is not None:  # (only with a goal of mine)
                data = wire.replan_msg(cfg.robot, step, mine, next(self.msg_numbers))
                self._send(j, "replan", data, step)
        elif m["k"] == "replan":
            if coordination.on_request(mode, mine, m["goal"], cfg.laser_range):
                self.request("request")
            else:
                self.events.write("stale_request", step, frm=j)
