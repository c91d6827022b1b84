"""The robot's shared structures and books (node.robot): what its five parts share under one
lock, and what they count.

Theory of operation. `RobotCore` holds, under `lock`, the shared structures of the paper's
Fig. 1 (`s`: the map, the local map, the current plan, the scans archive, and what the robot
knows of its teammates), the conditions the parts wake each other with (`tick`: the timer's
work; `caught_up`: a step's work done, for motion control's step order), the queues between
them (`requests` to the planner, `inbox` to message processing), and the books the run's
results are made of: messages sent, received and failed, CPU per part, latencies and the
lateness in emulated time (node.lateness) the fidelity verdict reads. What more than one part
does is here too: asking for a plan (`request`), sending a message to a teammate (`_send`),
and which teammates are in reach (`_reachable`). The parts are node.motion, node.planning,
node.timerpart and node.receiving; node.robot.Robot is all of them.
"""

from __future__ import annotations

import itertools
import os
import queue
import threading
from collections import Counter, defaultdict, deque
from dataclasses import dataclass, field

import numpy as np

from node import body, planner
from node.events import EventLog
from node.flood import Flooder
from node.grid import OccupancyGrid
from node.lateness import MS_BOUNDS, Lateness
from node.launch import NodeArgs
from node.messaging.arrivals import Arrivals
from node.messaging.contract import Messenger
from node.rays import Laser
from node.timing import RobotTimings

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


class RobotCore:
    """The robot's shared structures, queues and books (see the module docstring)."""

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

    def request(self, cause: str) -> None:
        with self.lock:
            if self.s.finished or self.s.plan_pending:
                return
            self.s.plan_pending = True
            self.s.plan_asked = self.s.step
            self.s.plan_asked_while_sending = self.s.planner_sending
        self.requests.put(cause)

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
        """Count step `step` for the timer (node.timerpart.TimerPart._tick)."""
        raise NotImplementedError
