"""A sweep's schedule while it runs: how many runs at once, each team size's time scale, and
which waiting run starts next (testbed.sweep.runner.Sweep starts and watches the runs).

Theory of operation. `Schedule` holds what the sweep's rules read and change: the concurrency
(--jobs), the load and cpu limits (each as the sweep file asked and as it is now), the factor
each team size's time scale is multiplied by, the clean runs towards speeding a team size up
again, and what --calibrate found. A waiting run gets its team size's factor (`scaled`), is
expected to keep `estimate` cores busy (testbed.sweep.cores, learnt from what the sweep's
finished runs measured: `learn`), and starts when it fits beside the runs in flight
(`next_fitting`: first fit). After a run, testbed.sweep.policy decides from `policy_state`,
and `apply` takes up its decision. Which runs are in their tail (their steps done, their
teardown going on) it reads from the files the runs create (`mark_tails`). While exactly
one run steps, the next may be pre-started beside it (`prestart_next`: it fits once that run
is in its tail), to hold its steps at a start gate until then. Nothing here starts a process.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from testbed.files.resultfile import RunResult
from testbed.files.runconfig import RunConfig
from testbed.sweep import cores as sweepcores
from testbed.sweep import policy as sweeppolicy
from testbed.sweep.file import PlannedRun
from testbed.sweep.plan import run_load


def note_sharing(flying: list) -> None:
    """Runs (testbed.sweep.runner._Child) that step at once now: each notes whether it shared
    the machine and the most load and estimated cores it saw in flight."""
    load = sum(c.load for c in flying)
    cores = sum(c.cores for c in flying)
    for c in flying:
        c.shared = c.shared or len(flying) > 1
        c.load_seen = max(c.load_seen, load)
        c.cpu_seen = max(c.cpu_seen, cores)


class Schedule:
    """The sweep's concurrency and time scales, and which run fits next (module docstring)."""

    def __init__(self, jobs: int, load_limit: float | None, cpu_limit: float | None):
        self.jobs = jobs
        self.jobs_requested = jobs
        self.load_limit = load_limit
        self.load_limit_requested = self.load_limit
        self.cpu_limit = cpu_limit
        self.cpu_limit_requested = self.cpu_limit
        # What the sweep's finished runs measured, for estimating the cores of the next ones,
        # and the cores per unit of load that makes per team size (the queue is scanned every
        # tenth of a second, each median only once per measurement).
        self.measured: list[sweepcores.Measured] = []
        self._rates: dict[int, float] = {}
        # Per team size, applied to its runs' time scales (see Sweep._finish): a large team
        # that runs short of CPU says nothing about a lone robot, which is bound by latency.
        self.scale_factors: dict[int, float] = {}
        self.clean_runs: dict[int, int] = {}
        # --calibrate: per team size, the factor its trials found (also its ceiling), and
        # the trials themselves [(factor, miss outside stalls), ...] for sweep.json.
        self.ceilings: dict[int, float] = {}
        self.calibration: dict[int, list[tuple[float, float, bool]]] = {}
        self.backoffs: list[dict] = []
        # The team sizes whose runs wait for other runs' tails (their teardown, after their
        # steps) to end; the others start beside a tail. The policy adds a team size when
        # one of its runs that overlapped a tail was late, and takes it out again after
        # enough clean runs.
        self.no_overlap: frozenset[int] = frozenset()
        # Per team size without the overlap: its clean runs since, and how often it gave the
        # overlap up (the policy's rule 9 takes it up again after enough clean runs).
        self.overlap_clean: dict[int, int] = {}
        self.overlap_strikes: dict[int, int] = {}
        # No run starts beside a tail at all (the sweep's --view: the run in its tail still
        # serves the live page on the one port).
        self.tails_wait = False
        # Pre-start (testbed.sweep.runner): off for the whole sweep with --no-prestart, and
        # per team size of the run stepping while the next prepares (the policy's rules 3a
        # and 9a, the same pattern as the overlap's).
        self.prestart = True
        self.no_prestart: frozenset[int] = frozenset()
        self.prestart_clean: dict[int, int] = {}
        self.prestart_strikes: dict[int, int] = {}

    @property
    def limited(self) -> bool:
        """Whether runs are packed by a load or cpu limit (not only by --jobs)."""
        return self.load_limit is not None or self.cpu_limit is not None

    def factor(self, robots: int) -> float:
        return self.scale_factors.get(robots, 1.0)

    def scaled(self, run: PlannedRun) -> RunConfig:
        """`run`'s config at the time scale it gets now: the file's times its team size's
        factor (testbed.sweep.policy)."""
        config = run.config
        factor = self.factor(config.robots)
        if factor != 1.0:
            config = replace(config, time_scale=round(config.time_scale * factor, 3))
        return config

    def estimate(self, run: PlannedRun) -> float:
        """The cores `run` is expected to keep busy, at the time scale it gets now
        (testbed.sweep.cores.estimate)."""
        config = self.scaled(run)
        n = config.robots
        if n not in self._rates:
            self._rates[n] = sweepcores.cores_per_load(n, self.measured)
        return self._rates[n] * sweepcores.load(n, config.time_scale)

    def learn(self, result: RunResult) -> None:
        """Learn from a finished run's result what its cores were."""
        measured = sweepcores.measure(result)
        if measured is not None:
            self.measured.append(measured)
            self._rates.clear()

    def mark_tails(self, children: dict, steps_over: Callable[[str], Path]) -> None:
        """Mark the runs whose steps are done (their --steps-over file, `steps_over(run id)`,
        exists) as in their tail; the runs still before or in their steps are then
        overlapped by it, unless their team size waits for tails (then they shared the
        machine with it as they would with any run started beside them)."""
        for child in children.values():
            if child.tail or not steps_over(child.run.run_id).exists():
                continue
            child.tail = True
            for other in children.values():
                if not other.tail and not self.waits_for_tails(other.run):
                    other.overlapped = True

    def waits_for_tails(self, run: PlannedRun) -> bool:
        """Whether `run` waits for every tail to end before it starts: under --view, or
        when its team size gave up the overlap (testbed.sweep.policy, rule 3)."""
        return self.tails_wait or run.config.robots in self.no_overlap

    def beside(self, run: PlannedRun, children: dict) -> list:
        """The runs `run` would start beside: the children (testbed.sweep.runner._Child)
        in flight, those in their tail left out unless its team size waits for tails, or
        more than --jobs tails go on (a teardown that hangs does not let runs pile up)."""
        tails = sum(1 for c in children.values() if c.tail)
        if self.waits_for_tails(run) or tails > self.jobs:
            return list(children.values())
        return [c for c in children.values() if not c.tail]

    def fits(self, run: PlannedRun, children: dict) -> bool:
        """Whether `run` fits beside the runs in flight (`beside`): always when there is
        none; else fewer than --jobs of them, their loads and its own within the load limit,
        their estimated cores and its own within the cpu limit (each when set)."""
        flying = self.beside(run, children)
        if not flying:
            return True
        if len(flying) >= self.jobs:
            return False
        if self.load_limit is not None:
            in_flight = sum(c.load for c in flying)
            if in_flight + run_load(run) > self.load_limit + 1e-9:
                return False
        if self.cpu_limit is not None:
            in_flight = sum(c.cores for c in flying)
            if in_flight + self.estimate(run) > self.cpu_limit + 1e-9:
                return False
        return True

    def next_fitting(self, queue: deque, children: dict) -> PlannedRun | None:
        """Take the first waiting run that fits; None when none fits. A run whose team size
        waits for tails is not overtaken while one ends (a second or so): a redone run
        would otherwise wait for a moment without tails, the sweep's end."""
        for i, run in enumerate(queue):
            if self.fits(run, children):
                del queue[i]
                return run
            if self.waits_for_tails(run) and any(c.tail for c in children.values()):
                return None
        return None

    def prestart_next(self, queue: deque, children: dict) -> tuple[PlannedRun, Any] | None:
        """The waiting run to pre-start now, taken off `queue`, and the child whose steps'
        end opens its start gate; None when none is. Only while exactly one run steps and no
        pre-started run waits, not under --view (tails_wait), not beside a team size that
        gave pre-start up (policy rule 3a) or a run whose last pre-started neighbour's gate
        timed out (`no_prestart_beside`), and only a run that fits once that run is in its
        tail (first fit, as `next_fitting`; a run that waits for tails stops the search)."""
        if not self.prestart or self.tails_wait or not queue:
            return None
        if any(c.gated for c in children.values()):
            return None
        stepping = [c for c in children.values() if not c.tail]
        if len(stepping) != 1:
            return None
        ending = stepping[0]
        if ending.run.config.robots in self.no_prestart or ending.no_prestart_beside:
            return None
        # In its tail it counts as in flight for none but a run that waits for tails, which
        # is then not pre-started (nor overtaken: it would wait for the tail regardless).
        rest = {rid: c for rid, c in children.items() if c is not ending}
        for i, run in enumerate(queue):
            if self.waits_for_tails(run):
                return None
            if self.fits(run, rest):
                del queue[i]
                return run, ending
        return None

    def policy_state(self) -> sweeppolicy.State:
        return sweeppolicy.State(
            jobs=self.jobs,
            load_limit=self.load_limit,
            cpu_limit=self.cpu_limit,
            scale_factors=dict(self.scale_factors),
            clean_runs=dict(self.clean_runs),
            ceilings=dict(self.ceilings),
            no_overlap=self.no_overlap,
            overlap_clean=dict(self.overlap_clean),
            overlap_strikes=dict(self.overlap_strikes),
            no_prestart=self.no_prestart,
            prestart_clean=dict(self.prestart_clean),
            prestart_strikes=dict(self.prestart_strikes),
        )

    def apply(self, d: sweeppolicy.Decision, run_id: str) -> None:
        """Take up what the policy decided after run `run_id`: its state and back-offs."""
        self.jobs, self.load_limit = d.state.jobs, d.state.load_limit
        self.cpu_limit = d.state.cpu_limit
        self.no_overlap = d.state.no_overlap
        self.overlap_clean = dict(d.state.overlap_clean)
        self.overlap_strikes = dict(d.state.overlap_strikes)
        self.no_prestart = d.state.no_prestart
        self.prestart_clean = dict(d.state.prestart_clean)
        self.prestart_strikes = dict(d.state.prestart_strikes)
        self.scale_factors, self.clean_runs = dict(d.state.scale_factors), dict(d.state.clean_runs)
        self.backoffs += [{"run": run_id, **record} for record in d.backoffs]

    def calibrated(self, robots: int, trials: list[tuple[float, float, bool]]) -> float:
        """Take up a team size's calibration trials; returns the factor they found."""
        found = sweeppolicy.calibrated(trials)
        self.calibration[robots], self.ceilings[robots] = trials, found
        self.scale_factors[robots] = found
        return found
