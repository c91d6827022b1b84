"""Deciding the paper's claims: a two-stage design that plans the runs each undecided
comparison needs and judges it on fresh runs, at a stated error rate.

Theory of operation. The report's verdicts (testbed.analysis.verdicts) rest on comparisons
of two points' mean exploration steps (a *point*: one laser range, communication range and
team size of the paper's main variant). With the paper's 3 runs a point many comparisons
are "within the noise", and which side of the noise a comparison falls on changes between
sweeps. This module decides them in two stages:

1. **Stage 1** is the sweep already run (the paper's 3 runs a point), with any sweeps of the
   same design at team sizes past the paper's ten (testbed/experiments/paper-large-teams.toml,
   `PLAN --with DIR`). Each comparison the report's claims rest on (the same ones:
   verdicts.team_groups, rise_groups and rise_pair, range_pairs, laser_pairs; the rise's over
   every team size that ran, the others over the paper's 1-10 alone, as the paper claims
   them) is tested with Welch's two-sample t test (two-sided), and a
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
   `testbed decide PLAN` writes its sweep files, with
   testbed.analysis.decidesweep). Each planned
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

Verdicts are per comparison (`Decision`: runs, test, p-value, its Holm-adjusted p (at most
alpha exactly when Holm rejects), the alpha it was judged at after the correction, its
stage-1 verdict and whether stage 2 changed it); a claim holds when
every comparison holds, does not hold when none does and all are decided, partly holds when
decided ones disagree, and is undecided otherwise. `testbed decide JUDGE`
prints the verdicts; `testbed report` shows them beside the 3-run ones
(testbed.analysis.decidereport) and `testbed compare` of two deciding sweeps sets them side
by side (testbed.analysis.claimcompare).

Not decided here: the shorter laser's "same steps-to-team ratio" (a bound on a spread of
ratios, not a comparison of two points) and Section 5.2's plan-generation claims.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

from testbed.analysis import stats, verdicts
from testbed.analysis.tables import PAPER_MAX_TEAM, Fig2Row

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
    p_holm: float = 1.0  # Holm-adjusted p (candidates included): <= the family's alpha
    # exactly when Holm rejects

    def words(self) -> str:
        return (f"{self.runs[0]}+{self.runs[1]} runs, difference {self.diff:+.0f} steps, "
                f"t = {self.t:.2f} ({self.df:.1f} df), p = {_p(self.p)}, Holm-adjusted "
                f"{_p(self.p_holm)} (alpha {_p(self.alpha)}) -> {self.verdict}")  # fmt: skip


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
    definitions), for one variant's Fig. 2 points: the rise over every team size, the other
    claims over the paper's (up to PAPER_MAX_TEAM)."""
    out = []
    everyone, fig2 = fig2, [r for r in fig2 if r.robots <= PAPER_MAX_TEAM]
    for (laser, comm), pts in verdicts.team_groups(fig2):
        for n in sorted(pts):
            if n > 1:
                out.append(Comparison("team", f"laser {_g(laser)} m, range {_g(comm)} m: 1 "
                                      f"robot vs {n}", _pt(pts[1]), _pt(pts[n])))  # fmt: skip
    for (laser, comm), pts in verdicts.rise_groups(everyone):
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


def holm_adjusted(ps: Sequence[float]) -> list[float]:
    """Holm's adjusted p-values (in the given order): the smallest family level at which each
    is rejected, max over the ranks up to its own of min(1, (m - rank) p)."""
    m = len(ps)
    out = [1.0] * m
    running = 0.0
    for rank, i in enumerate(sorted(range(m), key=lambda i: ps[i])):
        running = max(running, min(1.0, (m - rank) * ps[i]))
        out[i] = running
    return out


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
    adjusted = holm_adjusted(ps)
    for c, r, k, (threshold, rejected), adj in zip(comps, raw, factor, holm(ps, alpha), adjusted,
                                                   strict=True):  # fmt: skip
        if r is None:
            out.append(None)
            continue
        diff, t, df, p = r
        verdict = UNDECIDED if not rejected else HOLDS if diff > 0 else FAILS
        runs = (len(data[c.more]), len(data[c.fewer]))
        out.append(Test(runs, diff, t, df, p, threshold / k, verdict, adj))
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
