"""The sweep's rules for runs that missed step deadlines or were not faithful: a pure
`decide(outcome, state)`.

Theory of operation. A run records the fraction of step deadlines it missed, its fidelity
verdict (testbed.run.fidelity: whether its plans and timers came late in emulated time), and
how much of its misses fell in host stalls (testbed.run.stalls: the machine itself stopped, so
no slower clock would have helped). When a run ends, the sweep (testbed.sweep.command, the
mechanism) describes it as an `Outcome`, hands it with the sweep's `State` to `decide`, and
applies the `Decision`: the new state, the back-off records for sweep.json, whether to
redo the run, and the words for the progress line. `decide` reads no clock, does no IO
and changes nothing it is given.

The rules, in the order they are tried (each is cited at its branch below):

1. A run that missed at most DEADLINE_MISS_LIMIT of its deadlines is kept; nothing changes.
2. Over the limit, but within it once the misses in host stalls are left out: the host,
   not the load, is to blame. The time scale is kept; the run is redone (at most 3
   attempts) only if it missed more than REDO_MISS in all or was not faithful, else kept
   as it is.
3. Over the limit outside stalls while another run's tail (its teardown, after its steps:
   testbed.sweep.runner) overlapped this run's set-up or steps: runs of this team size
   overlap tails no more (a large team, short of CPU, may suffer from a tail that a lone
   robot does not notice); redo (2 attempts). The overlap is the cheapest thing to give
   up, so it goes first.
4. Over the limit outside stalls while another run shared the machine, under a load limit
   or a cpu limit (or both): each limit falls to 80% of the most of its measure that was in
   flight while this run ran, the load limit below the load seen, the cpu limit below the
   estimated cores seen (testbed.sweep.cores); redo (2 attempts). Once the cpu limit is
   below what two runs need, the sweep runs one at a time.
5. The same without either limit, when more than one run was allowed at its start: one run
   fewer at a time; redo (2 attempts).
6. Over the limit outside stalls while alone: the machine is slower than the sweep file's
   time scales assume (a shared machine varies). Later runs of this team size get their
   time scale multiplied by SLOWDOWN (down to MIN_SCALE_FACTOR of the file's), and this
   run is redone (3 attempts) if it missed more than REDO_MISS, else kept (an unfaithful
   one is redone once, at the lowest factor too). Only this team
   size: a small team is bound by the latency of a step's round trip, a large one by CPU,
   so one says little about the other; each finds its own scale.
7. Within the limit, but not faithful (testbed.run.fidelity: plans applied late, timers
   late): the load made emulated time run ahead of the work, as with missed deadlines, so
   rules 3 to 6 apply as they would to a late run, and the run is redone once (2 attempts)
   at the backed-off scale or concurrency: its results changed with the dilation.
8. A faithful run of a slowed-down team size that missed at most CLEAN_MISS outside stalls
   counts as clean; after CLEAN_RUNS_TO_SPEED_UP clean runs since the last change the factor goes
   back up a notch (divided by SLOWDOWN, never past the team size's ceiling: the file's
   scale, or what calibration found). Before stalls were told apart, a ratchet that needed
   6 runs under 0.3% to speed up again took the paper sweep's team sizes down to 0.44-0.72
   of the file's scales (2026-11-22).
9. A clean run (as in rule 8) of a team size that gave up the overlap counts towards taking
   it up again: after CLEAN_RUNS_TO_SPEED_UP clean runs since rule 3 fired for it, doubled
   for each time rule 3 fired for it before, its runs start beside tails again. Rule 3 blames
   the overlap for any late run that had one, host noise included (on a noisy evening it
   gave up the overlap for 7 of 10 team sizes); this way a false blame costs a few runs, and
   a true one, tried again ever more rarely, a redo each time.

Pre-start (testbed.sweep.runner: the next run prepared, its network up and its processes
connected while this one steps, its own steps held at a start gate) has two rules of the same
pattern, tried right after their namesakes:

3a. Over the limit outside stalls (or not faithful, as in rule 7) while the next run was
   pre-starting beside its steps: no run is pre-started beside a run of this team size any
   more; redo (2 attempts). Tried after rule 3 (a run that had both gives up the overlap
   first) and before rules 4 to 6.
9a. A clean run of a team size that gave up pre-start counts towards taking it up again,
   with rule 9's counts (CLEAN_RUNS_TO_SPEED_UP, doubled for each time rule 3a fired for it
   before).

Calibration (`testbed sweep --calibrate`, for a machine the file's scales were not made
for): before a team size's first run, short runs alone at the file's scale times a factor;
`calibration_next` says which factor to try next from the trials so far, and
`calibrated` which one to keep: up by 1/SLOWDOWN per trial while runs stay clean and
faithful (up to MAX_SCALE_FACTOR), down by SLOWDOWN while they miss over the limit or are
not faithful; the team's factor and ceiling become the last clean, faithful factor. A
trial is (factor, miss outside stalls, faithful); a pair (factor, miss) is a faithful one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TypeGuard

DEADLINE_MISS_LIMIT = 0.01
SLOWDOWN = 0.85  # time scale factor applied when a run alone misses over the limit
MIN_SCALE_FACTOR = 0.25
REDO_MISS = 0.05  # a run alone that missed more than this is redone (slower); less is kept
CLEAN_MISS = 0.005  # a run this clean counts towards speeding up again
CLEAN_RUNS_TO_SPEED_UP = 3
LOAD_BACKOFF = 0.8  # rule 4: the new load (or cpu) limit, as a share of what the late run saw
MAX_SCALE_FACTOR = 4.0  # calibration may take a team size up to 4 times the file's scale


@dataclass(frozen=True)
class Outcome:
    """What a finished run reported, and how it ran."""

    robots: int
    miss: float | None  # deadline_miss_fraction (None: the run did not say)
    miss_outside_stalls: float | None
    shared: bool = False  # another run was in flight at some time during this one
    overlapped: bool = False  # another run's tail overlapped its set-up or steps
    prestarted_beside: bool = False  # the next run was pre-started beside its steps
    load_seen: float = 0.0  # the most load in flight while it ran (testbed.sweep.plan.run_load)
    cpu_seen: float = 0.0  # the most estimated cores in flight while it ran (testbed.sweep.cores)
    jobs_at_start: int = 1  # the concurrency allowed when it started
    attempts: int = 1  # how many times it has been started, this one included
    faithful: bool | None = None  # its fidelity verdict (None: the run did not say)
    fidelity_reason: str = ""  # why not, when not


@dataclass(frozen=True)
class State:
    """What the rules read and change: the sweep's concurrency and per-team-size scales."""

    jobs: int
    load_limit: float | None = None
    cpu_limit: float | None = None  # cores
    scale_factors: dict[int, float] = field(default_factory=dict)  # robots -> factor
    clean_runs: dict[int, int] = field(default_factory=dict)  # robots -> clean runs since
    ceilings: dict[int, float] = field(default_factory=dict)  # robots -> highest factor
    no_overlap: frozenset[int] = frozenset()  # team sizes that wait for others' tails
    overlap_clean: dict[int, int] = field(default_factory=dict)  # robots -> clean runs since
    overlap_strikes: dict[int, int] = field(default_factory=dict)  # robots -> rule 3 firings
    no_prestart: frozenset[int] = frozenset()  # team sizes no run is pre-started beside
    prestart_clean: dict[int, int] = field(default_factory=dict)  # robots -> clean runs since
    prestart_strikes: dict[int, int] = field(default_factory=dict)  # robots -> rule 3a firings

    def factor(self, robots: int) -> float:
        return self.scale_factors.get(robots, 1.0)

    def ceiling(self, robots: int) -> float:
        return self.ceilings.get(robots, 1.0)


