"""`testbed sweep FILE --out DIR`: run every run of a sweep file, resumably; `--slurm` submits
them to a cluster instead, `--status DIR` shows where a sweep stands.

A sweep in parts: testbed.sweep.file reads the file and expands it into planned runs (each a
RunConfig with a stable id); testbed.sweep.rundir is the run directory contract (where a run lives,
when it is done, the `testbed run` command line that makes it); testbed.sweep.plan sorts the
planned runs by what is on disk; testbed.sweep.runner runs them here (its docstring tells how:
the fork server, concurrency, signals, back-off through testbed.sweep.policy) with
testbed.sweep.progress's line; testbed.sweep.slurm runs them on a cluster. This module is the
command line that joins them.
"""

from __future__ import annotations

import argparse
import fcntl
import logging
import os
import shutil
import stat
import sys
from pathlib import Path

from common.argtypes import number
from common.errors import UsageError
from common.jsonfile import make_dirs
from testbed.files import sweepstate
from testbed.files.runconfig import RunConfig
from testbed.sweep import file as sweepfile
from testbed.sweep.file import PlannedRun
from testbed.sweep.plan import Plan, config_mismatch, default_jobs, jobs_cap, other_sweep, plan
from testbed.sweep.rundir import is_done, run_dir
from testbed.sweep.runner import Sweep, wait_for_orphans
from topology.kernel.impair import kernel_has_netem

log = logging.getLogger(__name__)


def _open_lock(out: Path):
    """out/.sweep.lock, open for flock (held for the process's lifetime): made if missing,
    never truncated, and refused (one line) if it is a link or not a regular file."""
    path = out / ".sweep.lock"
    flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as e:
        raise UsageError(
            f"--out {out}: {path.name}: {e.strerror} (a link, or not a file)"
        ) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise UsageError(f"--out {out}: {path.name} is not a regular file")
    return os.fdopen(fd, "r+")


def _jobs(text: str) -> int | str:
    if text == "auto":
        return text
    return number(int, "--jobs", minimum=1)(text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "file", metavar="FILE", nargs="?",
        help="sweep file (TOML), e.g. testbed/experiments/paper.toml; at most "
        f"{sweepfile.MAX_RUNS:,} runs (the grid's lists times runs), its maps and lasers are "
        "checked before the first run",
    )  # fmt: skip
    parser.add_argument("--out", metavar="DIR", help="sweep directory")
    parser.add_argument(
        "--jobs",
        type=_jobs,
        default=None,
        metavar="J",
        help=f"runs at once, or 'auto' (from the cores and the CPU the sweep's largest run "
        f"needs); default {default_jobs()} on this machine, or the core count when the sweep "
        "file sets cpu_limit; lowered automatically when runs miss step deadlines",
    )
    parser.add_argument(
        "--view",
        metavar="[HOST:]PORT",
        help="the run in progress serves its live view there (one run at a time)",
    )
    parser.add_argument(
        "--no-prestart",
        action="store_true",
        help="start each run only when it may step (default: the next run sets up while the "
        "last one steps, its steps held until that one's are over)",
    )
    parser.add_argument(
        "--calibrate",
        action="store_true",
        help="before each team size's first run, find the time scale this machine sustains "
        "with short runs that stay in time and faithful (up to 4x the file's, or down); for "
        "hardware the file was not made for",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep in DIR: skip finished runs, redo partial ones; FILE must "
        "plan every run DIR holds, with the same settings (it may add runs)",
    )
    parser.add_argument(
        "--slurm",
        action="store_true",
        help="submit the runs to do as Slurm job arrays (one per team size) instead of "
        "running them here; DIR must be on a filesystem the nodes share",
    )
    parser.add_argument("--partition", metavar="P", help="with --slurm: sbatch --partition")
    parser.add_argument("--account", metavar="A", help="with --slurm: sbatch --account")
    parser.add_argument(
        "--sudo", action="store_true",
        help="with --slurm: tasks run `testbed run` through `sudo -n` (jobs that do not run "
        "as root)",
    )  # fmt: skip
    parser.add_argument(
        "--sbatch-arg", action="append", default=[], metavar="ARG",
        help="with --slurm: one more sbatch argument (repeatable), e.g. --sbatch-arg=--qos=long",
    )  # fmt: skip
    parser.add_argument(
        "--status",
        metavar="DIR",
        help="show each run of the sweep in DIR: done, running, pending (Slurm), failed, "
        "not submitted; no FILE needed",
    )


