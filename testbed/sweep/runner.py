"""The sweep runner: runs the runs of a sweep directory as child processes, resumably.

Theory of operation. The sweep file expands (testbed.sweep.file) into planned runs, each with an
id derived from its parameters. Run `R` lives in `DIR/runs/R/` and is *done* iff
`DIR/runs/R/result.json` exists (testbed.sweep.rundir: `testbed run` writes that file last and
atomically, so the file system alone says what is finished). testbed.sweep.plan sorts the
planned runs into done, to do (absent, or partial: a directory without result.json, deleted
before the run is redone) and skipped (points this machine cannot run, e.g. delay without
sch_netem, with the reason recorded); `Sweep.run` takes the runs to do.

Each run is a child process, `testbed run ... --out DIR/runs/R`, with its output in
`DIR/logs/R.log`. The children are forked from a fork server (topology.kernel.forkserver) that has
imported `testbed run` once: a fresh interpreter spent about 1 s of each run on its imports
(pyroute2, OpenCV, numpy), 4 minutes over the paper's 240 runs. Children run in their own
session (a Ctrl-C in the terminal reaches only the sweep, which forwards it) and with
PR_SET_PDEATHSIG=SIGINT towards the server, which itself dies with the sweep, so a SIGKILLed
sweep takes its runs down with it instead of leaving them writing into directories a resumed
sweep redoes. SIGINT, not SIGTERM: `testbed run` tears its testbed down on KeyboardInterrupt,
while SIGTERM's default action would kill it before it removes its namespaces. (With
TESTBED_SWEEP_RUN_COMMAND set, tests run a stand-in program instead, exec'd the same way.)
On SIGINT or SIGTERM the sweep starts nothing new, forwards SIGINT to each running child,
waits, escalates to SIGTERM and then SIGKILL of the child's process group, and exits 130.
A run that finishes during that grace period still counts.

Concurrency: at most --jobs runs at once (default from the core count) and, when the sweep file
sets `load_limit`, only while the loads of the runs in flight add up to at most that: a run's
load is (robots + 1) x time_scale, the process-steps it asks of the machine per 100 ms of
wall time, so a sweep whose time scale falls with team size packs small teams side by side
and gives a large one the machine alone. With `cpu_limit` (cores), only while the estimated
cores of the runs in flight add up to at most that: c x load at the time scale the run will
get, c learnt from what the sweep's finished runs measured (testbed.sweep.cores); without
--jobs the cap is then the core count, so that the estimate alone decides. A run must fit
every limit set, and a run always starts when none is in flight. A run whose steps are done
(it said so by creating the file `--steps-over` names: `DIR/logs/R.steps-over`) is in its
tail: its processes exit, its network goes down and its results are written, none of it
with a deadline, and it no longer counts as in flight, so the next run's set-up overlaps
that tail instead of waiting for it (about a second a run: a quarter of a run's fixed
cost). A run that was late while it overlapped a tail turns the overlap off for its team
size until enough of its runs came out clean (testbed.sweep.policy, rules 3 and 9); with
--view there is none (the live page's run holds its port to its exit), and while more than
--jobs tails go on, tails count as in flight again.

Pre-start: while exactly one run steps, the next one sets up beside it and waits at a start
gate until that run's steps are over (testbed.sweep.prestart).

The queue is served first-fit: the first waiting run that fits starts. What happens when a
run misses step deadlines (the concurrency backs off, a team size's time scale goes down and
up again, a run is redone) is decided by the pure rules of testbed.sweep.policy;
`Sweep._finish` only applies them. The limits, the time scales and which run fits next are
the sweep's schedule (testbed.sweep.schedule.Schedule); `Sweep` starts, watches and stops
the runs.
`DIR/sweep.json` holds the expanded plan and each run's status, rewritten atomically whenever
something changes; a lock file keeps two sweeps out of one directory.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import logging
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import BinaryIO

from common.errors import TestbedError
from testbed.files import sweepstate
from testbed.files.resultfile import RESULT_NAME, RunResult
from testbed.files.runconfig import RunConfig
from testbed.sweep import calibrate as sweepcalibrate
from testbed.sweep import cores as sweepcores
from testbed.sweep import policy as sweeppolicy
from testbed.sweep import prestart
from testbed.sweep.file import PlannedRun
from testbed.sweep.plan import run_load
from testbed.sweep.prestart import gate_file, gate_timeout
from testbed.sweep.progress import Progress
from testbed.sweep.rundir import is_done, plan_dict, run_argv, run_dir
from testbed.sweep.schedule import Schedule, note_sharing
from topology.kernel.forkserver import Forked, ForkServer, ForkServerError, python_env
from topology.state import is_alive, proc_start_time

log = logging.getLogger(__name__)

# Environment variable naming the command that runs one run (tests use a stand-in program).
RUN_COMMAND_ENV = "TESTBED_SWEEP_RUN_COMMAND"
# What the run server imports once for every run (testbed.cli imports the rest on demand).
RUN_PRELOAD = [
    "testbed.cli",
    "testbed.run.execute",
    "pyroute2",
    "topology.kernel.rtnl",
    "topology.network",
]
# Seconds a child gets after SIGINT, then after SIGTERM, before its group is SIGKILLed.
GRACE_INT = 30.0
GRACE_TERM = 10.0
_PR_SET_PDEATHSIG = 1


def run_command() -> list[str] | None:
    """The argv prefix of a program that runs one run, if TESTBED_SWEEP_RUN_COMMAND names one;
    None: runs are `testbed run` forked from the run server (RunForker)."""
    override = os.environ.get(RUN_COMMAND_ENV)
    return shlex.split(override) if override else None


class RunForker:
    """Starts `testbed run` as forks of a server that has done its imports (RUN_PRELOAD)."""

    def __init__(self, label: str):
        env = python_env()
        env["OPENBLAS_NUM_THREADS"] = "1"  # no BLAS thread pool in a process that forks
        self.server = ForkServer(RUN_PRELOAD, env=env, label=label)

    def start(self, argv: list[str], log_path: Path, title: str) -> Forked:
        """`argv`: `testbed run`'s arguments. Returns a Popen-like Forked."""
        try:
            return self.server.spawn(
                None, "testbed.cli", ["run", *argv], str(log_path), title=title,
                pdeathsig=signal.SIGINT,
            )  # fmt: skip
        except ForkServerError as exc:
            raise TestbedError(f"cannot start a run: {exc}") from None

    def close(self) -> None:
        self.server.close()