@dataclass(frozen=True)
class Decision:
    state: State  # the sweep's state from now on
    backoffs: tuple[dict, ...] = ()  # records for sweep.json (the sweep adds the run id)
    redo: bool = False  # run it again (it goes to the head of the queue)
    words: str = ""  # appended to the run's line in the progress display


def _number(x: object) -> TypeGuard[float]:
    return isinstance(x, int | float)


def _back_off(o: Outcome, state: State, change: dict, what: str, attempts: int) -> Decision:
    """A back-off: recorded, and the run redone unless it has had `attempts` already."""
    redo = o.attempts < attempts
    words = f"; {what}" + (", redoing it" if redo else "")
    record = {"deadline_miss_fraction": o.miss, **change}
    if o.faithful is False:
        record["faithful"] = False
    return Decision(state, (record,), redo, words)


def _lower_limits(o: Outcome, state: State) -> Decision:
    """Rule 4: each limit the sweep has falls below what this shared run saw in flight (the
    run could not tell which of them was too high), never up."""
    change: dict = {}
    words = []
    if state.load_limit is not None:
        change["load_limit"] = round(min(state.load_limit, LOAD_BACKOFF * o.load_seen), 1)
        words.append(f"load limit down to {change['load_limit']:g}")
    if state.cpu_limit is not None:
        change["cpu_limit"] = round(min(state.cpu_limit, LOAD_BACKOFF * o.cpu_seen), 2)
        words.append(f"cpu limit down to {change['cpu_limit']:g} cores")
    return _back_off(o, replace(state, **change), change, ", ".join(words), attempts=2)