def _print_status(out: Path) -> int:
    from testbed.sweep import slurm

    state = sweepstate.read(out)
    if state is None:
        raise UsageError(f"--status {out}: no sweep.json: not a sweep directory")
    planned = state.runs
    if slurm.submitted(out):
        rows = slurm.status(out, planned)
    else:
        rows = [(e.id, "done" if is_done(out, e.id) else ("?" if e.status is None else e.status))
                for e in planned]  # fmt: skip
    for rid, st in rows:
        print(f"{rid}\t{st}")
    counts: dict[str, int] = {}
    for _, st in rows:
        counts[st] = counts.get(st, 0) + 1
    print(", ".join(f"{n} {st}" for st, n in sorted(counts.items())), file=sys.stderr)
    return 0


def _submit(args, spec, runs: list[PlannedRun], out: Path, p: Plan) -> int:
    from testbed.sweep import slurm

    in_queue = slurm.queued(out) if args.resume else {}
    todo = [r for r in p.todo if r.run_id not in in_queue]
    for r in todo:
        if run_dir(out, r.run_id).exists():
            shutil.rmtree(run_dir(out, r.run_id))  # partial: its task died
    sweep = Sweep(spec, runs, out, 1, False, sweep_file=str(args.file))
    for r in p.done:
        sweep.status[r.run_id] = {"status": "done"}
    for rid, reason in p.skipped.items():
        sweep.status[rid] = {"status": "skipped", "reason": reason}
    for r in p.todo:
        sweep.status[r.run_id] = {"status": "slurm"}
    sweep._write_state()
    before = len(slurm.submitted(out))
    jobs = (
        slurm.submit(out, todo, args.partition, args.account, args.sbatch_arg, args.sudo)
        if todo
        else ()
    )
    new = jobs[before:]
    print(
        f"sweep {args.file}: {len(runs)} runs, {len(p.done)} done, {len(in_queue)} still "
        f"queued, {len(todo)} submitted to Slurm"
        + (f" as job(s) {', '.join(str(j.job) for j in new)}" if todo else ""),
        file=sys.stderr,
    )
    return 0


def _check_maps(spec: sweepfile.SweepSpec) -> None:
    """Every map of the sweep, and every laser on it, as a run would check them, before the
    first run: a map that is missing, not a PNG or too large, or a laser longer than a map's
    diagonal, stops the sweep now instead of failing each of its runs."""
    from testbed.run.prepare import check_laser
    from testbed.world.worldmap import CELL, empty_terrain, png_cells

    for m in dict.fromkeys(spec.values("map")):
        if m is None:
            size_m = empty_terrain().size_m
        else:
            cols, rows = png_cells(m, RunConfig.map_cell)
            size_m = (cols * CELL, rows * CELL)
        for laser in spec.values("laser_range"):
            try:
                check_laser(laser, size_m)
            except UsageError as exc:
                where = "the empty terrain" if m is None else f"map {m}"
                raise UsageError(f"sweep: grid.laser_range on {where}: {exc}") from None


def _check_middlewares(runs: list[PlannedRun]) -> None:
    """Every middleware of the sweep can be opened here (its Python package installed), before
    the first run: a missing one stops the sweep now instead of failing each of its runs."""
    from testbed.run.prepare import check_middleware

    for name in dict.fromkeys(r.config.middleware for r in runs):
        try:
            check_middleware(name)
        except UsageError as exc:
            raise UsageError(f"sweep: {exc}") from None


