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
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import os
import queue
import threading
import time
from collections import Counter, defaultdict, deque
from dataclasses import dataclass, field

import numpy as np

from common import sched
from node import body, coordination, planner, stepcore, wire
from node.events import EventLog
from node.flood import Flooder
from node.grid import FREE, OCC, OccupancyGrid
from node.lateness import MS_BOUNDS, Lateness
from node.launch import NodeArgs
from node.messaging.arrivals import Arrivals
from node.messaging.contract import Messenger
from node.rays import _BIAS, Laser
from node.timing import RobotTimings

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


FLOOD, MESSAGE = "flood", "message"  # what the inbox hands message processing
STOP = "stop"  # put in the queues by stop()
INBOX_LIMIT = 10_000  # messages waiting for processing; beyond, the inbox drops
STUCK_FRAMES = 5


@dataclass(frozen=True)
class RobotConfig:
    """What a robot process runs with; the parameters its command line sets take their
    defaults from there (node.launch.NodeArgs), the one place they are declared."""

    robot: int
    robots: int
    shape: tuple[int, int] = NodeArgs.map_size
    cell: float = NodeArgs.cell
    laser_range: float = NodeArgs.laser_range
    laser_rays: int = NodeArgs.laser_rays
    speed: float = NodeArgs.speed  # metres per step (the world's; for waypoint tolerance)
    radius: float = NodeArgs.radius
    plan_period: int = NodeArgs.plan_period
    map_period: int = NodeArgs.map_period
    full_period: int = 500  # whole local map at least this often (and on reunions)
    reach_steps: int = 30
    goal_fresh_steps: int = 40
    timing: RobotTimings = RobotTimings()  # every wall-clock duration (node.timing)
    coordination: str = NodeArgs.coordination  # how goals are agreed (node.coordination)
    planner_factor: int = 2
    phase: int = 0  # steps added to the first timer period (and map floods' offset)


@dataclass
class Teammate:
    heard: int = -(10**9)  # my step when its last map flood arrived
    goal: tuple[float, float] | None = None
    cost: float = 0.0
    goal_step: int = -(10**9)
    pos: tuple[float, float] | None = None


@dataclass
class Shared:
    grid: OccupancyGrid
    own: np.ndarray  # the local map: ternary, padded like grid.Lp (noiseless: last word wins)
    scans: list = field(default_factory=list)
    plan: planner.Plan | None = None
    wp: int = 0
    pose: tuple[float, float] = (0.0, 0.0)
    step: int = -1
    last_plan_step: int = -(10**9)
    dirty: tuple[int, int, int, int] | None = None  # local-map window changed since the last flood
    plan_pending: bool = False
    plan_asked: int = -1  # the step at which the pending plan was asked for
    plan_fresh: int | None = None  # a plan not yet applied: the step it was asked for
    # The planner was inside its goal sends when the pending plan was asked for: the plan
    # waits on the middleware (as long at any time scale), not on a processor.
    planner_sending: bool = False
    plan_asked_while_sending: bool = False
    plan_fresh_waited: bool = False  # the same, for the plan not yet applied
    finished: bool = False
    teammates: dict[int, Teammate] = field(default_factory=dict)


@dataclass
class TimerState:
    """The timer's own schedule: whether it asked for a plan yet, its next tick (coordination
    "paper"), the step of its last map flood."""

    fired: bool = False
    next_tick: int | None = None
    last_map: int = -(10**9)


@dataclass(frozen=True)
class TimerWork:
    """The timer's work at one step: a plan to ask for (due since `due_step`), a map to
    flood (`map_late` steps after its period, None for the first)."""

    plan: bool
    due_step: int | None  # None: no plan (before the first, no tick is set)
    flood: bool
    map_late: int | None


THREAD_CPU: dict[str, float] = {}  # CPU seconds of each part's thread, when it ended
PRIORITY: dict[str, str] = {}  # the scheduling each part with deadlines got (sched)


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


def _grow_box(a, b):
    if a is None:
        return b
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


