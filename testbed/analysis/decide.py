"""Deciding the paper's claims: a two-stage design that plans the runs each undecided
comparison needs and judges it on fresh runs, at a stated error rate.

Theory of operation. The report's verdicts (testbed.analysis.verdicts) rest on comparisons
of two points' mean exploration steps (a *point*: one laser range, communication range and
team size of the paper's main variant). With the paper's 3 runs a point many comparisons
are "within the noise", and which side of the noise a comparison falls on changes between
sweeps. This module decides them in two stages:

1. **Stage 1** is the sweep already run (the paper's 3 runs a point). Each comparison the
   report's claims rest on (the same ones: verdicts.team_groups, rise_groups and rise_pair,
   range_pairs, laser_pairs) is tested with Welch's two-sample t test (two-sided), and a
   claim's comparisons together by Holm's step-down procedure at level alpha1 = alpha / 5.
   A comparison significant there is decided: "holds" when the point the claim says needs
   more steps does, "does not hold" when it needs significantly fewer.
2. **The plan.** Every other comparison (undecided, or a point with one run) is planned
   from stage 1's spread: s, the two points' pooled standard deviation
   (sqrt((s1^2 + s2^2) / 2)), and d, the difference to find: stage 1's difference, or
   MIN_EFFECT (5%) of the two points' mean steps when that is larger (a smaller
   difference would take hundreds of runs, and a difference that small is not what the
   paper's claims are about). Its stage-2 runs a point are the fewest n >= 2 with power
   `power` (default 0.8) for a two-sided t test at alpha2 / m, where alpha2 = alpha - alpha1
   and m is the number of the claim's comparisons planned (Holm's strictest threshold, so
   the power is at least that). Power: the shifted-t approximation,
   P(T(f) > t(1 - a/2, f) - (d / s) sqrt(n / 2)), at f = 1.5 (n - 1) degrees of freedom:
   Welch's test has between n - 1 and 2n - 2, and at 2n - 2 the approximation promised 80%
   where simulated Welch tests found 62-74% at 4-6 runs; at 1.5 (n - 1) it is within 0.03
   of them, on the safe side below 6 runs (tests/unit/test_decide_error_rate.py checks it).
   A comparison needing over
   MAX_PLAN_RUNS runs a point is left undecided as beyond reach. A point that two
   comparisons share runs the larger of their numbers.
3. **The budget** (runs, or wall seconds: each run's expected wall time is the mean
   `wall_time_s` of the point's stage-1 runs, else of its team size's, else of all, the
   runs going one at a time as the paper's sweep does) is filled greedily, the comparison
   with the smallest added cost first, so that it decides as many comparisons as it can;
   what does not fit is named, with the runs it would need.
4. **Stage 2** runs only the planned points (a fresh sweep, seeds other than stage 1's:
   `python -m testbed.analysis.decide PLAN` writes its sweep files). Each planned
   comparison is judged **on stage-2 runs alone** by Welch's t test, a claim's planned
   comparisons together by Holm at alpha2 (m: those the budget kept). Stage 1's data only
   chose which comparisons to run and how many runs, both fixed before stage 2 ran, so
   looking at stage 1 does not bias stage 2's tests; that also holds for the rise, whose
   pair (the interior team size with the fewest steps, and the largest) is chosen on
   stage 1 and tested on stage 2.

Error rate. For each claim, the chance that any of its comparisons gets a verdict
("holds" or "does not hold") that the truth does not support, i.e. any verdict at all
where the two points do not differ, is at most alpha (default 5%): at most alpha1 at stage
1 plus at most alpha2 at stage 2 (Holm controls the family-wise error rate at its level
under any dependence between comparisons, and comparisons that share a point are
dependent; a union bound joins the stages). Holm rather than Bonferroni: the same guarantee,
never fewer verdicts. At stage 1 the rise's pair is chosen on the very data it is tested on
(the interior point with the fewest steps), so its p-value is multiplied by the number of
interior team sizes it was chosen among (Bonferroni over the candidates) before Holm. The
tests assume each point's mean steps is close to normal over runs; the rate was checked in
a simulation with normal and skewed steps (tests/unit/test_decide_error_rate.py). The power
is the planned one for a true difference of the planned size and a spread as stage 1
measured it; stage 1's spread rests on 2 x 3 runs, so the power achieved over repeated
experiments is lower than planned when the spread was underestimated (the simulation
measures it too).

Verdicts are per comparison (`Decision`: runs, test, p-value, the alpha it was judged at
after the correction, its stage-1 verdict and whether stage 2 changed it); a claim holds when
every comparison holds, does not hold when none does and all are decided, partly holds when
decided ones disagree, and is undecided otherwise. The report (`testbed report`) does not
read stage 2 yet: `python -m testbed.analysis.decide JUDGE` prints the verdicts.

Not decided here: the shorter laser's "same steps-to-team ratio" (a bound on a spread of
ratios, not a comparison of two points) and Section 5.2's plan-generation claims.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tomllib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from common.errors import UsageError
from common.jsonfile import write_atomic
from testbed.analysis import middlewares, stats, tables, verdicts
from testbed.analysis.runs import FinishedRun, load_runs
from testbed.analysis.tables import Fig2Row
from testbed.run.config import OPTIONS, RunConfig
from testbed.run.options import GRID, RUN
from testbed.sweep import file as sweepfile
from testbed.sweep import state as sweepstate

ALPHA = 0.05
POWER = 0.8
STAGE1_SHARE = 0.2  # of alpha, spent on the verdicts stage 1 already makes
MIN_EFFECT = 0.05  # the smallest difference planned for, of the two points' mean steps
MAX_PLAN_RUNS = 1000  # runs a point beyond which a comparison is out of reach
MIN_RUNS = 2  # runs a point needs for a t test (its spread)

HOLDS, FAILS, UNDECIDED = verdicts.HOLDS, verdicts.FAILS, "undecided"
TEST = "Welch's two-sample t test, two-sided"

Point = tuple[float, float, int]  # (laser range, communication range, team size)
Data = Mapping[Point, Sequence[float]]  # each point's exploration steps, run by run

# The claims decided here: key -> the report's wording (its verdict functions' own).
CLAIMS = {
    "team": verdicts.verdict_team_beats_one([]).claim,
    "rise": verdicts.verdict_fall_then_rise([]).claim,
    "range": verdicts.verdict_smaller_range([]).claim,
    "laser": verdicts.verdict_shorter_laser([]).claim + " (more steps)",
}


@dataclass(frozen=True)
class Comparison:
    """Two points a claim compares: it says `more` needs more steps than `fewer`."""

    claim: str  # a key of CLAIMS
    where: str
    more: Point
    fewer: Point
    candidates: int = 1  # comparisons stage 1 chose it among (the rise's interior sizes)


@dataclass(frozen=True)
class Test:
    """One comparison tested on one stage's runs."""

    runs: tuple[int, int]  # runs at (more, fewer)
    diff: float  # mean steps of `more` minus `fewer`
    t: float
    df: float
    p: float
    alpha: float  # the threshold p was judged against, after the correction
    verdict: str  # HOLDS, FAILS or UNDECIDED

    def words(self) -> str:
        return (f"{self.runs[0]}+{self.runs[1]} runs, difference {self.diff:+.0f} steps, "
                f"t = {self.t:.2f} ({self.df:.1f} df), p = {_p(self.p)} "
                f"(alpha {_p(self.alpha)}) -> {self.verdict}")  # fmt: skip


