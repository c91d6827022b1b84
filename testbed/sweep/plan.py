"""The plan of a sweep: which planned runs are done, to do, partial or skipped, whether a
finished run was made with other settings, and how many runs to start at once.

Pure functions of the planned runs and the sweep directory (testbed.sweep.rundir's contract);
nothing here starts a process.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from testbed.files import sweepstate
from testbed.files.resultfile import RunResult
from testbed.files.runconfig import RunConfig
from testbed.sweep.cores import load
from testbed.sweep.file import PlannedRun
from testbed.sweep.rundir import is_done, plan_dict, run_dir


@dataclass
class Plan:
    done: list[PlannedRun] = field(default_factory=list)
    todo: list[PlannedRun] = field(default_factory=list)
    partial: list[PlannedRun] = field(default_factory=list)  # subset of todo: dir to delete
    skipped: dict[str, str] = field(default_factory=dict)  # run id -> reason


def skip_reason(run: PlannedRun, netem: bool) -> str | None:
    """Why this machine cannot do `run`, or None."""
    if run.config.delay_ms > 0 and not netem:
        return "delay needs the sch_netem kernel module, which this kernel lacks"
    return None


def plan(runs: list[PlannedRun], out: Path, netem: bool) -> Plan:
    """Sort planned runs into done / to do / skipped by what is on disk."""
    p = Plan()
    for run in runs:
        reason = skip_reason(run, netem)
        if is_done(out, run.run_id):
            p.done.append(run)
        elif reason:
            p.skipped[run.run_id] = reason
        else:
            p.todo.append(run)
            if run_dir(out, run.run_id).exists():
                p.partial.append(run)
    return p


def config_mismatch(out: Path, run: PlannedRun) -> str | None:
    """How a finished run's recorded config differs from the planned one, or None."""
    result = RunResult.read(run_dir(out, run.run_id))
    if result is None:
        return None  # unreadable results are the report's problem, not a reason to stop
    recorded = result.config.to_dict()
    for key, want in plan_dict(run.config).items():
        if key == "time_scale":
            continue  # how fast, not what: the sweep may have run it slower (sweeprunner)
        if key in recorded and recorded[key] != want:
            return f"{key} is {recorded[key]!r} there, {want!r} in the sweep file"
    return None


def other_sweep(out: Path, runs: list[PlannedRun]) -> str | None:
    """What in sweep directory `out` belongs to another sweep than `runs`, or None.

    A directory belongs to one sweep: every run its sweep.json plans, and every run
    directory it holds, must be a run of `runs` with the same config (its time scale aside:
    a sweep may run slower, testbed.sweep.runner). A plan that only adds runs (more `runs`
    per point, a value more in a list) extends the sweep and is the same one."""
    planned = {r.run_id: r.config for r in runs}
    state = sweepstate.read(out)
    for entry in state.runs if state else ():
        rid = entry.id
        if rid not in planned:
            return f"its sweep.json plans run {rid}, which this sweep file does not"
        config = entry.config
        differs = _plan_difference(config, planned[rid]) if config is not None else None
        if differs:
            return f"run {rid} has {differs}"
    runs_dir = out / "runs"
    held = sorted(p.name for p in runs_dir.iterdir()) if runs_dir.is_dir() else []
    stray = [rid for rid in held if rid not in planned]
    if stray:
        return f"it holds run {stray[0]}, which this sweep file does not plan"
    return None


_DEFAULTS = RunConfig(robots=1, comm_range=1.0).to_dict()


def _plan_difference(recorded: Mapping, config: RunConfig) -> str | None:
    """How a plan as sweep.json recorded it (plan_dict: options at their default may be left
    out) differs from `config`, its time scale aside; None when it does not."""
    mine = config.to_dict()
    for key in sorted(set(plan_dict(config)) | set(recorded)):
        if key == "time_scale" or key not in mine:
            continue
        there = recorded.get(key, _DEFAULTS[key])
        if there != mine[key]:
            return f"{key} {there!r} there and {mine[key]!r} in this sweep file"
    return None


def auto_jobs(runs: list[PlannedRun], cores: int | None = None) -> int:
    """--jobs auto: the cores divided by the CPUs the sweep's most demanding run needs
    (testbed.sweep.slurm.resources: its robots' CPU per step at its time scale, and a core for the
    world), at least 1. On the 2-core development machine: 1."""
    from testbed.sweep.slurm import resources

    cores = cores or os.cpu_count() or 1
    need = max((resources(r.config)[0] for r in runs), default=1)
    return max(1, cores // need)


def default_jobs(cores: int | None = None) -> int:
    """Concurrent runs to start with: half the cores (a run is a world plus N robots)."""
    cores = cores or os.cpu_count() or 1
    return max(1, cores // 2)


def jobs_cap(
    requested: int | str | None,
    runs: list[PlannedRun],
    cpu_limit: float | None,
    cores: int | None = None,
) -> int:
    """The most runs at once: --jobs J as given, --jobs auto (auto_jobs); without --jobs, the
    core count when the sweep packs runs by their estimated cores (cpu_limit: the estimate
    decides, and a cap of half the cores would keep two runs apart on two cores), else
    default_jobs."""
    if requested == "auto":
        return auto_jobs(runs, cores)
    if requested:
        return int(requested)
    if cpu_limit is not None:
        return max(1, cores or os.cpu_count() or 1)
    return default_jobs(cores)


def run_load(run: PlannedRun) -> float:
    """What a run asks of the machine: process-steps (robots, plus the display) per 100 ms of
    wall time, at the sweep file's time scale (testbed.sweep.cores.load)."""
    return load(run.config.robots, run.config.time_scale)
