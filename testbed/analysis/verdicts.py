"""The paper's claims, decided on the tables behind the figures.

Theory of operation. Each claim of the paper's Section 5 is a pure function of the tables
testbed.analysis.figures.make_all returns (`verdict_*`) that returns a `Verdict`: holds /
partly / does not hold / not enough data, with the numbers it was decided on.

How each claim is decided (a *group* is one laser range and communication range, a *point*
one team size of a group; steps are the mean over runs of the exploration steps):

- 5.1 team work beats one robot: in a group with a one-robot point, every larger team needs
  fewer steps than one robot.
- 5.1 steps fall then rise with team size: in a group with at least three team sizes, the
  fewest steps are at a team size strictly between the smallest and the largest, and the rise
  from there to the largest team exceeds the run-to-run noise: the two points' 95% confidence
  intervals (testbed.analysis.stats, Student's t) do not overlap.
- 5.1 a smaller range needs more steps: for each team of two or more and laser range, the
  smallest communication range needs more steps than the largest, beyond the noise in the
  same sense.
- 5.1 a shorter laser needs more steps at the same steps-to-team ratio: for each range and
  team, the shorter laser needs more steps, and the ratio of the two lasers' steps is the same
  across team sizes: their coefficient of variation is at most RATIO_CV_MAX beyond the noise.
  The noise: each point's mean drawn CV_DRAWS times from its sampling distribution (normal,
  its runs' standard deviation over the square root of their number), the CV of each draw's
  ratios; "same" when 97.5% of the draws' CVs are at most RATIO_CV_MAX, "varies" when 97.5%
  are above, undecided (within the noise) otherwise. The draws add the noise to means that
  carry it already, so they lean to larger CVs: "same" is the harder verdict to reach.
- 5.2 a single robot plans on the timer: at least TIMER_SHARE_MIN of a lone robot's plan
  generations (after its first) have cause "timer".
- 5.2 on-request plan generations grow with team size: the Spearman rank correlation between
  team size and the mean number of on-request generations per run is at least RHO_MIN.

A claim holds when it holds in every group that has the data, partly when in some, and does
not hold when in none. The two claims tested against the run-to-run noise (fall then rise, a
smaller range) cannot be decided in a group where a point has one run: its noise is unknown,
so neither a rise nor its absence is shown. Such a group counts as undecided, and a claim
with no decided group is "too few runs to decide", not "does not hold". The same ratio of the
shorter laser's claim is undecided in a range where it is within the noise or a point has one
run; undecided in every range, its headline names the cause: "within the run-to-run noise"
where any range had the runs to measure the noise, "too few runs" where none had. The claims
decided on the means alone say so in their evidence when a point rests on one run.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from testbed.analysis import ablation, stats
from testbed.analysis.tables import PAPER_MAX_TEAM, Fig2Row, PlanCauseRow
from testbed.analysis.verdictwords import FAILS, HOLDS, NO_DATA, PARTLY, TOO_FEW

if TYPE_CHECKING:
    from testbed.analysis.figures import Tables


WITHIN_NOISE = "undecided: within the run-to-run noise"
MIN_RUNS = 2  # runs a point needs before its noise (and so a noise-aware test) is known
RATIO_CV_MAX = 0.15
CV_DRAWS = 2000  # draws of the points' means for the noise of the ratios' CV
TIMER_SHARE_MIN = 0.95
RHO_MIN = 0.8


RULES = (
    "team work beats one robot: in a group with a one-robot point, every larger team needs "
    "fewer steps than one robot;",
    "fall then rise: in a group with three or more team sizes, the fewest steps are at a team "
    "size strictly between the smallest and the largest, and the 95% intervals of that point "
    "and of the largest team do not overlap (the rise exceeds the run-to-run spread);",
    "smaller range: for each team of two or more, the smallest range needs more steps than the "
    "largest and their 95% intervals do not overlap;",
    f"intervals: {stats.METHOD}, over a point's runs; the runs a point would need to resolve a "
    "difference d with run-to-run standard deviation s (5% significance, 80% power): "
    "2 ((1.96 + 0.84) s / d)^2;",
    "shorter laser: the shorter laser needs more steps at every (range, team), and the ratio of "
    f"the two lasers' steps varies across team sizes by at most {RATIO_CV_MAX:.0%} (CV) "
    "beyond the noise (97.5% of the CVs of the ratios of means drawn from each point's "
    "sampling distribution at most that; undecided when they straddle it);",
    f"timer: at least {TIMER_SHARE_MIN:.0%} of a lone robot's plan generations after its first "
    "are on the timer;",
    "on request: the mean number of on-request plan generations per run rises with team size "
    f"(Spearman rank correlation at least {RHO_MIN});",
    "a claim holds when it holds in every group with the data, partly when in some, and does "
    "not hold when in none;",
    f"a noise-aware claim (fall then rise, smaller range) is undecided in a group where a point "
    f"has fewer than {MIN_RUNS} runs (its noise is unknown); with no decided group it is "
    f"'{TOO_FEW}'.",
)


@dataclass
class Verdict:
    section: str
    claim: str
    verdict: str
    evidence: list[str] = field(default_factory=list)


def _f(x: float) -> str:
    return f"{x:g}"


def _overall(results: Sequence[bool | None]) -> str:
    """The claim over its groups' results (None: undecided, too few runs)."""
    if not results:
        return NO_DATA
    decided = [r for r in results if r is not None]
    if not decided:
        return TOO_FEW
    if all(decided):
        return HOLDS
    return PARTLY if any(decided) else FAILS


