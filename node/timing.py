"""A robot's timings: every wall-clock duration the robot process uses, derived in one place.

Theory of operation. The world's clock ticks once per step, STEP_S of emulated time (the
paper's motion update, 100 ms). `--time-scale K` runs emulated time K times faster than the
wall clock, so every duration that belongs to emulated time is divided by K, here and only
here: the robot's parts take their durations from a `RobotTimings`, never from the time
scale. Durations that are the machine's, not the emulated world's (a thread's switch
interval, a poll's timeout while nothing happens), are not scaled and do not live here.
The world's side of the same clock (testbed.run.stepclock, and the run's config and fidelity
verdict) imports STEP_S from this module.
"""

from __future__ import annotations

from dataclasses import dataclass

from common import timescale

STEP_S = 0.1  # emulated seconds per step: the one definition of the project
NEIGHBOUR_HOLD_MAP_PERIODS = 1.5  # a flood neighbour is forgotten after this many map periods
GOAL_SEND_TIMEOUT_EMULATED_MS = 50  # half a step: a goal not sent by then is given up
GOAL_SEND_TIMEOUT_MIN_MS = 2  # nng's send timeout in whole ms; below 2 it gives up at once
# nng redials a teammate it lost after reconnect_time_min, doubling up to reconnect_time_max:
# how long a robot goes without a connection to a teammate it can reach again.
GOAL_RECONNECT_MIN_EMULATED_MS = 50
GOAL_RECONNECT_MAX_EMULATED_MS = 500
NNG_MIN_MS = 1  # nng's durations are whole ms
FLOOD_LINGER_MAX_S = 0.001  # wait at most this long for more copies of a flood burst
FLOOD_LINGER_EMULATED_S = 0.01  # ... and at most a tenth of a step
STEP_ORDER_WAIT_STEPS = 0.75  # a frame waits at most this much of a step for the robot's threads


@dataclass(frozen=True)
class RobotTimings:
    time_scale: float = 1.0
    map_period: int = 10  # steps between a robot's map floods

    def __post_init__(self) -> None:
        if timescale.refusal(self.time_scale):
            raise ValueError(timescale.refusal(self.time_scale))
        if self.map_period < 1:
            raise ValueError(f"map_period must be >= 1, not {self.map_period}")

    @property
    def step_order_wait_s(self) -> float:
        """Wall seconds after the world sent a frame until which motion control may hold it
        for the timer and the planner to finish the previous step's work (node.robot): three
        quarters of a step, leaving the rest for the answer to make the world's deadline one
        step after the send."""
        return STEP_ORDER_WAIT_STEPS * STEP_S / self.time_scale

    @property
    def neighbour_hold_s(self) -> float:
        """Wall seconds after which a flood neighbour not heard from is forgotten (node.flood):
        1.5 map periods, so one lost flood does not drop a neighbour."""
        return NEIGHBOUR_HOLD_MAP_PERIODS * self.map_period * STEP_S / self.time_scale

    @property
    def goal_send_timeout_ms(self) -> int:
        """How long sending a goal to an unreachable teammate may block (node.messaging)."""
        return max(GOAL_SEND_TIMEOUT_MIN_MS, round(GOAL_SEND_TIMEOUT_EMULATED_MS / self.time_scale))

    @property
    def goal_reconnect_min_ms(self) -> int:
        """nng's first wait before redialling a teammate (node.messaging), in wall ms."""
        return max(NNG_MIN_MS, round(GOAL_RECONNECT_MIN_EMULATED_MS / self.time_scale))

    @property
    def goal_reconnect_max_ms(self) -> int:
        """nng's longest wait between redials (its backoff's ceiling), in wall ms."""
        return max(NNG_MIN_MS, round(GOAL_RECONNECT_MAX_EMULATED_MS / self.time_scale))

    @property
    def flood_linger_s(self) -> float:
        """How long the inbox waits for more copies of a flood burst before handing it on."""
        return min(FLOOD_LINGER_MAX_S, FLOOD_LINGER_EMULATED_S / self.time_scale)