@dataclass(frozen=True)
class Planned:
    """A comparison after stage 1: its stage-1 test and the stage-2 runs it needs."""

    comparison: Comparison
    stage1: Test | None  # None when a point has fewer than MIN_RUNS runs
    runs: int | None = None  # stage-2 runs a point; None: decided, or no plan possible
    why: str = ""  # why these runs (or none)
    in_budget: bool = False

    @property
    def decided(self) -> bool:
        return self.stage1 is not None and self.stage1.verdict != UNDECIDED


@dataclass(frozen=True)
class Plan:
    alpha: float
    power: float
    alpha1: float
    alpha2: float
    items: tuple[Planned, ...]
    point_runs: dict[Point, int]  # stage-2 runs per point (within the budget)
    wall_s: dict[Point, float]  # the expected wall seconds of a run at each point
    budget: str  # how it was capped, in words

    def family(self, claim: str) -> list[Planned]:
        """The claim's comparisons stage 2 tests (Holm's family there)."""
        return [p for p in self.items if p.comparison.claim == claim and p.in_budget]

    @property
    def total_runs(self) -> int:
        return sum(self.point_runs.values())

    @property
    def total_wall_s(self) -> float:
        return sum(n * self.wall_s.get(pt, 0.0) for pt, n in self.point_runs.items())


@dataclass(frozen=True)
class Decision:
    """A comparison's final verdict."""

    planned: Planned
    stage2: Test | None
    final: str
    note: str = ""

    @property
    def stage1_verdict(self) -> str:
        return self.planned.stage1.verdict if self.planned.stage1 else UNDECIDED

    @property
    def changed(self) -> bool:
        return self.final != self.stage1_verdict

    @property
    def test(self) -> Test | None:
        return self.stage2 if self.stage2 is not None else self.planned.stage1


# ------------------------------------------------------------------ comparisons


def _pt(row: Fig2Row) -> Point:
    return row.laser_range, row.comm_range, row.robots


def _g(x: float) -> str:
    return f"{x:g}"


def _p(p: float) -> str:
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"


