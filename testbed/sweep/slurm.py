"""Sweeps on a Slurm cluster: `testbed sweep FILE --out DIR --slurm`, and `--status DIR`.

Theory of operation
-------------------
The sweep directory is the whole interface, exactly as for a local sweep: run R lives in
`DIR/runs/R/` and is done iff its `result.json` exists (written last, atomically, by `testbed
run`); `DIR/sweep.json` holds the plan. DIR must be on a filesystem every node sees.

`submit` writes, for the runs still to do, one task list and one batch script per team size
under `DIR/slurm/`, and submits each as a Slurm job array (`sbatch --array=1-N`): Slurm gives
every task of an array the same CPUs and time limit, and those depend on the team size
(`resources`). Array task i runs `python -m testbed.sweep.slurm task DIR LIST i` on whatever node
it lands on: it reads the i-th run id of LIST, finds the run's configuration in the plan,
removes a partial directory an earlier attempt left, and runs `testbed run` in-process,
which tears its namespaces down on SIGTERM (what `scancel` and a time limit send first).
The job ids go to `DIR/slurm/jobs.json` (its type: testbed.files.slurmjobs). A task killed
outright (SIGKILL, a node lost) leaves a directory without result.json: `--status` calls it
failed, and the next `--resume --slurm` resubmits exactly the runs that are neither done nor
queued, never a finished one.

`status` joins the directory with `squeue` (pending or running array tasks): done, running,
pending, failed (submitted, not done, no longer queued) or not submitted.
"""

from __future__ import annotations

import math
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from common.errors import TestbedError, UsageError
from common.jsonfile import make_dirs, write_atomic
from testbed import PROJECT_ROOT
from testbed.files import slurmjobs, sweepstate
from testbed.files.resultfile import RESULT_NAME, RunResult
from testbed.files.runconfig import RunConfig
from testbed.sweep.file import PlannedRun
from testbed.sweep.rundir import is_done, run_argv, run_dir

# CPU the whole run uses per robot-step: robots, display, the world's step loop and the
# routing daemons together (result.json's cpu_s.per_robot_step_ms). Measured 1.0-1.5 ms for
# 10 robots at 20 m on a quiet machine, 1.8 ms on a loaded one (CPU_MARGIN covers it), where
# 4 ms was assumed before. A sweep directory with finished runs sizes by what they measured.
CPU_S_PER_ROBOT_STEP = 0.0015
STEP_S = 0.1  # a world step is 100 ms of robot time
CPU_MARGIN = 1.5
TIME_MARGIN = 3.0
STARTUP_S = 120.0  # bring-up, teardown, and a loaded node's slowness


def resources(
    config: RunConfig, cpus_per_node: int | None = None, cpu_per_robot_step: float | None = None
) -> tuple[int, int]:
    """(CPUs, time limit in minutes) for one run: its robots (and the display) each use
    `cpu_per_robot_step` seconds (default CPU_S_PER_ROBOT_STEP) per step, and a step lasts
    STEP_S / time scale of wall time, plus a core for the world's clock and the captures;
    the time is the step cap at that pace, with margin. CPUs are capped at what a node of
    the partition has."""
    ts = config.time_scale
    per_step = cpu_per_robot_step or CPU_S_PER_ROBOT_STEP
    cores = (config.robots + 1) * per_step * ts / STEP_S * CPU_MARGIN + 1
    cpus = max(1, math.ceil(cores))
    if cpus_per_node:
        cpus = min(cpus, cpus_per_node)
    seconds = config.max_steps * STEP_S / ts * TIME_MARGIN + STARTUP_S
    return cpus, max(1, math.ceil(seconds / 60))


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise UsageError(f"--slurm needs Slurm's `{name}` on this machine (slurm-client)")
    return path


def _run(argv: list[str]) -> str:
    proc = subprocess.run(argv, capture_output=True, text=True)
    if proc.returncode != 0:
        first = (proc.stderr.strip() or proc.stdout.strip() or "no output").splitlines()[0]
        raise TestbedError(f"{Path(argv[0]).name} failed: {first}")
    return proc.stdout


