"""The ranges of result.json's values: what testbed.files.resultfile checks after the types.

A result.json from elsewhere is strict JSON of the right types (testbed.files.resultfile,
common.boundedfile) but may still hold numbers no run can produce: -100 steps, a team of 0,
a finish step past the run's end, more deadlines missed in host stalls than in all. A report
drawn from those would be silently wrong ("team work beats one robot: holds" from negative
steps), so `check(result)` refuses them: ValueError naming the field and the bound, which
testbed.files.resultfile turns into its one-line ResultError naming the file.

Bounds are the run's own where it has them: a finish step or a plan's step is at most one
past the run's `steps` (a robot that finishes on the last step records the next), counts of
robots at most the team; otherwise the limits of the options (testbed.files.options).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from common import timescale

MAX_ROBOTS = 1000  # topology.names.MAX_ROBOTS
MAX_STEPS = 10**9  # testbed.files.options' max_steps bound
MAX_COORDINATE = 10_000_000.0  # metres: docs/security.md's coordinate limit
MAX_SECONDS = 1e9  # about 30 years


def _bounded(name: str, value, low: float, high: float, *, whole: bool = False):
    """`value` (None passes) within [low, high], whole where asked; ValueError otherwise.
    -0.0 comes back as 0.0 (a report would show "-0.0%")."""
    if value is None:
        return None
    if not math.isfinite(value):
        raise ValueError(f"{name!r} is {value}, not a finite number")
    if whole and value != int(value):
        raise ValueError(f"{name!r} is {value:g}, not a whole number")
    if not low <= value <= high:
        raise ValueError(f"{name!r} is {value:g}, outside {low:g}..{high:g}")
    return int(value) if whole else value + 0  # -0.0 + 0 is 0.0; an int stays an int


def _config(c) -> None:
    _bounded("config.robots", c.robots, 1, MAX_ROBOTS, whole=True)
    for name in ("comm_range", "laser_range"):
        value = getattr(c, name)
        _bounded(f"config.{name}", value, 0, MAX_COORDINATE)
        if not value > 0:
            raise ValueError(f"'config.{name}' is {value:g}, not greater than 0")
    if c.time_scale is not None and not timescale.valid(c.time_scale):
        raise ValueError(
            f"'config.time_scale' is {c.time_scale}: {timescale.refusal(c.time_scale)}"
        )
    _bounded("config.loss_pct", c.loss_pct, 0, 100)
    _bounded("config.delay_ms", c.delay_ms, 0, 1e7)
    _bounded("config.max_steps", c.max_steps, 0, MAX_STEPS, whole=True)
    for name in ("coordination", "start"):
        if not isinstance(getattr(c, name), str):
            raise ValueError(f"'config.{name}' is not a string")


def _robots(r, last: int | None) -> tuple:
    """The robots with whole steps; ValueError where a step is out of the run."""
    top = MAX_STEPS if last is None else last + 1
    out = []
    for robot in r.robots:
        name = f"robots.{robot.name}"
        finish = _bounded(f"{name}.finish_step", robot.finish_step, 0, top)
        _bounded(f"{name}.stopped_step", robot.stopped_step, 0, top, whole=True)
        path = _bounded(f"{name}.path_length_m", robot.path_length_m, 0, 1e12)
        for p in robot.plans:
            _bounded(f"{name}.plans.step", p.step, 0, top, whole=True)
        for kind, counts in (("sent", robot.sent), ("received", robot.received)):
            for k, n in counts.items():
                if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= 10**15:
                    raise ValueError(f"'{name}.messages.{kind}.{k}' is not a count")
        out.append(dataclasses.replace(robot, finish_step=finish, path_length_m=path))
    return tuple(out)


def check(r: Any) -> Any:
    """`r` (a testbed.files.resultfile.RunResult, whose reader calls this: typed Any, as this
    module sits below the type) with its whole numbers as ints and its -0.0s as 0.0, or ValueError
    naming the first value out of its range (see the module's docstring)."""
    _config(r.config)
    if len(r.robots) > MAX_ROBOTS + 1:  # the team and the display robot
        raise ValueError(f"'robots' lists {len(r.robots)}, more than {MAX_ROBOTS + 1}")
    steps = _bounded("steps", r.steps, 0, MAX_STEPS, whole=True)
    top = MAX_STEPS if steps is None else steps + 1
    _bounded("last_finish_step", r.last_finish_step, 0, top)
    mean = _bounded("mean_finish_step", r.mean_finish_step, 0, top)
    _bounded("mean_finish_step_robots", r.mean_finish_step_robots, 0, r.config.robots + 1)
    coverage = _bounded("coverage_final", r.coverage_final, 0, 1 + 1e-9)
    requested = r.time_scale_requested
    if requested is not None and not (math.isfinite(requested) and requested > 0):
        raise ValueError(f"'time_scale_requested' is {requested}, not a positive number")
    achieved = _bounded("time_scale_achieved", r.time_scale_achieved, 0, 1e6)  # 0: no step
    missed = _bounded("deadlines_missed", r.deadlines_missed, 0, MAX_STEPS * 1001, whole=True)
    _bounded("deadlines_missed_world", r.deadlines_missed_world, 0, top, whole=True)
    miss = _bounded("deadline_miss_fraction", r.deadline_miss_fraction, 0, 1)
    outside = _bounded(
        "deadline_miss_fraction_outside_stalls", r.deadline_miss_fraction_outside_stalls, 0, 1
    )
    hs = r.host_stalls
    _bounded("host_stalls.events", hs.events, 0, MAX_STEPS, whole=True)
    _bounded("host_stalls.stalled_s", hs.stalled_s, 0, MAX_SECONDS)
    _bounded("host_stalls.deadlines_missed", hs.deadlines_missed, 0, missed, whole=True)
    _bounded("wall_time_s", r.wall_time_s, 0, MAX_SECONDS)
    _bounded("step_loop_wall_s", r.step_loop_wall_s, 0, MAX_SECONDS)
    for i in r.isolated:
        _bounded("isolated.from_step", i.from_step, 0, top, whole=True)
        _bounded("isolated.back_step", i.back_step, 0, top, whole=True)
    return dataclasses.replace(
        r, steps=steps, robots=_robots(r, steps), mean_finish_step=mean, coverage_final=coverage,
        time_scale_achieved=achieved, deadline_miss_fraction=miss,
        deadline_miss_fraction_outside_stalls=outside,
    )  # fmt: skip