def comparisons(fig2: list[Fig2Row]) -> list[Comparison]:
    """The comparisons the claims rest on, in the report's order (testbed.analysis.verdicts'
    definitions), for one variant's Fig. 2 points."""
    out = []
    for (laser, comm), pts in verdicts.team_groups(fig2):
        for n in sorted(pts):
            if n > 1:
                out.append(Comparison("team", f"laser {_g(laser)} m, range {_g(comm)} m: 1 "
                                      f"robot vs {n}", _pt(pts[1]), _pt(pts[n])))  # fmt: skip
    for (laser, comm), pts in verdicts.rise_groups(fig2):
        best, largest = verdicts.rise_pair(pts)
        inner = sum(1 for n in pts if min(pts) < n < max(pts))
        out.append(Comparison("rise", f"laser {_g(laser)} m, range {_g(comm)} m: {largest} "
                              f"robots vs {best}", _pt(pts[largest]), _pt(pts[best]),
                              candidates=inner))  # fmt: skip
    for (laser, robots), small, large in verdicts.range_pairs(fig2):
        out.append(Comparison("range", f"laser {_g(laser)} m, {robots} robots: range "
                              f"{_g(small.comm_range)} m vs {_g(large.comm_range)} m",
                              _pt(small), _pt(large)))  # fmt: skip
    for (comm, robots), short, long_ in verdicts.laser_pairs(fig2):
        out.append(Comparison("laser", f"range {_g(comm)} m, {robots} robots: laser "
                              f"{_g(short.laser_range)} m vs {_g(long_.laser_range)} m",
                              _pt(short), _pt(long_)))  # fmt: skip
    return out


def samples(fig2: list[Fig2Row]) -> dict[Point, tuple[float, ...]]:
    """Each point's exploration steps, run by run."""
    return {_pt(r): tuple(r.steps_per_run) for r in fig2}


# ------------------------------------------------------------------ tests


def holm(ps: Sequence[float], alpha: float) -> list[tuple[float, bool]]:
    """Holm's step-down procedure: for each p-value (in the given order) the threshold it is
    judged against, alpha / (m - rank), and whether it is rejected (every smaller p was)."""
    m = len(ps)
    out: list[tuple[float, bool]] = [(alpha, False)] * m
    going = True
    for rank, i in enumerate(sorted(range(m), key=lambda i: ps[i])):
        threshold = alpha / (m - rank)
        going = going and ps[i] <= threshold
        out[i] = (threshold, going)
    return out


def _tests(
    comps: Sequence[Comparison], data: Data, alpha: float,
    chosen: bool,
) -> list[Test | None]:  # fmt: skip
    """Welch's test of each comparison on `data`, the comparisons together by Holm at
    `alpha`; a rise chosen on the same data (`chosen`) has its p multiplied by its candidates.
    None where a point has fewer than MIN_RUNS runs (it counts in m all the same)."""
    raw: list[tuple[float, float, float, float] | None] = []
    for c in comps:
        a, b = data.get(c.more, ()), data.get(c.fewer, ())
        if len(a) < MIN_RUNS or len(b) < MIN_RUNS:
            raw.append(None)
            continue
        t, df, p = stats.welch(list(a), list(b))
        raw.append((statistics.fmean(a) - statistics.fmean(b), t, df, p))
    factor = [c.candidates if chosen else 1 for c in comps]
    ps = [1.0 if r is None else min(1.0, r[3] * k) for r, k in zip(raw, factor, strict=True)]
    out: list[Test | None] = []
    for c, r, k, (threshold, rejected) in zip(comps, raw, factor, holm(ps, alpha), strict=True):
        if r is None:
            out.append(None)
            continue
        diff, t, df, p = r
        verdict = UNDECIDED if not rejected else HOLDS if diff > 0 else FAILS
        runs = (len(data[c.more]), len(data[c.fewer]))
        out.append(Test(runs, diff, t, df, p, threshold / k, verdict))
    return out


def _by_claim(comps: Sequence[Comparison]) -> dict[str, list[int]]:
    out: dict[str, list[int]] = {}
    for i, c in enumerate(comps):
        out.setdefault(c.claim, []).append(i)
    return out


def screen(comps: Sequence[Comparison], data: Data, alpha1: float) -> list[Test | None]:
    """Stage 1: each comparison tested on the stage-1 runs, each claim's by Holm at alpha1."""
    out: list[Test | None] = [None] * len(comps)
    for idx in _by_claim(comps).values():
        for i, test in zip(idx, _tests([comps[i] for i in idx], data, alpha1, True), strict=True):
            out[i] = test
    return out


# ------------------------------------------------------------------ planning