def measured_cpu_per_robot_step(out: Path) -> float | None:
    """The most CPU seconds per robot-step that the finished runs (and calibration trials)
    of the sweep directory measured (result.json's cpu_s), or None when none says."""
    found = []
    for res in [*out.glob(f"runs/*/{RESULT_NAME}"), *out.glob(f"calibration/*/{RESULT_NAME}")]:
        result = RunResult.read(res.parent)
        ms = result.cpu_per_robot_step_ms if result else None
        if ms is not None and ms > 0:
            found.append(ms / 1000)
    return max(found, default=None)


def node_cpus(partition: str | None) -> int | None:
    """The most CPUs a node of the partition (or the default one) has, from sinfo."""
    argv = [_tool("sinfo"), "-h", "-o", "%c"]
    if partition:
        argv += ["-p", partition]
    values = [int(v) for v in _run(argv).split() if v.isdigit()]
    return max(values) if values else None


def submitted(out: Path) -> tuple[slurmjobs.SlurmJob, ...]:
    """The job arrays submitted for this sweep, in the order they were (UsageError when its
    jobs file is not one)."""
    return slurmjobs.read(out).jobs


def queued(out: Path) -> dict[str, str]:
    """Run id -> Slurm state (PENDING, RUNNING, ...) of the sweep's tasks still in the queue."""
    jobs = submitted(out)
    if not jobs:
        return {}
    ids = ",".join(str(j.job) for j in jobs)
    text = _run([_tool("squeue"), "-h", "-r", "-j", ids, "-o", "%i %T"])
    by_job = {str(j.job): j.runs for j in jobs}
    state = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) != 2 or "_" not in parts[0]:
            continue
        job, task = parts[0].split("_", 1)
        runs = by_job.get(job)
        if runs and task.isdigit() and 1 <= int(task) <= len(runs):
            state[runs[int(task) - 1]] = parts[1]
    return state


def batch_script(out: Path, task_list: Path, sudo: bool = False) -> str:
    """The array task's script; with `sudo`, it runs the task through `sudo -n` (for sites
    whose jobs run as the user, with sudo allowed for this command)."""
    python = ("sudo -n " if sudo else "") + shlex.quote(sys.executable)
    repo = shlex.quote(PROJECT_ROOT)
    return (
        "#!/bin/sh\n"
        "# One run of a testbed sweep per array task (testbed/sweep/slurm.py). Needs root on the\n"
        "# node: network namespaces.\n"
        f"cd {repo} || exit 1\n"
        f"exec {python} -m testbed.sweep.slurm task {shlex.quote(str(out))} "
        f'{shlex.quote(str(task_list))} "$SLURM_ARRAY_TASK_ID"\n'
    )


def submit(
    out: Path,
    todo: list[PlannedRun],
    partition: str | None = None,
    account: str | None = None,
    sbatch_args: list[str] | None = None,
    sudo: bool = False,
) -> tuple[slurmjobs.SlurmJob, ...]:
    """Submit one job array per team size for `todo`; returns the jobs (also recorded)."""
    sbatch = _tool("sbatch")
    cap = node_cpus(partition)
    measured = measured_cpu_per_robot_step(out)
    slurm_dir = out / "slurm"
    make_dirs(slurm_dir / "logs", root=out)  # never through a link
    jobs = list(submitted(out))
    groups: dict[int, list[PlannedRun]] = {}
    for run in todo:
        groups.setdefault(run.config.robots, []).append(run)
    for robots, runs in sorted(groups.items()):
        cpus = max(resources(r.config, cap, measured)[0] for r in runs)
        minutes = max(resources(r.config, cap, measured)[1] for r in runs)
        n = len(jobs) + 1
        task_list = slurm_dir / f"tasks-{n}.txt"
        write_atomic(task_list, "".join(f"{r.run_id}\n" for r in runs))
        script = slurm_dir / f"job-{n}.sh"
        write_atomic(script, batch_script(out, task_list, sudo), mode=0o755)
        argv = [
            sbatch, "--parsable", f"--array=1-{len(runs)}", f"--cpus-per-task={cpus}",
            f"--time={minutes}", f"--job-name=tb-{out.name}-n{robots}",
            f"--output={slurm_dir / 'logs' / '%A_%a.log'}",
        ]  # fmt: skip
        if partition:
            argv.append(f"--partition={partition}")
        if account:
            argv.append(f"--account={account}")
        argv += list(sbatch_args or []) + [str(script)]
        job = _run(argv).strip().split(";")[0]
        if not job.isdigit():
            raise TestbedError(f"sbatch answered {job!r}, not a job id")
        jobs.append(slurmjobs.SlurmJob(job=int(job), task_list=str(task_list), robots=robots,
                                       cpus=cpus, minutes=minutes,
                                       runs=tuple(r.run_id for r in runs)))  # fmt: skip
        slurmjobs.write(out, slurmjobs.SlurmJobs(tuple(jobs)))
    return tuple(jobs)