def _relieve(o: Outcome, state: State) -> Decision:
    """Rules 3 to 6: no overlap of tails, no pre-start beside it (3a), less load (a lower
    load or cpu limit, fewer jobs) or, alone, a lower time scale for this team size; an
    unfaithful run is redone at least once."""
    n, miss = o.robots, o.miss
    limited = state.load_limit is not None or state.cpu_limit is not None
    if o.overlapped and n not in state.no_overlap:
        # Rule 3: another run's tail overlapped it: none for its team size, this run again.
        alone = replace(
            state,
            no_overlap=state.no_overlap | {n},
            overlap_clean={**state.overlap_clean, n: 0},
            overlap_strikes={**state.overlap_strikes, n: state.overlap_strikes.get(n, 0) + 1},
        )
        return _back_off(
            o, alone, {"robots": n, "overlap": False},
            f"teams of {n} no longer start during another run's teardown", attempts=2,
        )  # fmt: skip
    if o.prestarted_beside and n not in state.no_prestart:
        # Rule 3a: the next run was pre-started beside its steps: none beside this team size.
        alone = replace(
            state,
            no_prestart=state.no_prestart | {n},
            prestart_clean={**state.prestart_clean, n: 0},
            prestart_strikes={**state.prestart_strikes, n: state.prestart_strikes.get(n, 0) + 1},
        )
        return _back_off(
            o, alone, {"robots": n, "prestart": False},
            f"no run is pre-started beside teams of {n} any more", attempts=2,
        )  # fmt: skip
    if limited and o.shared:
        # Rule 4: shared under a load or cpu limit: the limits fall below what this run saw.
        return _lower_limits(o, state)
    if not limited and o.jobs_at_start > 1:
        # Rule 5: shared by job count: one run fewer at a time.
        jobs = max(1, min(state.jobs, o.jobs_at_start) - 1)
        return _back_off(o, replace(state, jobs=jobs), {"jobs": jobs},
                         f"concurrency down to {jobs}", attempts=2)  # fmt: skip
    if not o.shared and state.factor(n) > MIN_SCALE_FACTOR:
        # Rule 6: alone and still late: this team size slows down, this run again if bad.
        new = max(MIN_SCALE_FACTOR, state.factor(n) * SLOWDOWN)
        slower = replace(
            state,
            scale_factors={**state.scale_factors, n: new},
            clean_runs={**state.clean_runs, n: 0},
        )
        bad = _number(miss) and miss > REDO_MISS
        return _back_off(
            o, slower, {"robots": n, "time_scale_factor": round(new, 3)},
            f"time scales of teams of {n} down to {new:.0%} of the file's",
            attempts=3 if bad else 2 if o.faithful is False else 1,
        )  # fmt: skip
    if o.faithful is False:
        # Rule 6 at the lowest factor: nothing left to relieve, but its results changed.
        return _back_off(o, state, {"robots": n}, "at the lowest time scale", attempts=2)
    return Decision(state)


def decide(o: Outcome, state: State) -> Decision:
    """What the sweep does about a finished run (the rules of the module docstring)."""
    n, miss, ours = o.robots, o.miss, o.miss_outside_stalls
    d = Decision(state)
    if _number(miss) and miss > DEADLINE_MISS_LIMIT:
        words = f", missed {miss:.1%} of step deadlines"
        if _number(ours) and ours < miss:
            words += f" ({miss - ours:.1%} in host stalls)"
        if _number(ours) and ours <= DEADLINE_MISS_LIMIT:
            # Rule 2: the host's stalls, not the load: the scale stays; redo only a bad run.
            if miss > REDO_MISS or o.faithful is False:
                d = _back_off(o, state, {"in_host_stalls": True},
                              "the host's stalls, time scale kept", attempts=3)  # fmt: skip
        else:
            d = _relieve(o, state)  # rules 3 to 6
        d = replace(d, words=words + d.words)
    elif o.faithful is False:
        # Rule 7: in time but not faithful: relieved as a late run would be, redone once.
        words = ", not faithful" + (f" ({o.fidelity_reason})" if o.fidelity_reason else "")
        d = _relieve(o, state)
        d = replace(d, words=words + d.words)
    clean = _number(ours) and ours <= CLEAN_MISS and o.faithful is not False
    if clean:
        d = _prestart_again(n, _overlap_again(n, _speed_up(n, d)))
    return d