def power_of(n: int, effect: float, alpha: float) -> float:
    """The power of Welch's two-sided test at `alpha` with n runs a point and a true
    difference of `effect` standard deviations: the shifted-t approximation at 1.5 (n - 1)
    degrees of freedom (see the module docstring)."""
    df = 1.5 * (n - 1)
    crit = stats.t_quantile(1 - alpha / 2, df)
    shift = abs(effect) * math.sqrt(n / 2)
    return (1 - stats.t_cdf(crit - shift, df)) + stats.t_cdf(-crit - shift, df)


def runs_for_power(effect: float, alpha: float, power: float) -> int | None:
    """The fewest runs a point (at least MIN_RUNS) for `power` at `alpha` and a difference of
    `effect` standard deviations; None beyond MAX_PLAN_RUNS."""
    if effect == 0 or not math.isfinite(effect):
        return None if effect == 0 else MIN_RUNS
    z = statistics.NormalDist()
    za = z.inv_cdf(1 - alpha / 2)
    guess = 2 * ((za + z.inv_cdf(power)) / effect) ** 2  # normal; t needs a few more
    if guess > MAX_PLAN_RUNS:
        return None
    n = max(MIN_RUNS, math.ceil(guess))
    while n > MIN_RUNS and power_of(n - 1, effect, alpha) >= power:  # rarely
        n -= 1
    while power_of(n, effect, alpha) < power:
        n += 1
        if n > MAX_PLAN_RUNS:
            return None
    return n


def _spread(data: Data, c: Comparison) -> tuple[float, float] | None:
    """(difference, pooled sd) of a comparison's stage-1 runs; None when a point has one."""
    a, b = data.get(c.more, ()), data.get(c.fewer, ())
    if len(a) < MIN_RUNS or len(b) < MIN_RUNS:
        return None
    (ma, va), (mb, vb) = stats.mean_var(list(a)), stats.mean_var(list(b))
    return ma - mb, math.sqrt((va + vb) / 2)


def _need(
    c: Comparison, data: Data, cv: float | None, alpha: float,
    power: float,
) -> tuple[int | None, str]:  # fmt: skip
    """The stage-2 runs a point an undecided comparison needs, and why."""
    a, b = data.get(c.more, ()), data.get(c.fewer, ())
    means = [statistics.fmean(x) for x in (a, b) if x]
    level = statistics.fmean(means) if means else 0.0
    spread = _spread(data, c)
    if spread is not None:
        diff, sd = spread
        seen = f"stage 1: difference {diff:+.0f} steps, sd {sd:.0f}"
    elif cv is not None and len(means) == 2:
        diff, sd = means[0] - means[1], cv * level
        seen = f"stage 1: one run at a point; difference {diff:+.0f}, sd {sd:.0f} (the claim's "
        seen += "median spread)"
    else:
        return None, "no runs or no spread at stage 1 to plan from"
    floor = MIN_EFFECT * level
    target = max(abs(diff), floor)
    if sd == 0:
        return MIN_RUNS, seen + "; no spread"
    n = runs_for_power(target / sd, alpha, power)
    what = "the difference seen" if abs(diff) >= floor else f"{MIN_EFFECT:.0%} of the mean"
    if n is None:
        return None, f"{seen}; beyond reach (over {MAX_PLAN_RUNS} runs a point for {what})"
    return n, f"{seen}; power {power:.0%} for {what} at alpha {_p(alpha)}"


def _median_cv(data: Data, pts: Iterable[Point]) -> float | None:
    spreads = [stats.mean_var(list(data[p])) for p in set(pts) if len(data.get(p, ())) >= MIN_RUNS]
    cvs = [math.sqrt(v) / m for m, v in spreads if m > 0]
    return statistics.median(cvs) if cvs else None


def _fill(
    items: list[Planned], cost_of: Callable[[Point], float], budget: float | None
) -> tuple[list[Planned], dict[Point, int]]:
    """The budget, filled greedily: the plannable comparison that adds the least cost first;
    each point runs the most its kept comparisons need."""
    runs: dict[Point, int] = {}
    kept: set[int] = set()
    spent = 0.0

    def added(p: Planned) -> float:
        assert p.runs is not None
        c = p.comparison
        return sum(max(0, p.runs - runs.get(pt, 0)) * cost_of(pt) for pt in {c.more, c.fewer})

    open_ = [i for i, p in enumerate(items) if p.runs is not None]
    while open_:
        i = min(open_, key=lambda i: (added(items[i]), i))
        cost = added(items[i])
        if budget is not None and spent + cost > budget:
            break
        spent += cost
        kept.add(i)
        open_.remove(i)
        c, n = items[i].comparison, items[i].runs
        assert n is not None
        for pt in (c.more, c.fewer):
            runs[pt] = max(runs.get(pt, 0), n)
    out = [replace(p, in_budget=i in kept) for i, p in enumerate(items)]
    return out, runs