def _few(rows: Iterable[Fig2Row]) -> list[int]:
    """The team sizes among fig2 `rows` whose point has fewer than MIN_RUNS runs."""
    return sorted(r.robots for r in rows if r.steps.n < MIN_RUNS)


def _yes_no(ok: bool | None) -> str:
    return "too few runs" if ok is None else "yes" if ok else "no"


def _single_run_note(rows: list[Fig2Row]) -> list[str]:
    """For the claims decided on means alone: say when they compare single runs."""
    few = [r for r in rows if r.steps.n < MIN_RUNS]
    if not few:
        return []
    return [
        f"{len(few)} of {len(rows)} points rest on one run: this compares single runs, whose "
        "run-to-run noise is unknown"
    ]


def _rows(fig2: list[Fig2Row]) -> dict[tuple, dict[int, Fig2Row]]:
    """(laser, range) -> {team size: fig2 row} (mean, interval, spread)."""
    out: dict[tuple, dict[int, Fig2Row]] = {}
    for r in fig2:
        out.setdefault((r.laser_range, r.comm_range), {})[r.robots] = r
    return out


def _group_name(laser, comm) -> str:
    return f"laser {_f(laser)} m, range {_f(comm)} m"


# -- The comparisons the claims rest on, shared with testbed.analysis.decide (which tests each
# on fresh runs): each names the points a claim compares, the one it says needs more steps.


def team_groups(fig2: list[Fig2Row]) -> list[tuple[tuple[float, float], dict[int, Fig2Row]]]:
    """Team work beats one robot: each (laser, range) group with a one-robot point and at
    least one team, with its points by team size (one robot needs more steps than each)."""
    return [(g, pts) for g, pts in sorted(_rows(fig2).items()) if 1 in pts and len(pts) >= 2]


def rise_groups(fig2: list[Fig2Row]) -> list[tuple[tuple[float, float], dict[int, Fig2Row]]]:
    """Fall then rise: each (laser, range) group with three team sizes or more."""
    return [(g, pts) for g, pts in sorted(_rows(fig2).items()) if len(pts) >= 3]


def rise_pair(pts: dict[int, Fig2Row]) -> tuple[int, int]:
    """Fall then rise, one group (three team sizes or more): (the team size strictly between
    the smallest and the largest with the fewest steps, the largest): the rise says the
    largest team needs more steps than that one."""
    inner = [n for n in pts if min(pts) < n < max(pts)]
    return min(inner, key=lambda n: (pts[n].steps.mean, n)), max(pts)


def range_pairs(fig2: list[Fig2Row]) -> list[tuple[tuple[float, int], Fig2Row, Fig2Row]]:
    """A smaller range needs more steps: for each (laser, team of two or more) with two
    ranges or more, its points at the smallest and at the largest range."""
    by: dict[tuple, dict[float, Fig2Row]] = {}
    for r in fig2:
        if r.robots >= 2:
            by.setdefault((r.laser_range, r.robots), {})[r.comm_range] = r
    return [(key, pts[min(pts)], pts[max(pts)]) for key, pts in sorted(by.items())
            if len(pts) >= 2]  # fmt: skip