def _child_setup(parent_pid: int) -> None:  # runs in the child between fork and exec
    os.setsid()
    with contextlib.suppress(Exception):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGINT, 0, 0, 0)
    if os.getppid() != parent_pid:  # the sweep died before prctl took effect
        os._exit(1)


@dataclass
class _Child:
    run: PlannedRun
    proc: subprocess.Popen | Forked
    started: float
    jobs_at_start: int
    log_file: BinaryIO
    load: float = 0.0
    shared: bool = False  # another run was in flight at some time during this one
    load_seen: float = 0.0  # the most load in flight while this one ran
    cores: float = 0.0  # its estimated cores when it started (testbed.sweep.cores)
    cpu_seen: float = 0.0  # the most estimated cores in flight while this one ran
    tail: bool = False  # its steps are done (it created its --steps-over file)
    overlapped: bool = False  # another run's tail overlapped its set-up or steps
    gated: bool = False  # pre-started: its steps wait for the sweep to create its gate
    awaits: str = ""  # pre-started: the run whose steps' end opens its gate
    gate_wait: float = 0.0  # pre-started: seconds from its start to its gate's opening
    prestarted_beside: bool = False  # the next run was pre-started beside its steps
    no_prestart_beside: bool = False  # a run pre-started beside it timed out at its gate
    config: RunConfig | None = None  # what it was started with (its time scale)
    cancelled: bool = False  # pre-started at a time scale the policy changed since: stopped