def plan(
    comps: Sequence[Comparison],
    data: Data,
    *,
    alpha: float = ALPHA,
    power: float = POWER,
    wall_s: dict[Point, float] | None = None,
    budget_runs: int | None = None,
    budget_s: float | None = None,
) -> Plan:
    """Stage 1 tested (`screen`) and stage 2 planned for the comparisons it left undecided,
    within the budget (runs, or wall seconds by `wall_s`; none: every plannable one)."""
    if not 0 < alpha < 1 or not 0 < power < 1:
        raise ValueError(f"alpha and power are in (0, 1), not {alpha} and {power}")
    if budget_s is not None and wall_s is None:
        raise ValueError("a budget in wall time needs the runs' wall times")
    alpha1 = alpha * STAGE1_SHARE
    alpha2 = alpha - alpha1
    first = screen(comps, data, alpha1)
    items: list[Planned] = []
    for idx in _by_claim(comps).values():
        open_ = [i for i in idx if first[i] is None or first[i].verdict == UNDECIDED]  # type: ignore[union-attr]
        cv = _median_cv(data, [pt for i in idx for pt in (comps[i].more, comps[i].fewer)])
        level = alpha2 / max(1, len(open_))
        for i in idx:
            if i in open_:
                n, why = _need(comps[i], data, cv, level, power)
                items.append(Planned(comps[i], first[i], n, why))
            else:
                items.append(Planned(comps[i], first[i], None, "decided at stage 1"))
    order = {c: k for k, c in enumerate(comps)}
    items.sort(key=lambda p: order[p.comparison])
    walls = wall_s or {}
    if budget_s is not None:
        filled, runs = _fill(items, lambda pt: walls[pt], budget_s)
        budget = f"{budget_s / 60:.0f} minutes of runs, one at a time"
    else:
        filled, runs = _fill(items, lambda pt: 1.0, budget_runs)
        budget = f"{budget_runs} runs" if budget_runs is not None else "none"
    return Plan(alpha, power, alpha1, alpha2, tuple(filled), runs, dict(walls), budget)


# ------------------------------------------------------------------ judging


def judge(p: Plan, data2: Data) -> list[Decision]:
    """The final verdicts: stage 1's where it decided, else stage 2's on its runs alone (each
    claim's kept comparisons by Holm at alpha2)."""
    second: dict[Comparison, Test | None] = {}
    for claim in CLAIMS:
        fam = p.family(claim)
        tests = _tests([x.comparison for x in fam], data2, p.alpha2, False)
        second.update(zip([x.comparison for x in fam], tests, strict=True))
    out = []
    for item in p.items:
        if item.decided:
            assert item.stage1 is not None
            out.append(Decision(item, None, item.stage1.verdict, "decided at stage 1"))
        elif not item.in_budget:
            need = f"needs {item.runs} runs a point" if item.runs else item.why
            word = "over the budget" if item.runs else "not planned"
            out.append(Decision(item, None, UNDECIDED, f"{word}: {need}"))
        else:
            test = second[item.comparison]
            if test is None:
                out.append(Decision(item, None, UNDECIDED, "too few stage-2 runs at a point"))
            else:
                out.append(Decision(item, test, test.verdict, "stage 2"))
    return out


def claim_verdict(decisions: Sequence[Decision]) -> str:
    """A claim over its comparisons' final verdicts (see the module docstring)."""
    finals = [d.final for d in decisions]
    if not finals:
        return verdicts.NO_DATA
    if HOLDS in finals and FAILS in finals:
        return verdicts.PARTLY
    if UNDECIDED in finals:
        return f"undecided ({finals.count(UNDECIDED)} of {len(finals)} comparisons)"
    return HOLDS if HOLDS in finals else FAILS


# ------------------------------------------------------------------ a sweep directory


def paper_rows(runs: list[FinishedRun]) -> list[Fig2Row]:
    """The Fig. 2 points the report's verdicts are decided on: the main network, messaging
    and variant's (as testbed.analysis.figures.make_all selects them)."""
    network = tables.main_network(runs)
    messaging = middlewares.main_messaging(runs)
    runs = [r for r in runs if r.network == network
            and (middlewares.middleware_of(r), middlewares.failure_of(r)) == messaging]  # fmt: skip
    main = tables.main_variant(runs)
    return [r for r in tables.fig2_rows(runs) if r.variant == main]


def wall_times(runs: list[FinishedRun], points: Iterable[Point]) -> dict[Point, float]:
    """The expected wall seconds of a run at each point: the mean `wall_time_s` of its runs,
    else of its team size's, else of all; empty when no run recorded one."""
    by_point: dict[Point, list[float]] = {}
    for r in runs:
        if r.wall_time_s is not None and r.wall_time_s > 0:
            c = r.config
            by_point.setdefault((c.laser_range, c.comm_range, c.robots), []).append(r.wall_time_s)
    every = [w for ws in by_point.values() for w in ws]
    if not every:
        return {}
    out = {}
    for pt in points:
        same = by_point.get(pt) or [w for q, ws in by_point.items() if q[2] == pt[2] for w in ws]
        out[pt] = statistics.fmean(same or every)
    return out