def laser_pairs(fig2: list[Fig2Row]) -> list[tuple[tuple[float, int], Fig2Row, Fig2Row]]:
    """A shorter laser needs more steps: for each (range, team) that ran both the shortest
    and the longest laser of the sweep, its points at the shorter and the longer (none when
    the sweep has one laser)."""
    lasers = sorted({r.laser_range for r in fig2})
    if len(lasers) < 2:
        return []
    short, long_ = lasers[0], lasers[-1]
    by: dict[tuple, dict[float, Fig2Row]] = {}
    for r in fig2:
        by.setdefault((r.comm_range, r.robots), {})[r.laser_range] = r
    return [(key, pts[short], pts[long_]) for key, pts in sorted(by.items())
            if short in pts and long_ in pts]  # fmt: skip


def verdict_team_beats_one(fig2: list[Fig2Row]) -> Verdict:
    v = Verdict(
        "5.1", "Team work beats one robot: every team needs fewer steps than one robot", NO_DATA
    )
    results = []
    for (laser, comm), rows in team_groups(fig2):
        pts = {n: row.steps.mean for n, row in rows.items()}
        teams = {n: s for n, s in pts.items() if n > 1}
        ok = all(s < pts[1] for s in teams.values())
        results.append(ok)
        worst = max(teams, key=lambda n: teams[n])
        v.evidence.append(
            f"{_group_name(laser, comm)}: 1 robot {pts[1]:.0f} steps; teams of "
            f"{min(teams)}-{max(teams)}: {min(teams.values()):.0f}-{max(teams.values()):.0f} "
            f"(most steps: {worst} robots) -> {'yes' if ok else 'no'}"
        )
    v.verdict = _overall(results)
    if results:
        v.evidence += _single_run_note(fig2)
    return v


def verdict_fall_then_rise(fig2: list[Fig2Row]) -> Verdict:
    """Noise-aware: the rise from the fewest steps to the largest team must exceed the spread
    of the runs (their 95% intervals do not overlap; testbed.analysis.ablation.rise)."""
    v = Verdict("5.1", "Exploration steps fall, then rise again as the team grows", NO_DATA)
    results: list[bool | None] = []
    for (laser, comm), pts in rise_groups(fig2):
        few = _few(pts.values())
        ok: bool | None
        ok, why = ablation.rise(pts)
        note = ""
        if few:
            ok = None
            why = f"one run at {', '.join(map(str, few))} robots, so the noise is unknown"
        elif min(pts, key=lambda n: pts[n].steps.mean) == max(pts):
            note = " (the sweep may stop short of the turning point)"
        if max(pts) > PAPER_MAX_TEAM:
            note += f" (teams past {PAPER_MAX_TEAM}: beyond the paper's range)"
        results.append(ok)
        v.evidence.append(f"{_group_name(laser, comm)}: {why} -> {_yes_no(ok)}{note}")
    v.verdict = _overall(results)
    return v


def verdict_smaller_range(fig2: list[Fig2Row]) -> Verdict:
    """Noise-aware: for each laser and team of two or more, the smallest range needs more
    steps than the largest and their 95% intervals do not overlap."""
    v = Verdict("5.1", "A smaller communication range needs more steps", NO_DATA)
    results: list[bool | None] = []
    within: list[int | None] = []
    for (laser, robots), small, large in range_pairs(fig2):
        a, b = small.steps.ci, large.steps.ci
        ok: bool | None = small.steps.mean > large.steps.mean and stats.separated(a, b)
        if _few([small, large]):
            ok = None
        results.append(ok)
        if small.steps.mean > large.steps.mean and not ok and a is not None and b is not None:
            within.append(ablation.runs_needed(large.steps, small.steps))
        v.evidence.append(
            f"laser {_f(laser)} m, {robots} robots: range {_f(small.comm_range)} m "
            f"{small.steps.mean:.0f} {ablation._interval(a)}, range {_f(large.comm_range)} m "
            f"{large.steps.mean:.0f} {ablation._interval(b)} -> {_yes_no(ok)}"
        )
    v.verdict = _overall(results)
    decided = [r for r in results if r is not None]
    if decided:
        head = (
            f"smaller range needs more steps, beyond the noise, in {sum(decided)} of "
            f"{len(decided)} cases"
        )
        if len(decided) < len(results):
            head += f" ({len(results) - len(decided)} more undecided: one run at a point)"
        if within:
            need = sorted(n for n in within if n)
            if need:
                head += (f"; {len(within)} more in the same direction but within the noise "
                         f"(resolving them would take {need[len(need) // 2]} runs per point, "
                         "median)")  # fmt: skip
        v.evidence.insert(0, head)
    return v


