"""The robot role: the paper's five concurrent parts around three shared structures.

Theory of operation (the paper's Fig. 1). Shared, under one lock: the *map* (a log-odds grid
merged from the robot's own scans and teammates' local maps; the robot's own observations are
also kept apart, as the local map it shares), the *current plan*, and the *scans archive*.
Five threads:

- motion control (the main thread): reads a frame (step, pose, scan) from the body link,
  puts the scan into the maps and the archive, steers along the current plan and answers the
  frame with a motion command;
- path planning: waits for a request, plans on a snapshot of the map (node.planner: the
  nearest reachable frontier not within laser range of a reachable teammate's goal), makes it
  the current plan and announces the goal to reachable teammates over the run's middleware
  (node.messaging: nanomsg unless --middleware says otherwise); with no
  reachable frontier left the robot has finished and tells its body so;
- timer: asks for a plan when 20 steps passed since the last one, and floods the robot's
  local map every `map_period` steps (motion control counts the steps and evaluates that
  rule as it answers each frame, and wakes the timer only for a step with work: `_tick`);
- message processing: merges maps, records teammates' goals, settles goal conflicts (the
  winner by priority asks the loser to re-plan; the loser re-plans on that request);
- inbox: receives from the network (UDP floods, relayed on the way; the messenger) and hands
  each new message to message processing through a bounded queue (full: dropped, counted).

With `--maps pubsub` the "flooder" the robot is given is its middleware's map topic
(node.messaging.maps): the same interface, maps published and received end to end instead of
flooded, the same messages into the same inbox; nothing below tells the two apart.

A teammate is *reachable* while its map floods keep arriving (within `reach_steps`): a flood
only arrives over a path that exists. Every plan, send and receipt goes to the event log with
the step, which is what the run's results and checks are built from.

The parts, each a class of its own that `Robot` puts together: motion control (node.motion),
path planning (node.planning), the timer (node.timerpart), the inbox and message processing
(node.receiving), all on the shared structures, queues and books of node.robotcore. This
module starts and stops them and writes the robot's summary.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import threading
import time

import numpy as np

from node import summary
from node.motion import MotionControl
from node.planning import Planning
from node.receiving import Receiving
from node.robotcore import PRIORITY, STOP, THREAD_CPU
from node.robotcore import RobotConfig as RobotConfig
from node.timerpart import TimerPart

log = logging.getLogger(__name__)


def peak_rss_mb() -> float | None:
    """This process's peak resident memory (VmHWM), in MiB.

    Not getrusage's ru_maxrss: Linux carries that across fork and exec, so a robot started
    from a large parent would report the parent's peak as its own."""
    try:
        with open("/proc/self/status") as f:
            kb = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
    except (OSError, StopIteration, ValueError):
        return None
    return round(kb / 1024, 1)


def _fatal_on_error(fn, name: str):
    """A part that dies takes the robot with it (exit status 3): a robot without its planner
    or inbox would idle until the step cap, while a dead process is recorded as a crash."""

    def guarded():
        prof_dir = os.environ.get("NODE_PROFILE_DIR")  # development aid: cProfile per part
        prof = None
        if prof_dir:
            import cProfile

            prof = cProfile.Profile(time.thread_time)  # CPU, not waiting
            prof.enable()
        try:
            fn()
            THREAD_CPU[name] = time.thread_time()
        except Exception:
            log.exception("the %s part failed; the robot stops", name)
            logging.shutdown()
            os._exit(3)
        finally:
            if prof is not None:
                prof.disable()
                prof.dump_stats(os.path.join(prof_dir, f"{os.getpid()}.{name}.prof"))

    return guarded


class Robot(MotionControl, Planning, TimerPart, Receiving):
    """One robot: its five parts (node.motion, node.planning, node.timerpart,
    node.receiving) around the shared structures of node.robotcore."""

    # -- the five parts ---------------------------------------------------------------------

    def run(self) -> None:
        """Start the other four parts and run motion control until the run ends."""
        for name, fn in (
            ("planner", self._planning),
            ("timer", self._timer),
            ("processing", self._processing),
            ("inbox", self._inbox),
        ):
            t = threading.Thread(target=_fatal_on_error(fn, name), name=name, daemon=True)
            t.start()
            self.threads.append(t)
        for j in self.s.teammates:
            self.goals.connect(j)
        self.laser.prepare_tables()  # none is built mid-run (done already when forked warm)
        self.link.ready()
        try:
            _fatal_on_error(self._motion, "motion")()
        finally:
            self.stop()

    def stop(self) -> None:
        self.stopping.set()
        # Wake every part now rather than at its next 0.5 s timeout.
        with self.tick:
            self.tick.notify_all()
        self.requests.put(STOP)
        with contextlib.suppress(queue.Full):
            self.inbox.put_nowait((STOP, b""))
        with contextlib.suppress(OSError):
            os.write(self.wake_w, b"x")
        for t in self.threads:
            t.join(timeout=2.0)
        parts = sum(THREAD_CPU.values())
        thread_cpu = {k: round(v, 3) for k, v in THREAD_CPU.items()}
        thread_cpu["other"] = round(time.process_time() - parts, 3)  # nng's threads, start-up
        fields = summary.ordered(
            sent=dict(self.sent),
            received=dict(self.received),
            send_failed=dict(self.failed),
            malformed=self.malformed + self.flooder.counts["malformed"],
            flood=dict(self.flooder.counts),
            maps=self.flooder.stats.as_dict(),
            frames=self.frames,
            frames_skipped=self.skipped,
            order_timeouts=self.order_timeouts,
            inbox_dropped=self.inbox_dropped,
            plan_ms_median=float(np.median(self.plan_ms)) if self.plan_ms else None,
            cpu_s=round(time.process_time(), 3),
            max_rss_mb=peak_rss_mb(),
            busy_s={k: round(v, 3) for k, v in self.busy.items()},
            thread_cpu_s=thread_cpu,
            priority=dict(PRIORITY),
            lateness={k: v.as_dict() for k, v in self.lateness.items()},
            latency_ms={
                k: {
                    q: round(float(np.percentile(v, p)) * 1000, 2)
                    for q, p in (("p50", 50), ("p90", 90), ("p99", 99), ("max", 100))
                }
                for k, v in self.latency.items()
                if v
            },
            finished=self.s.finished,
            middleware=self.goals.name,
            messenger=self.goals.stats.as_dict(),
            arrivals=self.arrivals.as_dict(),
            events_failed=self.events.failed,
            robot_impl="python",
        )
        self.events.write("summary", self.s.step, **fields)