@dataclass
class Stage1:
    """A finished sweep read for planning."""

    runs: list[FinishedRun]
    rows: list[Fig2Row]
    comps: list[Comparison] = field(default_factory=list)
    data: dict[Point, tuple[float, ...]] = field(default_factory=dict)


def read_stage1(sweep_dir: Path) -> Stage1:
    if not sweep_dir.is_dir():
        raise UsageError(f"{sweep_dir}: not a directory")
    runs = load_runs(sweep_dir)
    if not runs:
        raise UsageError(f"{sweep_dir}: no finished runs (no runs/*/result.json)")
    rows = paper_rows(runs)
    comps = comparisons(rows)
    if not comps:
        raise UsageError(f"{sweep_dir}: no comparison the paper's claims rest on (too few "
                         "points with usable runs)")  # fmt: skip
    return Stage1(runs, rows, comps, samples(rows))


# ------------------------------------------------------------------ stage 2's sweep files

STAGE2_SEED = 1_000_003  # added to stage 1's base seed (more while a seed would repeat)
_GRID_ONLY = tuple(o for o in OPTIONS if o.sweep == {GRID})
_RUN_ONLY = tuple(o for o in OPTIONS if RUN in o.sweep and o.name != "time_scale")
_POINT = ("robots", "comm_range", "laser_range")


def blocks(point_runs: dict[Point, int]) -> list[tuple[list[Point], int]]:
    """The points with their runs as grids a sweep file can hold (one `runs` a file, its
    points a product of team sizes, ranges and lasers): points of one runs count grouped by
    (laser, range), then groups of the same team sizes merged over ranges, then lasers."""
    by: dict[tuple, set[int]] = {}
    for (laser, comm, robots), n in point_runs.items():
        by.setdefault((n, laser, comm), set()).add(robots)
    by_comm: dict[tuple, set[float]] = {}
    for (n, laser, comm), teams in by.items():
        by_comm.setdefault((n, laser, tuple(sorted(teams))), set()).add(comm)
    by_laser: dict[tuple, set[float]] = {}
    for (n, laser, teams), comms in by_comm.items():
        by_laser.setdefault((n, teams, tuple(sorted(comms))), set()).add(laser)
    out = []
    for (n, teams, comms), lasers in sorted(by_laser.items()):
        pts = [(la, c, r) for la in sorted(lasers, reverse=True) for c in comms for r in teams]
        out.append((pts, n))
    return out


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        if not math.isfinite(v):
            raise ValueError(f"{v} has no TOML form in a sweep file")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a TOML basic string
    raise ValueError(f"{v!r}: not a sweep file value")


def stage2_text(
    pts: list[Point], runs: int, templates: dict[Point, RunConfig], scales: dict[int, float],
    seed: int, title: str,
) -> str:  # fmt: skip
    """A sweep file (testbed.sweep.file's format) of the product grid `pts`, `runs` runs a
    point, every other option as stage 1 ran it (`templates`: a stage-1 run's config at each
    point), each team size's time scale `scales`, and base seed `seed`."""
    t = templates[pts[0]]
    lines = [f"description = {_toml(title)}", "", "[grid]"]
    for name in _POINT:
        values = sorted({getattr(templates[pt], name) for pt in pts},
                        reverse=name == "laser_range")  # fmt: skip
        lines.append(f"{name} = [{', '.join(_toml(v) for v in values)}]")
    for opt in _GRID_ONLY:
        if opt.name not in _POINT and getattr(t, opt.name) != opt.default:
            lines.append(f"{opt.name} = [{_toml(getattr(t, opt.name))}]")
    lines += [f"runs = {runs}", "", "[run]"]
    teams = sorted({pt[2] for pt in pts})
    lines.append("time_scale = { " + ", ".join(f"{n} = {_toml(float(scales[n]))}"
                                              for n in teams) + " }")  # fmt: skip
    for opt in _RUN_ONLY:
        value = getattr(t, opt.name)
        if value is not None and value != opt.default:
            lines.append(f"{opt.name} = {_toml(value)}")
    lines.append(f"seed = {seed}")
    return "\n".join(lines) + "\n"