class Sweep:
    """Runs the to-do runs of one sweep directory; `run()` returns the process exit status."""

    def __init__(
        self,
        spec,
        runs: list[PlannedRun],
        out: Path,
        jobs: int,
        netem: bool,
        sweep_file: str = "",
        command: list[str] | None = None,
        progress_stream=None,
        calibrate: bool = False,
        view: str | None = None,
        prestart: bool = True,
    ):
        self.spec = spec
        self.runs = runs
        self.out = out
        # The concurrency, limits and time scales, and which run fits next.
        self.schedule = Schedule(
            jobs, getattr(spec, "load_limit", None), getattr(spec, "cpu_limit", None)
        )
        self.calibrate = calibrate  # --calibrate: find each team size's time scale first
        # --view: the run in progress serves the live page (one run at a time holds it, to
        # its exit: no run starts during another's tail then).
        self.view = view
        self.schedule.tails_wait = view is not None
        self.schedule.prestart = prestart  # --no-prestart: no run is pre-started
        self.children: dict[str, _Child] = {}  # the runs in flight, by id (run())
        self.view_owner: str | None = None
        self.netem = netem
        self.sweep_file = sweep_file
        self.command = command or run_command()
        self.forker: RunForker | None = None  # started by run() when there is no command
        self.status: dict[str, dict] = {r.run_id: {"status": "pending"} for r in runs}
        self.stop_signal: int | None = None
        self.progress = Progress(len(runs), progress_stream)

    # -- the schedule's (testbed.sweep.schedule)

    @property
    def jobs(self) -> int:
        return self.schedule.jobs

    @property
    def measured(self) -> list[sweepcores.Measured]:
        return self.schedule.measured

    @measured.setter
    def measured(self, measured: list[sweepcores.Measured]) -> None:
        self.schedule.measured = measured

    @property
    def scale_factors(self) -> dict[int, float]:
        return self.schedule.scale_factors

    @scale_factors.setter
    def scale_factors(self, factors: dict[int, float]) -> None:
        self.schedule.scale_factors = factors

    def _estimate(self, run: PlannedRun) -> float:
        """The cores `run` is expected to keep busy (Schedule.estimate)."""
        return self.schedule.estimate(run)

    def _next_fitting(self, queue: deque, children: dict) -> PlannedRun | None:
        """The first waiting run that fits, taken off `queue` (Schedule.next_fitting)."""
        return self.schedule.next_fitting(queue, children)

    # -- bookkeeping

    def _write_state(self) -> None:
        sch = self.schedule
        sweepstate.write(
            self.out,
            sweepstate.SweepState(
                format=sweepstate.STATE_FORMAT,
                sweep_file=self.sweep_file,
                spec=self.spec.to_dict(),
                jobs_requested=sch.jobs_requested,
                jobs=sch.jobs,
                load_limit_requested=sch.load_limit_requested,
                load_limit=sch.load_limit,
                cpu_limit_requested=sch.cpu_limit_requested,
                cpu_limit=sch.cpu_limit,
                time_scale_factor={
                    str(n): round(f, 3) for n, f in sorted(sch.scale_factors.items())
                },
                netem=self.netem,
                calibration={
                    str(n): {"factor": sch.ceilings.get(n), "trials": trials}
                    for n, trials in sorted(sch.calibration.items())
                },
                backoffs=tuple(sch.backoffs),
                updated=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                runs=tuple(
                    sweepstate.SweepRun(
                        id=r.run_id,
                        index=r.index,
                        config=plan_dict(r.config),
                        record=self.status[r.run_id],
                    )
                    for r in self.runs
                ),
            ),
        )

    def _counts(self):
        st = [s["status"] for s in self.status.values()]
        return st.count("done"), st.count("running"), st.count("failed")

    def _show(self, queue, event=None) -> None:
        done, running, failed = self._counts()
        jobs = self.progress.parallelism() if self.schedule.limited else self.jobs
        eta = self.progress.eta(list(queue), running, jobs)
        self.progress.update(done, running, failed, eta, event)

    # -- signals

    def _on_signal(self, signum, frame) -> None:
        if self.stop_signal is None:
            self.stop_signal = signum
            log.warning("%s: stopping, waiting for runs in flight", signal.Signals(signum).name)
        else:
            self.stop_signal = -1  # a second signal: stop waiting politely

    # -- one child

    def _spawn(
        self,
        config: RunConfig,
        rdir: Path,
        log_path: Path,
        title: str,
        steps_over: Path | None = None,
        gate: tuple[Path, float] | None = None,
    ) -> tuple[subprocess.Popen | Forked, BinaryIO]:
        """Start one `testbed run` of `config` into `rdir` (removed first if there): from
        the run server, or the stand-in command with the death signal towards the sweep;
        with `--steps-over steps_over` when given (removed first if there), and pre-started
        with `--start-when FILE --start-timeout S` when `gate` is (FILE, S) (FILE removed
        first). Returns (process, its open log file, which the caller closes)."""
        if rdir.exists():
            shutil.rmtree(rdir)
        log_path.parent.mkdir(parents=True, exist_ok=True)
        extra: list[str] = []
        if steps_over is not None:
            steps_over.unlink(missing_ok=True)
            extra = ["--steps-over", str(steps_over)]
        if gate is not None:
            gate[0].unlink(missing_ok=True)
            extra += ["--start-when", str(gate[0]), "--start-timeout", f"{gate[1]:.0f}"]
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC
        log_file = os.fdopen(os.open(log_path, flags, 0o644), "wb")  # the caller closes it
        proc: subprocess.Popen | Forked
        if self.forker is not None:
            proc = self.forker.start(run_argv([], config, rdir) + extra, log_path, title)
        else:
            assert self.command is not None  # run() starts the forker when there is none
            proc = subprocess.Popen(
                run_argv(self.command, config, rdir) + extra,
                stdin=subprocess.DEVNULL,
                stdout=log_file,
                stderr=subprocess.STDOUT,
                preexec_fn=functools.partial(_child_setup, os.getpid()),
            )
        return proc, log_file

    def _measure(self, result: RunResult | None, st: dict) -> None:
        """Learn from a finished run's result (None: unreadable) what its cores were, and
        record them in its status entry `st`."""
        cores = result.cores_while_stepping if result else None
        if cores is not None:
            st["cores_measured"] = round(cores, 3)
        if result:
            self.schedule.learn(result)

    def _start(self, run: PlannedRun, after: _Child | None = None) -> _Child:
        """Start `run`; pre-started, its gate opening when `after`'s steps are over, when
        `after` is given."""
        config = self.schedule.scaled(run)
        estimate = self.schedule.estimate(run)
        if self.view and self.view_owner is None:
            config = replace(config, view=self.view)
            self.view_owner = run.run_id
        proc, log_file = self._spawn(
            config, run_dir(self.out, run.run_id), self.out / "logs" / f"{run.run_id}.log",
            run.run_id, self._steps_over_file(run.run_id),
            None if after is None else (gate_file(self.out, run.run_id),
                                        gate_timeout(self.schedule.scaled(after.run))),
        )  # fmt: skip
        self.status[run.run_id] = {
            "status": "running",
            "pid": proc.pid,
            "pid_start": proc_start_time(proc.pid),
            "attempts": self.status[run.run_id].get("attempts", 0) + 1,
            "cores_estimated": round(estimate, 3),
        }
        child = _Child(run, proc, time.monotonic(), self.jobs, log_file, load=run_load(run),
                       cores=estimate)  # fmt: skip
        child.load_seen, child.cpu_seen = child.load, child.cores
        child.config = config
        if after is not None:
            child.gated, child.awaits = True, after.run.run_id
            after.prestarted_beside = True
            self.status[run.run_id]["prestarted"] = True
        return child

    def _steps_over_file(self, run_id: str) -> Path:
        """The file run `run_id` creates when its steps are done (`testbed run --steps-over`)."""
        return self.out / "logs" / f"{run_id}.steps-over"

    def _finish(self, child: _Child, queue: deque) -> str:
        """Record a child that exited; returns the event line for the progress display."""
        child.log_file.close()
        self._steps_over_file(child.run.run_id).unlink(missing_ok=True)
        gate_file(self.out, child.run.run_id).unlink(missing_ok=True)
        if self.view_owner == child.run.run_id:
            self.view_owner = None
        run = child.run
        wall = time.monotonic() - child.started
        st = self.status[run.run_id]
        st.pop("pid", None)
        st["exit_status"] = child.proc.returncode
        if child.overlapped:  # another run's tail overlapped its set-up or steps
            st["overlapped"] = True
        if child.prestarted_beside:  # the next run was pre-started beside its steps
            st["prestarted_beside"] = True
        st["wall_time_s"] = round(wall, 1)
        if child.cancelled:  # stopped at its gate (testbed.sweep.prestart.open_gates)
            return prestart.redo_cancelled(child, st, queue)
        if st.get("prestarted"):
            st["gate_wait_s"] = round(child.gate_wait, 2)
        if not is_done(self.out, run.run_id):
            st["status"] = "failed"
            st["reason"] = _last_line(self.out / "logs" / f"{run.run_id}.log") or (
                f"exited with status {child.proc.returncode} without {RESULT_NAME}"
            )
            return f"{run.run_id}: FAILED ({st['reason']})"
        # None: unreadable, counted as saying nothing (the report names it)
        result = RunResult.read(run_dir(self.out, run.run_id))
        if result is not None and result.status == prestart.GATE_TIMEOUT_STATUS:
            return prestart.redo_shut(child, result.status_detail, st, queue, self.children)
        st["status"] = "done"
        st["result_status"] = result.status if result else None
        miss = result.deadline_miss_fraction if result else None
        st["deadline_miss_fraction"] = miss
        faithful = result.faithful if result else None
        if faithful is not None:
            st["faithful"] = faithful
        self._measure(result, st)
        n = run.config.robots
        self.progress.record(n, wall - child.gate_wait)
        outcome = sweeppolicy.Outcome(
            robots=n,
            miss=miss,
            # Misses while the host stalled the whole machine (testbed.run.stalls) are told apart.
            miss_outside_stalls=result.deadline_miss_fraction_outside_stalls if result else None,
            shared=child.shared,
            overlapped=child.overlapped,
            prestarted_beside=child.prestarted_beside,
            load_seen=child.load_seen,
            cpu_seen=child.cpu_seen,
            jobs_at_start=child.jobs_at_start,
            attempts=st["attempts"],
            faithful=faithful,
            fidelity_reason=result.fidelity_reason if result else "",
        )
        decision = sweeppolicy.decide(outcome, self.schedule.policy_state())
        self._apply(decision, run, st, queue)
        return f"{run.run_id}: {st['result_status']} in {wall:.0f} s" + decision.words

    def _apply(self, d: sweeppolicy.Decision, run: PlannedRun, st: dict, queue: deque) -> None:
        """Carry out what the policy decided about `run` (status entry `st`)."""
        self.schedule.apply(d, run.run_id)
        if d.redo:
            st["status"] = "pending"
            queue.appendleft(run)

    def _stop_children(self, children: dict[str, _Child], queue: deque) -> None:
        for child in children.values():
            with contextlib.suppress(ProcessLookupError):
                child.proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + GRACE_INT
        stage = "int"
        while children:
            for rid in [r for r, c in children.items() if c.proc.poll() is not None]:
                self._finish(children.pop(rid), queue)
            if not children:
                break
            now = time.monotonic()
            if stage == "int" and (now > deadline or self.stop_signal == -1):
                for child in children.values():
                    with contextlib.suppress(ProcessLookupError):
                        child.proc.terminate()
                stage, deadline = "term", now + GRACE_TERM
            elif stage == "term" and now > deadline:
                for child in children.values():
                    with contextlib.suppress(ProcessLookupError, PermissionError):
                        os.killpg(child.proc.pid, signal.SIGKILL)
                stage = "kill"
            time.sleep(0.1)
        for rid, st in self.status.items():
            if st["status"] == "failed" and not is_done(self.out, rid):
                st["status"] = "interrupted"

    # -- the loop

    def run(self, todo: list[PlannedRun], done: list[PlannedRun], skipped: dict[str, str]) -> int:
        for r in done:
            self.status[r.run_id] = {"status": "done", "previous_sweep": True}
            res = RunResult.read(run_dir(self.out, r.run_id))
            self.status[r.run_id]["result_status"] = res.status if res else None
            self._measure(res, self.status[r.run_id])
        for rid, reason in skipped.items():
            self.status[rid] = {"status": "skipped", "reason": reason}
        self.progress.total = len(self.runs) - len(skipped)
        queue = deque(todo)
        children = self.children
        old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        if self.command is None and queue:
            self.forker = RunForker(label=str(self.out.resolve()))
        try:
            if self.calibrate:
                sweepcalibrate.calibrate(self, list(queue))
            self._write_state()
            self._show(queue)
            while (queue or children) and self.stop_signal is None:
                self.schedule.mark_tails(children, self._steps_over_file)
                # Before any other start: a pre-started run was first in line.
                if prestart.open_gates(children, self.schedule, self.out):
                    self._write_state()
                while queue and self.stop_signal is None:
                    run = self.schedule.next_fitting(queue, children)
                    if run is None:
                        break
                    flying = self.schedule.beside(run, children)
                    child = self._start(run)
                    child.overlapped = len(flying) < len(children)
                    children[run.run_id] = child
                    flying.append(child)
                    note_sharing(flying)
                    self._write_state()
                    self._show(queue)
                pre = None
                if self.stop_signal is None:
                    pre = self.schedule.prestart_next(queue, children)
                if pre is not None:
                    run, ahead = pre
                    children[run.run_id] = self._start(run, after=ahead)
                    self._write_state()
                    self._show(queue)
                exited = [rid for rid, c in children.items() if c.proc.poll() is not None]
                for rid in exited:
                    event = self._finish(children.pop(rid), queue)
                    self._write_state()
                    self._show(queue, event)
                if not exited:
                    # A shut gate is on the critical path: its opening is looked for sooner.
                    time.sleep(0.01 if any(c.gated for c in children.values()) else 0.1)
            if self.stop_signal is not None:
                self._stop_children(children, queue)
                self._write_state()
        finally:
            for s, h in old.items():
                signal.signal(s, h)
            if self.forker is not None:
                self.forker.close()
            self.progress.close()
        if self.stop_signal is not None:
            done, _, _ = self._counts()
            print(
                f"sweep interrupted: {done} of {self.progress.total} runs done; "
                f"resume with --resume",
                file=sys.stderr,
            )
            return 130
        failed = [rid for rid, s in self.status.items() if s["status"] == "failed"]
        if failed:
            print(
                f"sweep finished with {len(failed)} failed run(s) (see {self.out}/logs/): "
                + ", ".join(failed[:5])
                + (" ..." if len(failed) > 5 else ""),
                file=sys.stderr,
            )
            return 1
        return 0


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][:200] if lines else ""


# ---------------------------------------------------------------- orphans of a killed sweep


def wait_for_orphans(out: Path, timeout: float = 60.0) -> None:
    """A SIGKILLed sweep's children get SIGINT (PDEATHSIG); wait until they are gone before
    redoing their runs, and SIGKILL any still running after `timeout` (only the very processes
    recorded in sweep.json: pid and start time)."""
    state = sweepstate.read(out) or sweepstate.SweepState()
    procs = [
        (e.pid, e.pid_start) for e in state.runs if e.status == "running" and isinstance(e.pid, int)
    ]
    procs = [(pid, start) for pid, start in procs if is_alive(pid, start)]
    deadline = time.monotonic() + timeout
    while procs and time.monotonic() < deadline:
        time.sleep(0.2)
        procs = [(pid, start) for pid, start in procs if is_alive(pid, start)]
    for pid, _ in procs:
        log.warning(
            "run process %d of an earlier sweep still alive after %.0f s: SIGKILL", pid, timeout
        )
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(pid, signal.SIGKILL)