def laser_more_steps(fig2: list[Fig2Row]) -> str:
    """The shorter laser's claim, its "more steps" part alone, on the means (as
    verdict_shorter_laser decides that part): the part testbed.analysis.decide tests."""
    return _overall([a.steps.mean > b.steps.mean for _, a, b in laser_pairs(fig2)])


def verdict_shorter_laser(fig2: list[Fig2Row]) -> Verdict:
    v = Verdict(
        "5.1",
        "A shorter laser needs more steps, at the same steps-to-team ratio",
        NO_DATA,
    )
    lasers = sorted({r.laser_range for r in fig2})
    if len(lasers) < 2:
        return v
    short, long_ = lasers[0], lasers[-1]
    more: list[bool] = []
    pairs_by_range: dict[float, list[tuple[Fig2Row, Fig2Row]]] = {}
    for (comm, _robots), a, b in laser_pairs(fig2):
        more.append(a.steps.mean > b.steps.mean)
        pairs_by_range.setdefault(comm, []).append((a, b))
    if not more:
        return v
    same_ratio: list[bool | None] = []
    noisy = 0  # ranges whose points have their runs, undecided because of the noise
    v.evidence.append(
        f"laser {_f(short)} m needs more steps than laser {_f(long_)} m in {sum(more)} of "
        f"{len(more)} (range, team) points"
    )
    for comm, pairs in sorted(pairs_by_range.items()):
        if len(pairs) < 2:
            continue
        ratios = [a.steps.mean / b.steps.mean for a, b in pairs]
        mean = statistics.fmean(ratios)
        cv = statistics.pstdev(ratios) / mean
        band = _ratio_cv_band(pairs)
        if band is None:
            same, why = None, "a point has one run -> too few runs"
        else:
            lo, hi = band
            same = True if hi <= RATIO_CV_MAX else False if lo > RATIO_CV_MAX else None
            word = {True: "same", False: "varies", None: "within the noise"}[same]
            noisy += same is None
            why = f"noise band {lo:.2f}-{hi:.2f} -> {word}"
        same_ratio.append(same)
        v.evidence.append(
            f"range {_f(comm)} m: steps ratio {_f(short)} m / {_f(long_)} m = "
            f"{min(ratios):.2f}-{max(ratios):.2f} over team sizes (mean {mean:.2f}, "
            f"CV {cv:.2f}; {why})"
        )
    parts = [_overall(more), _overall(same_ratio) if same_ratio else NO_DATA]
    undecided = sum(1 for same in same_ratio if same is None)
    if parts == [HOLDS, HOLDS]:
        v.verdict = HOLDS
        if undecided:
            v.evidence.append(
                f"the same ratio is shown at {len(same_ratio) - undecided} of "
                f"{len(same_ratio)} ranges and undecided at the others"
            )
    elif parts[0] == FAILS:
        v.verdict = FAILS
    elif parts == [HOLDS, TOO_FEW]:
        # Undecided everywhere: the headline names the cause (the noise, where any range had
        # the runs to measure it; too few runs only where none had).
        v.verdict = WITHIN_NOISE if noisy else TOO_FEW
        v.evidence.append("more steps: holds; same ratio across team sizes: undecided")
    else:
        v.verdict = PARTLY
        v.evidence.append(f"more steps: {parts[0]}; same ratio across team sizes: {parts[1]}")
    v.evidence += _single_run_note(fig2)
    return v