def _templates(stage1: Stage1, state: sweepstate.SweepState, pts: Iterable[Point]):
    """A stage-1 run's config (as sweep.json planned it) at each point."""
    ids = {_pt(r): r.runs for r in stage1.rows}
    out: dict[Point, RunConfig] = {}
    for pt in pts:
        for rid in ids.get(pt, ()):
            planned = state.run(rid)
            if planned is not None and planned.config is not None:
                out[pt] = RunConfig.from_dict(dict(planned.config))
                break
        else:
            raise UsageError(f"sweep.json plans no run of {_point_name(pt)}")
    return out


def write_stage2(
    p: Plan, stage1: Stage1, sweep_dir: Path, out: Path
) -> list[tuple[Path, list[Point], int]]:
    """Stage 2's sweep files in `out` (stage2-01.toml, ...; one per grid of `blocks`), each
    checked by the sweep file's own parser, their seeds none of stage 1's. Returns (file,
    points, runs a point) for each."""
    state = sweepstate.read(sweep_dir)
    if state is None:
        raise UsageError(f"{sweep_dir}: no sweep.json (not a sweep directory)")
    templates = _templates(stage1, state, p.point_runs)
    by_file = state.spec.get("time_scale_by_robots") or {}
    scales = {pt[2]: float(by_file.get(str(pt[2]), t.time_scale)) for pt, t in templates.items()}
    used = {r.config.get("seed") for r in state.runs if r.config}
    base = state.spec.get("seed") or 0
    base = (base if isinstance(base, int) else 0) + STAGE2_SEED
    grids = blocks(p.point_runs)
    while True:
        texts, seeds = [], []
        for k, (pts, n) in enumerate(grids, start=1):
            title = (f"Stage 2 of deciding the claims of {sweep_dir.name} ({k} of {len(grids)}): "
                     f"{n} runs a point, planned by testbed.analysis.decide")  # fmt: skip
            text = stage2_text(pts, n, templates, scales, base, title)
            spec = sweepfile.parse(tomllib.loads(text), out / f"stage2-{k:02d}.toml")
            seeds += [r.config.seed for r in sweepfile.expand(spec)]
            texts.append(text)
        if not used.intersection(seeds) and len(set(seeds)) == len(seeds):
            break
        base += 1
    if texts:
        out.mkdir(parents=True, exist_ok=True)
    written = []
    for k, (text, (pts, n)) in enumerate(zip(texts, grids, strict=True), start=1):
        path = out / f"stage2-{k:02d}.toml"
        write_atomic(path, text)
        written.append((path, pts, n))
    return written


def _minutes(s: float) -> str:
    m = round(s / 60)
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{max(m, 1) if s else 0} min"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m testbed.analysis.decide",
        description="Plan (PLAN) or judge (JUDGE) the runs that decide the paper's claims.",
    )
    ap.add_argument("action", choices=("PLAN", "JUDGE"))
    ap.add_argument("sweep_dir", type=Path, help="the finished stage-1 sweep directory")
    ap.add_argument("stage2", type=Path, nargs="*", help="JUDGE: the stage-2 sweep directories")
    budget = ap.add_mutually_exclusive_group()
    budget.add_argument("--budget-runs", type=int, metavar="N")
    budget.add_argument("--budget-minutes", type=float, metavar="M")
    ap.add_argument("--power", type=float, default=POWER)
    ap.add_argument("--alpha", type=float, default=ALPHA)
    ap.add_argument("--out", type=Path, help="PLAN: where the stage-2 sweep files go "
                    "(default: SWEEP_DIR-stage2 beside it)")  # fmt: skip
    try:
        args = ap.parse_args(argv)
    except SystemExit as e:
        return int(e.code or 0)
    try:
        return _run(args)
    except (UsageError, ValueError, OSError) as e:
        print(f"decide: {str(e).splitlines()[0] if str(e) else type(e).__name__}",
              file=sys.stderr)  # fmt: skip
        return 2


def _checked(args: argparse.Namespace) -> None:
    if not 0 < args.alpha < 1 or not math.isfinite(args.alpha):
        raise UsageError(f"--alpha must be in (0, 1), not {args.alpha}")
    if not 0 < args.power < 1 or not math.isfinite(args.power):
        raise UsageError(f"--power must be in (0, 1), not {args.power}")
    if args.budget_runs is not None and args.budget_runs < 0:
        raise UsageError(f"--budget-runs must be 0 or more, not {args.budget_runs}")
    if args.budget_minutes is not None and not (
        math.isfinite(args.budget_minutes) and args.budget_minutes >= 0
    ):
        raise UsageError(f"--budget-minutes must be 0 or more, not {args.budget_minutes}")
    if args.action == "PLAN" and args.stage2:
        raise UsageError("PLAN takes one sweep directory (stage 2's are JUDGE's)")
    if args.action == "JUDGE" and not args.stage2:
        raise UsageError("JUDGE needs the stage-2 sweep directories after the stage-1 one")