class Robot:
    def __init__(
        self,
        cfg: RobotConfig,
        link: body.BodyClient,
        flooder: Flooder,
        goals: Messenger,
        events: EventLog,
    ):
        self.cfg = cfg
        self.link = link
        self.flooder = flooder
        self.goals = goals
        self.events = events
        self.laser = Laser(cfg.laser_range, cfg.laser_rays, cfg.cell)
        self.params = planner.PlannerParams(cfg.cell, cfg.planner_factor, cfg.radius)
        self.s = Shared(
            OccupancyGrid(cfg.shape, cfg.cell, pad=self.laser.pad),
            np.zeros(
                (cfg.shape[0] + 2 * self.laser.pad, cfg.shape[1] + 2 * self.laser.pad),
                dtype=np.uint8,
            ),
            teammates={j: Teammate() for j in range(1, cfg.robots + 1) if j != cfg.robot},
        )
        self.lock = threading.Lock()
        # Motion control counts the steps and evaluates the timer's rule (_tick); the timer
        # thread is woken on this condition only for a step with work: a plan to ask for or a
        # map to flood. timer_work holds those steps in order.
        self.tick = threading.Condition(self.lock)
        self.timer_work: deque[tuple[int, TimerWork | None]] = deque()
        self.timer_busy = False
        self.timer_state = TimerState()
        # Step order (see _keep_step_order): the timer and the planner say on this condition
        # that they finished a step's work; timer_seen is the last step the timer handled.
        self.caught_up = threading.Condition(self.lock)
        self.timer_seen = -1
        self.order_timeouts = 0
        self.requests: queue.Queue[str] = queue.Queue()
        self.inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(INBOX_LIMIT)
        self.wake_r, self.wake_w = os.pipe()  # stop() wakes the inbox's select through it
        self.stopping = threading.Event()
        self.sent: Counter[str] = Counter()
        self.received: Counter[str] = Counter()
        self.failed: Counter[str] = Counter()
        self.malformed = 0
        self.msg_numbers = itertools.count(1)  # "n" of the goals and requests sent (node.wire)
        self.arrivals = Arrivals()  # duplicates and late ones among those received
        self.inbox_dropped = 0
        self.stuck = 0
        self.linger = cfg.timing.flood_linger_s
        self.frames = 0
        self.skipped = 0
        self.last_full = -(10**9)
        self.full_wanted = False  # set when someone comes back into reach
        self.last_heard: dict[int, int] = {}  # origin -> my step when its last flood came
        self.plan_ms: list[float] = []
        self.busy: defaultdict[str, float] = defaultdict(float)  # thread CPU seconds per part
        # Wall seconds: world send -> frame received; frame received -> command sent.
        self.latency: dict[str, list[float]] = {"delivery": [], "answer": []}
        # Lateness in emulated time (node.lateness), for the run's fidelity verdict: a plan's
        # age in steps when applied (0: at the first frame after it was asked for), the
        # timer's lateness in steps, a frame's answer in emulated ms after the world sent it.
        self.lateness = {
            "plan_age_steps": Lateness(),
            # the same for plans asked for while the planner was blocked in a goal send: late
            # because the middleware held it, at any time scale (not in the verdict)
            "plan_age_blocked_steps": Lateness(),
            "plan_timer_steps": Lateness(),
            "map_timer_steps": Lateness(),
            "frame_answer_ms": Lateness(MS_BOUNDS),
            # emulated ms a frame was held for the timer or the planner (_keep_step_order)
            "order_wait_ms": Lateness(MS_BOUNDS),
        }
        self.threads: list[threading.Thread] = []

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
        self.events.write(
            "summary",
            self.s.step,
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
        )

    def _motion(self) -> None:
        # A robot's motion control answers every frame within its step while, on this shared
        # machine, other robots' merges and inboxes compete for the CPU: on hardware a control
        # loop has its own. So this thread runs at real-time priority 1, one below the world's
        # clock (it works a fraction of a millisecond per frame, then blocks on the next one),
        # else at nice -5; without root, at the default. So do the planner and the timer.
        PRIORITY["motion"] = sched.raise_priority(*sched.DEADLINE_PRIORITY)
        started = False
        last_xy = None
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
        tol = 1e-3 + 0.01 * self.cfg.speed
        while s.wp < len(path) and math.dist(s.pose, path[s.wp]) <= tol:
            s.wp += 1
        self.stuck = 0 if moved or s.wp >= len(path) else self.stuck + 1
        if self.stuck >= STUCK_FRAMES:
            self.stuck = 0
            s.wp += 1
            log.info("stuck at %s: skipping a waypoint", tuple(round(v, 2) for v in s.pose))
        return path[s.wp] if s.wp < len(path) else None

    def request(self, cause: str) -> None:
        with self.lock:
            if self.s.finished or self.s.plan_pending:
                return
            self.s.plan_pending = True
            self.s.plan_asked = self.s.step
            self.s.plan_asked_while_sending = self.s.planner_sending
        self.requests.put(cause)

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
                self.link.send(body.done(step))
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

    def _send(self, j: int, kind: str, data: bytes, step: int) -> None:
        if self.goals.send(j, data):
            self.sent[kind] += 1
            self.events.write("send", step, kind=kind, to=j)
        else:
            self.failed[kind] += 1
            self.events.write("send_failed", step, kind=kind, to=j)

    def _reachable(self) -> list[int]:
        """Teammates whose map floods arrived recently (lock held)."""
        s = self.s
        return [j for j, tm in s.teammates.items() if s.step - tm.heard <= self.cfg.reach_steps]

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