def _check_same_sweep(out: Path, runs: list[PlannedRun], sweep_file: str) -> None:
    """--resume continues the sweep that made `out`, never another one into it."""
    diff = other_sweep(out, runs)
    if diff:
        state = sweepstate.read(out)
        made_by = (state.sweep_file if state else None) or "another sweep file"
        raise UsageError(
            f"--out {out} is the sweep of {made_by}, not of {sweep_file}: {diff}; resume it "
            "with its own sweep file, or give this one a new --out"
        )


def _concurrency(jobs: int, spec: sweepfile.SweepSpec) -> str:
    """How many runs at once, for the sweep's first line."""
    if spec.cpu_limit is None:
        return f", {jobs} at a time"
    cores = "core" if spec.cpu_limit == 1 else "cores"
    return f", up to {jobs} at a time within {spec.cpu_limit:g} {cores} (cpu_limit)"


def main(args: argparse.Namespace) -> int:
    if args.status:
        return _print_status(Path(args.status))
    if not args.file or not args.out:
        raise UsageError("testbed sweep needs FILE and --out DIR (or --status DIR)")
    if not args.slurm and (args.partition or args.account or args.sbatch_arg or args.sudo):
        raise UsageError("--partition, --account, --sbatch-arg and --sudo go with --slurm")
    if args.view:  # a busy port refused before the sweep's directory and lock are made
        from testbed.view.server import check_bind

        try:
            check_bind(args.view)
        except ValueError as e:
            raise UsageError(str(e)) from None
    spec = sweepfile.load(args.file)
    out = Path(args.out)
    runs = sweepfile.expand(spec)
    # Everything that can refuse the sweep comes before anything is made or locked.
    _check_maps(spec)
    _check_middlewares(runs)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    existing = sorted(p.name for p in (out / "runs").iterdir()) if (out / "runs").is_dir() else []
    if existing and not args.resume:
        raise UsageError(
            f"--out {out}: holds runs of an earlier sweep; pass --resume to continue it "
            "or choose another directory"
        )
    if args.resume:
        _check_same_sweep(out, runs, args.file)
        for r in runs:
            diff = config_mismatch(out, r) if is_done(out, r.run_id) else None
            if diff:
                raise UsageError(
                    f"--out {out}: run {r.run_id} was made with other settings ({diff}); "
                    "use a new directory"
                )
    jobs = jobs_cap(args.jobs, runs, spec.cpu_limit)
    netem = kernel_has_netem() if any(d > 0 for d in spec.values("delay_ms")) else False
    out.mkdir(parents=True, exist_ok=True)
    make_dirs(out / "runs", root=out)  # a runs/ that is a link is refused, not followed
    lock = _open_lock(out)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise UsageError(f"--out {out}: another sweep is running in this directory") from None
    if args.resume and not args.slurm:
        wait_for_orphans(out)
    p = plan(runs, out, netem)
    if p.skipped:
        log.warning("skipping %d run(s): %s", len(p.skipped), next(iter(p.skipped.values())))
    if args.slurm:
        return _submit(args, spec, runs, out, p)
    print(
        f"sweep {args.file}: {len(runs)} runs, {len(p.done)} done, {len(p.todo)} to do"
        + (f" ({len(p.partial)} partial, redone)" if p.partial else "")
        + (f", {len(p.skipped)} skipped" if p.skipped else "")
        + _concurrency(jobs, spec),
        file=sys.stderr,
    )
    sweep = Sweep(spec, runs, out, jobs, netem, sweep_file=str(args.file),
                  calibrate=args.calibrate, view=args.view,
                  prestart=not args.no_prestart)  # fmt: skip
    return sweep.run(p.todo, p.done, p.skipped)


if __name__ == "__main__":  # `python -m testbed.sweep.command` is `testbed sweep`
    from testbed.cli import main as cli_main

    sys.exit(cli_main(["sweep", *sys.argv[1:]]))