def _ratio_cv_band(pairs: list[tuple[Fig2Row, Fig2Row]]) -> tuple[float, float] | None:
    """The 2.5 and 97.5 percentiles of the CV of the (shorter / longer laser) steps ratios
    over team sizes when each point's mean is drawn from its sampling distribution; None
    when a point has fewer than MIN_RUNS runs (its noise is unknown)."""
    rows = [row for pair in pairs for row in pair]
    if _few(rows):
        return None
    rng = np.random.default_rng(0)  # the same report from the same runs
    means = np.array([r.steps.mean for r in rows])
    sems = np.array([(r.steps.std or 0.0) / np.sqrt(r.steps.n) for r in rows])
    draws = rng.normal(means, sems, size=(CV_DRAWS, len(rows)))
    ratios = draws[:, 0::2] / draws[:, 1::2]
    cvs = ratios.std(axis=1) / ratios.mean(axis=1)
    lo, hi = np.percentile(cvs, [2.5, 97.5])
    return float(lo), float(hi)


def verdict_single_robot_timer(plans: list[PlanCauseRow]) -> Verdict:
    v = Verdict("5.2", "A single robot generates its plans on the timer", NO_DATA)
    alone = [p for p in plans if p.robots == 1]
    timer = sum(p.timer for p in alone)
    total = sum(p.timer + p.request for p in alone)
    if not total:
        return v
    share = timer / total
    v.verdict = HOLDS if share >= TIMER_SHARE_MIN else FAILS
    v.evidence.append(
        f"{len(alone)} one-robot runs: {timer} of {total} plan generations after the first "
        f"were on the timer ({share:.0%}; needed {TIMER_SHARE_MIN:.0%})"
    )
    return v


def spearman(xs: list[float], ys: list[float]) -> float | None:
    """Spearman's rank correlation (average ranks for ties); None when undefined."""

    def ranks(v):
        order = sorted(range(len(v)), key=lambda i: v[i])
        r = [0.0] * len(v)
        i = 0
        while i < len(order):
            j = i
            while j + 1 < len(order) and v[order[j + 1]] == v[order[i]]:
                j += 1
            for k in range(i, j + 1):
                r[order[k]] = (i + j) / 2
            i = j + 1
        return r

    if len(xs) < 2:
        return None
    rx, ry = ranks(xs), ranks(ys)
    mx, my = statistics.fmean(rx), statistics.fmean(ry)
    sx = sum((a - mx) ** 2 for a in rx) ** 0.5
    sy = sum((b - my) ** 2 for b in ry) ** 0.5
    if not sx or not sy:
        return None
    return sum((a - mx) * (b - my) for a, b in zip(rx, ry, strict=True)) / (sx * sy)


def verdict_requests_grow(plans: list[PlanCauseRow]) -> Verdict:
    v = Verdict("5.2", "On-request plan generations grow with team size", NO_DATA)
    by_team: dict[int, list[int]] = {}
    for p in plans:
        by_team.setdefault(p.robots, []).append(p.request)
    if len(by_team) < 2:
        return v
    teams = sorted(by_team)
    means = [statistics.fmean(by_team[n]) for n in teams]
    rho = spearman([float(n) for n in teams], means)
    grows = means[-1] > means[0]
    if rho is None:
        v.verdict = FAILS
    elif rho >= RHO_MIN and grows:
        v.verdict = HOLDS
    elif rho > 0 and grows:
        v.verdict = PARTLY
    else:
        v.verdict = FAILS
    v.evidence.append(
        "on-request generations per run (all robots), by team size: "
        + ", ".join(f"{n}: {m:.1f}" for n, m in zip(teams, means, strict=True))
    )
    v.evidence.append(
        f"Spearman rank correlation {rho:.2f} (needed {RHO_MIN})"
        if rho is not None
        else "rank correlation undefined (no variation)"
    )
    return v


def verdicts(tables: Tables) -> list[Verdict]:
    fig2, plans = tables.fig2, tables.plans
    return [
        verdict_team_beats_one(fig2),
        verdict_fall_then_rise(fig2),
        verdict_smaller_range(fig2),
        verdict_shorter_laser(fig2),
        verdict_single_robot_timer(plans),
        verdict_requests_grow(plans),
    ]