def _speed_up(n: int, d: Decision) -> Decision:
    """Rule 8, after a clean run of team size n."""
    s = d.state
    if s.factor(n) < s.ceiling(n):
        # Rule 8: a clean run of a slowed-down size; enough of them speed it up a notch.
        runs = s.clean_runs.get(n, 0) + 1
        if runs < CLEAN_RUNS_TO_SPEED_UP:
            return replace(d, state=replace(s, clean_runs={**s.clean_runs, n: runs}))
        up = min(s.ceiling(n), s.factor(n) / SLOWDOWN)
        faster = replace(
            s, scale_factors={**s.scale_factors, n: up}, clean_runs={**s.clean_runs, n: 0}
        )
        return replace(
            d,
            state=faster,
            backoffs=d.backoffs + ({"robots": n, "time_scale_factor": up},),
            words=d.words + f"; time scales of teams of {n} up to {up:.0%}",
        )
    return d


def _overlap_again(n: int, d: Decision) -> Decision:
    """Rule 9, after a clean run of team size n: enough of them since rule 3 fired for it
    (more each time it fired) and its runs start beside tails again."""
    s = d.state
    if n not in s.no_overlap:
        return d
    runs = s.overlap_clean.get(n, 0) + 1
    if runs < CLEAN_RUNS_TO_SPEED_UP * 2 ** (s.overlap_strikes.get(n, 1) - 1):
        return replace(d, state=replace(s, overlap_clean={**s.overlap_clean, n: runs}))
    again = replace(s, no_overlap=s.no_overlap - {n}, overlap_clean={**s.overlap_clean, n: 0})
    return replace(
        d,
        state=again,
        backoffs=d.backoffs + ({"robots": n, "overlap": True},),
        words=d.words + f"; teams of {n} start during another run's teardown again",
    )


def _prestart_again(n: int, d: Decision) -> Decision:
    """Rule 9a, after a clean run of team size n: enough of them since rule 3a fired for it
    (more each time it fired) and runs are pre-started beside its runs again."""
    s = d.state
    if n not in s.no_prestart:
        return d
    runs = s.prestart_clean.get(n, 0) + 1
    if runs < CLEAN_RUNS_TO_SPEED_UP * 2 ** (s.prestart_strikes.get(n, 1) - 1):
        return replace(d, state=replace(s, prestart_clean={**s.prestart_clean, n: runs}))
    again = replace(s, no_prestart=s.no_prestart - {n}, prestart_clean={**s.prestart_clean, n: 0})
    return replace(
        d,
        state=again,
        backoffs=d.backoffs + ({"robots": n, "prestart": True},),
        words=d.words + f"; runs are pre-started beside teams of {n} again",
    )


Trial = tuple  # (factor, miss outside stalls[, faithful]): a calibration run's outcome


def _faithful(trial: Trial) -> bool:
    return len(trial) < 3 or trial[2] is not False


def _clean(trial: Trial) -> bool:
    """Clean: at most CLEAN_MISS of its deadlines missed, and faithful."""
    return trial[1] <= CLEAN_MISS and _faithful(trial)


def _within(trial: Trial) -> bool:
    """Within the limit: at most DEADLINE_MISS_LIMIT missed, and faithful."""
    return trial[1] <= DEADLINE_MISS_LIMIT and _faithful(trial)


def calibration_next(trials: list[Trial]) -> float | None:
    """The next factor to try, from the trials so far (in the order they ran), or None when
    calibration is over."""
    if not trials:
        return 1.0
    factor = trials[-1][0]
    if _clean(trials[0]):  # going up: until a trial misses or is not faithful, or the top
        if not _clean(trials[-1]) or factor >= MAX_SCALE_FACTOR:
            return None
        return min(MAX_SCALE_FACTOR, factor / SLOWDOWN)
    if _within(trials[0]):
        return None  # within the limit at the file's scale: keep it
    if _clean(trials[-1]) or factor <= MIN_SCALE_FACTOR:  # going down: until clean
        return None
    return max(MIN_SCALE_FACTOR, factor * SLOWDOWN)


def calibrated(trials: list[Trial]) -> float:
    """The factor calibration keeps: the highest that ran clean (and faithful); if none
    did, the file's scale when it stayed within the limit, else the lowest tried."""
    clean = [t[0] for t in trials if _clean(t)]
    if clean:
        return max(clean)
    within = [t[0] for t in trials if _within(t)]
    return max(within) if within else min((t[0] for t in trials), default=1.0)