def make_plan(stage1: Stage1, args: argparse.Namespace) -> Plan:
    walls = wall_times(stage1.runs, stage1.data)
    if args.budget_minutes is not None and not walls:
        raise UsageError(f"{args.sweep_dir}: no run recorded wall_time_s: use --budget-runs")
    minutes = args.budget_minutes
    return plan(stage1.comps, stage1.data, alpha=args.alpha, power=args.power,
                wall_s=walls or None, budget_runs=args.budget_runs,
                budget_s=None if minutes is None else minutes * 60)  # fmt: skip


def _run(args: argparse.Namespace) -> int:
    _checked(args)
    stage1 = read_stage1(args.sweep_dir)
    p = make_plan(stage1, args)
    if args.action == "PLAN":
        out = args.out or args.sweep_dir.parent / f"{args.sweep_dir.name}-stage2"
        files = write_stage2(p, stage1, args.sweep_dir, out)
        print("\n".join(plan_lines(p, files, out)))
        return 0
    runs2 = [r for d in args.stage2 for r in _stage2_runs(d)]
    decisions = judge(p, samples(paper_rows(runs2)))
    print("\n".join(judge_lines(p, decisions)))
    return 0


def _stage2_runs(d: Path) -> list[FinishedRun]:
    if not d.is_dir():
        raise UsageError(f"{d}: not a directory")
    return load_runs(d)


def _point_name(pt: Point) -> str:
    return f"laser {_g(pt[0])} m, range {_g(pt[1])} m, {pt[2]} robots"


def plan_lines(p: Plan, files: Sequence[tuple[Path, list[Point], int]], out: Path) -> list[str]:
    """The plan on one screen: the design, each stage-2 file's points and why, the wall time,
    and what stays undecided."""
    lines = [
        f"Deciding the claims: {TEST}; Holm's correction per claim; alpha {p.alpha:g} "
        f"(stage 1 {p.alpha1:g}, stage 2 {p.alpha2:g}), power {p.power:.0%}; budget {p.budget}.",
    ]
    for claim, text in CLAIMS.items():
        mine = [x for x in p.items if x.comparison.claim == claim]
        if mine:
            done = sum(x.decided for x in mine)
            kept = sum(x.in_budget for x in mine)
            lines.append(f"- {text}: {len(mine)} comparisons, {done} decided at stage 1, "
                         f"{kept} planned")  # fmt: skip
    why: dict[Point, list[str]] = {}
    for x in p.items:
        if x.in_budget:
            for pt in (x.comparison.more, x.comparison.fewer):
                why.setdefault(pt, []).append(f"{x.comparison.claim}: {x.comparison.where}")
    lines.append(f"Stage 2: {p.total_runs} runs at {len(p.point_runs)} points"
                 + (f", about {_minutes(p.total_wall_s)} one at a time" if p.wall_s else "")
                 + ":")  # fmt: skip
    for path, pts, n in files:
        wall = sum(n * p.wall_s.get(pt, 0.0) for pt in pts)
        lines.append(f"  {path.name}: {len(pts)} points x {n} runs"
                     + (f" (~{_minutes(wall)})" if p.wall_s else "") + ": "
                     + "; ".join(f"{_point_name(pt)} [{', '.join(why[pt])}]"
                                 for pt in pts))  # fmt: skip
    left = [x for x in p.items if not x.decided and not x.in_budget]
    if left:
        lines.append(f"Left undecided ({len(left)}):")
        for x in left:
            need = f"needs {x.runs} runs a point" if x.runs else x.why
            lines.append(f"  {x.comparison.claim}: {x.comparison.where}: {need}")
    if files:
        lines.append(f"Run: for f in {out}/stage2-*.toml; do testbed sweep \"$f\" "
                     f"--out {out}/$(basename \"$f\" .toml); done")  # fmt: skip
        lines.append(f"Judge: python -m testbed.analysis.decide JUDGE SWEEP_DIR {out}/stage2-* "
                     "(with this plan's --alpha, --power and budget)")  # fmt: skip
    return lines


def judge_lines(p: Plan, decisions: Sequence[Decision]) -> list[str]:
    lines = [f"{TEST}; Holm per claim; alpha {p.alpha:g} per claim (stage 1 {p.alpha1:g}, "
             f"stage 2 {p.alpha2:g}, on stage-2 runs alone)."]  # fmt: skip
    for claim, text in CLAIMS.items():
        mine = [d for d in decisions if d.planned.comparison.claim == claim]
        if not mine:
            continue
        lines.append(f"{text}: {claim_verdict(mine)}")
        for d in mine:
            test = d.test
            said = test.words() if test else d.note
            change = f" (stage 1: {d.stage1_verdict})" if d.changed else ""
            lines.append(f"  {d.planned.comparison.where}: {d.final}{change}; {d.note}; {said}")
    return lines


if __name__ == "__main__":
    sys.exit(main())