def status(out: Path, plan_runs: Sequence[sweepstate.SweepRun]) -> list[tuple[str, str]]:
    """(run id, done | running | pending | failed | not submitted) for every planned run."""
    in_queue = queued(out)
    ever = {rid for j in submitted(out) for rid in j.runs}
    rows = []
    for entry in plan_runs:
        rid = entry.id
        if is_done(out, rid):
            rows.append((rid, "done"))
        elif rid in in_queue:
            rows.append(
                (rid, "running" if in_queue[rid] in ("RUNNING", "COMPLETING") else "pending")
            )
        elif rid in ever:
            rows.append((rid, "failed"))
        else:
            rows.append((rid, "not submitted" if entry.status is None else entry.status))
    return rows


def task_main(out: Path, task_list: Path, index: int) -> int:
    """One array task: run the `index`-th run of `task_list` (1-based) into its directory."""
    from testbed import cli
    from testbed.cli import main as cli_main
    from topology.cleanup import clean

    run_ids = task_list.read_text().split()
    if not 1 <= index <= len(run_ids):
        print(f"testbed slurm task: no run {index} in {task_list}", file=sys.stderr)
        return 2
    rid = run_ids[index - 1]
    try:
        state = sweepstate.read(out)
    except UsageError as e:
        print(f"testbed slurm task: {e}", file=sys.stderr)
        return 2
    planned = state.run(rid) if state else None
    if planned is None:
        print(f"testbed slurm task: {rid} is not in {sweepstate.state_path(out)}", file=sys.stderr)
        return 2
    if is_done(out, rid):
        print(f"{rid}: already done", file=sys.stderr)
        return 0
    clean()  # what testbeds of a task killed on this node left behind (live ones stay)
    rdir = run_dir(out, rid)
    if rdir.exists():
        shutil.rmtree(rdir)  # a partial run of an earlier attempt
    print(f"{rid}: on {os.uname().nodename}", file=sys.stderr, flush=True)
    status = cli_main(["run", *run_argv([], dict(planned.config or {}), rdir)])
    if cli.terminated:
        _mark_interrupted(rdir)
    return status


def _mark_interrupted(rdir: Path) -> None:
    """A task cancelled or out of time gets SIGTERM, and so do its run's helper processes
    (Slurm signals the whole step): the run may end with an error of its own ("the fork
    server died") rather than as interrupted. It did not end on its own, so it is recorded
    as interrupted, which `--resume` redoes (testbed.sweep.rundir.is_done)."""
    result = RunResult.read(rdir)
    if result is None or result.status == "interrupted":
        return
    detail = (
        f"cancelled (SIGTERM from the batch system); it ended as {result.status}: "
        f"{result.status_detail}"
    )
    replace(result, status="interrupted", status_detail=detail).write(rdir)


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "task" and sys.argv[4].isdigit():
        sys.exit(task_main(Path(sys.argv[2]), Path(sys.argv[3]), int(sys.argv[4])))
    print("usage: python -m testbed.sweep.slurm task DIR TASK_LIST INDEX", file=sys.stderr)
    sys.exit(2)
