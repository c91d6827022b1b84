"""Estimated cores of a planned run: what a sweep with `cpu_limit` packs runs by.

Theory of operation. A run's CPU grows with the process-steps it asks of the machine per
second, its load (testbed.sweep.plan.run_load): (robots + 1) x time_scale, each robot and
the display stepping ten times per second of robot time, time_scale times faster than the
wall clock. So its cores are about c x load, where c, the cores per unit of load, is what a
process-step costs in CPU seconds over the 0.1 s of robot time it stands for (the world's
step loop and the routing daemons included, shared out over the team).

c is learnt from the sweep's own finished runs (`measure`: the cores a run kept busy while
stepping, over the load it ran at): the median over the runs of the same team size (a small
team pays more of the world's fixed costs per robot than a large one), else the median over
all of them, else PRIOR_CORES_PER_LOAD, from the CPU per robot-step testbed.sweep.slurm
sizes cluster tasks by, with its margin, so that the first runs pack cautiously until a
measurement says how much room there is. The median: one run slowed by a burst on the host
does not move it. Pure: the runner gathers the measurements and asks.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable
from dataclasses import dataclass

from testbed.files.resultfile import RunResult
from testbed.sweep.slurm import CPU_MARGIN, CPU_S_PER_ROBOT_STEP, STEP_S

# Cores per unit of load before any run of the sweep has finished: CPU_S_PER_ROBOT_STEP is
# the whole run's CPU (world, display and routing included) per robot-step, measured on
# 10-robot runs; the load counts the display as one more robot, which leaves a small team
# its share of the world's per-step work; CPU_MARGIN for a loaded machine.
PRIOR_CORES_PER_LOAD = CPU_S_PER_ROBOT_STEP * CPU_MARGIN / STEP_S


@dataclass(frozen=True)
class Measured:
    """What one finished run says about c: its team size and its cores per unit of load."""

    robots: int
    cores_per_load: float


def load(robots: int, time_scale: float) -> float:
    """Process-steps per 100 ms of wall time: the robots and the display, time_scale times
    a second of robot time (testbed.sweep.plan.run_load for a planned run)."""
    return (robots + 1) * time_scale


def measure(result: RunResult) -> Measured | None:
    """A finished run's cores per unit of load, or None when its result.json does not say
    (no cpu_s or no stepping wall time: older runs). The load is taken at the time scale the
    run achieved, when it says: a run that fell behind did fewer steps a second than it was
    asked, and its CPU measures that smaller load."""
    cores = result.cores_while_stepping
    scale = result.time_scale_ran
    if cores is None or not scale or scale <= 0:
        return None
    return Measured(result.config.robots, cores / load(result.config.robots, scale))


def cores_per_load(robots: int, measurements: Iterable[Measured]) -> float:
    """c for a run of `robots` robots: the median over measured runs of that team size, else
    over all measured runs, else the prior."""
    measurements = list(measurements)
    same = [m.cores_per_load for m in measurements if m.robots == robots]
    every = [m.cores_per_load for m in measurements]
    if same:
        return statistics.median(same)
    if every:
        return statistics.median(every)
    return PRIOR_CORES_PER_LOAD


def estimate(robots: int, time_scale: float, measurements: Iterable[Measured]) -> float:
    """Cores a run of `robots` robots at `time_scale` (the scale it will run at, after the
    sweep's per-team-size factor) is expected to keep busy while it steps."""
    return cores_per_load(robots, measurements) * load(robots, time_scale)
