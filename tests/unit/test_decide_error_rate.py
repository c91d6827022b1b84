"""The deciding design's error rate and power, checked in a simulation
(testbed.analysis.decide).

False positives: claims made false by construction. A grid of 16 points (lasers 2 and
1.5 m, ranges 5 and 20 m, teams of 1 to 4) whose runs' exploration steps all come from one
distribution, so that no point needs more steps than another and every verdict ("holds"
or "does not hold") on any comparison is an error. Each simulated experiment runs the whole
design: stage 1 (3 runs a point), the plan (within a budget), stage 2 (fresh runs, as many
as planned), the verdicts. The design states that each claim gets any verdict at all in at
most alpha = 5% of such experiments (its family-wise error rate); the test allows the
binomial noise of N experiments on top: rate <= alpha + 3 sqrt(alpha (1 - alpha) / N), about
2.8 points at N = 540 (a true rate of 5% passes 99.9% of the time). Steps normal, and
skewed as step counts are (a floor plus a gamma tail, skewness 1.4).

Power: a true difference of the planned size, with the spread known, is found at about the
planned power (80%), within the binomial noise of N tests plus 0.03 for the approximation
the plan uses. And end to end, the spread estimated from stage 1's 3 runs a point as the
design does, the power achieved is measured and must stay above 60%: lower than planned
because a spread underestimated from 2 x 3 runs plans too few runs (the module says so).
"""

import math

import numpy as np
import pytest

from testbed.analysis import decide, stats
from testbed.analysis.rows import Spread
from testbed.analysis.tables import Fig2Row

ALPHA = 0.05
N_NULL = 540
LASERS, RANGES, TEAMS = (2.0, 1.5), (5.0, 20.0), (1, 2, 3, 4)
POINTS = [(la, c, n) for la in LASERS for c in RANGES for n in TEAMS]


def tolerance(p: float, n: int) -> float:
    """Three binomial standard deviations of a rate `p` measured over `n` trials."""
    return 3 * math.sqrt(p * (1 - p) / n)


def fig2(data: dict) -> list[Fig2Row]:
    return [
        Fig2Row(
            "ours",
            "corner",
            la,
            c,
            n,
            Spread.of(list(v)),
            tuple(v),
            tuple(f"r{k}" for k in range(len(v))),
        )  # fmt: skip
        for (la, c, n), v in data.items()
    ]


def normal(rng, size):
    return rng.normal(1000.0, 100.0, size)


def skewed(rng, size):  # mean 1000, sd 212, skewness 1.41: a floor and a long tail
    return 700.0 + rng.gamma(2.0, 150.0, size)


def experiment(rng, draw, shift=None, points=POINTS, budget_runs=600):
    """One two-stage experiment; `shift`: point -> its true mean's offset (none: all alike).
    Returns the decisions."""
    shift = shift or {}
    first = {pt: tuple(draw(rng, 3) + shift.get(pt, 0.0)) for pt in points}
    comps = decide.comparisons(fig2(first))
    plan = decide.plan(comps, first, alpha=ALPHA, budget_runs=budget_runs)
    second = {pt: tuple(draw(rng, n) + shift.get(pt, 0.0)) for pt, n in plan.point_runs.items()}
    return plan, decide.judge(plan, second)


@pytest.mark.parametrize("draw", [normal, skewed], ids=["normal", "skewed"])
def test_false_claims_get_a_verdict_at_most_alpha_of_the_time(draw):
    rng = np.random.default_rng(20160 + (draw is skewed))
    wrong = dict.fromkeys(decide.CLAIMS, 0)
    runs = []
    for _ in range(N_NULL):
        plan, decisions = experiment(rng, draw)
        runs.append(plan.total_runs)
        for claim in decide.CLAIMS:
            finals = [d.final for d in decisions if d.planned.comparison.claim == claim]
            assert finals, claim
            wrong[claim] += any(f != decide.UNDECIDED for f in finals)
    limit = ALPHA + tolerance(ALPHA, N_NULL)
    rates = {claim: n / N_NULL for claim, n in wrong.items()}
    print(f"{draw.__name__}: family-wise false verdicts {rates}, stage-2 runs "
          f"{np.mean(runs):.0f} on average")  # fmt: skip
    assert all(r <= limit for r in rates.values()), (rates, limit)
    assert np.mean(runs) > 100  # stage 2 ran: the rate is not low for want of runs


@pytest.mark.parametrize("effect", [0.6, 1.2, 2.5])
@pytest.mark.parametrize("family", [1, 6])
def test_a_difference_of_the_planned_size_is_found_at_the_planned_power(effect, family):
    """Stage 2 alone, the spread known: runs_for_power's runs, Welch's test at the level a
    comparison of a family of `family` is planned at."""
    rng = np.random.default_rng(int(effect * 10) + family)
    level = ALPHA * (1 - decide.STAGE1_SHARE) / family
    n = decide.runs_for_power(effect, level, decide.POWER)
    assert n is not None
    trials = 1500
    found = 0
    for _ in range(trials):
        a, b = rng.normal(effect, 1.0, n), rng.normal(0.0, 1.0, n)
        t, _df, p = stats.welch(list(a), list(b))
        found += p <= level and t > 0
    rate = found / trials
    planned = decide.power_of(n, effect, level)  # at least 80%, more where runs are few
    print(f"effect {effect} sd, family {family}: {n} runs a point, power {rate:.3f} "
          f"(planned {planned:.3f})")  # fmt: skip
    assert planned >= decide.POWER
    assert rate >= decide.POWER - tolerance(decide.POWER, trials) - 0.03, (rate, n)
    assert abs(rate - planned) <= tolerance(planned, trials) + 0.03, (rate, planned, n)
    # and one run fewer would not have had the power (the fewest runs that do)
    if n > decide.MIN_RUNS:
        assert decide.power_of(n - 1, effect, level) < decide.POWER


def test_end_to_end_power_planned_from_stage_one():
    """One comparison (range 5 m vs 20 m, two robots) with a real difference of 1.5 sds:
    stage 1 rarely decides it, the plan takes its size from stage 1, stage 2 decides."""
    rng = np.random.default_rng(7)
    points = [(2.0, 5.0, 2), (2.0, 20.0, 2)]
    shift = {(2.0, 5.0, 2): 150.0}
    trials = 600
    holds = wrong = at_stage1 = 0
    for _ in range(trials):
        _plan, (d,) = experiment(rng, normal, shift, points, budget_runs=None)
        holds += d.final == decide.HOLDS
        wrong += d.final == decide.FAILS
        at_stage1 += d.planned.decided
    print(f"end to end: holds {holds / trials:.3f}, wrong way {wrong / trials:.3f}, "
          f"decided at stage 1 {at_stage1 / trials:.3f}")  # fmt: skip
    assert holds / trials >= 0.6
    assert wrong == 0
