"""Run-to-run noise: confidence intervals of a point's mean, and the runs needed to resolve a
difference.

A Fig. 2 point is the mean of a few runs' exploration steps, and runs of the same
configuration on a real stack differ by tens of percent (thread timing, packet timing). So
every point carries a 95% confidence interval of its mean, computed with Student's t
distribution: mean +- t(0.975, n - 1) * s / sqrt(n), with s the sample standard deviation.
t rather than a bootstrap because a point has 3 to 5 runs, too few for a bootstrap to
estimate its own tails, while t is exact for normal noise and the steps of repeated runs
are close to normal. Two points differ *beyond the noise* when their intervals do not
overlap (a conservative test: it needs more than a 5% two-sample t-test does).

`runs_to_resolve(diff, sd)` answers the planning question: how many runs per point a
two-sample comparison needs to detect a difference `diff` between two means with standard
deviation `sd` each, at 5% significance and 80% power (normal approximation):
n = 2 * ((z(0.975) + z(0.8)) * sd / diff)^2, rounded up.

For the deciding design (testbed.analysis.decide), which tests at other levels than 5%:
Student's t distribution at any degrees of freedom (`t_sf2`, its two-sided tail, from the
regularized incomplete beta function; `t_quantile`) and Welch's two-sample t test (`welch`),
in the standard library alone (the testbed does not depend on scipy).
"""

from __future__ import annotations

import functools
import math
import statistics

CONFIDENCE = 0.95
# Student's t quantile t(0.975, df) for df = 1..30 (standard tables); beyond, the first
# Cornish-Fisher term of its expansion around the normal (within 0.001 of the table at 40).
_T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip
Z975 = 1.959964  # normal quantile for a two-sided 5% test
Z80 = 0.841621  # normal quantile for 80% power
METHOD = "Student's t, 95%: mean +- t(0.975, n-1) * sd / sqrt(n)"


def t975(df: int) -> float:
    """The 97.5% quantile of Student's t with `df` degrees of freedom (df >= 1)."""
    if df < 1:
        raise ValueError(f"degrees of freedom must be >= 1, not {df}")
    if df <= len(_T975):
        return _T975[df - 1]
    return Z975 + (Z975**3 + Z975) / (4 * df)


def mean_ci(values: list[float]) -> tuple[float, float, float] | None:
    """(mean, low, high) of the 95% t interval of the mean; None for fewer than two values
    (one run says nothing about the noise)."""
    n = len(values)
    if n < 2:
        return None
    m = statistics.fmean(values)
    half = t975(n - 1) * statistics.stdev(values) / math.sqrt(n)
    return m, m - half, m + half


def separated(a: tuple[float, float, float] | None, b: tuple[float, float, float] | None) -> bool:
    """True when two intervals (mean, low, high) do not overlap: a difference beyond noise."""
    if a is None or b is None:
        return False
    return a[2] < b[1] or b[2] < a[1]


def runs_to_resolve(diff: float, sd: float) -> int | None:
    """Runs per point to tell apart two means `diff` apart with noise `sd` (5%, 80% power);
    None when there is no difference to resolve."""
    if diff == 0 or not math.isfinite(diff) or not math.isfinite(sd):
        return None
    return max(2, math.ceil(2 * ((Z975 + Z80) * sd / abs(diff)) ** 2))


def share_ci(hits: int, n: int) -> tuple[float, float, float] | None:
    """(share, low, high): the 95% Wilson score interval of a share of `hits` in `n` runs
    (a share of whole runs, where a t interval would leave [0, 1]); None for no runs."""
    if n < 1:
        return None
    p, z2 = hits / n, Z975**2
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z975 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return p, max(0.0, centre - half), min(1.0, centre + half)


def _beta_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta function (modified Lentz's method)."""
    tiny, eps = 1e-300, 1e-15
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 100_000):
        for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):  # fmt: skip
            d = 1 + num * d
            d = 1 / (d if abs(d) > tiny else tiny)
            c = 1 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1) < eps:
            break
    return h


def beta_reg(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function I_x(a, b), a, b > 0, 0 <= x <= 1."""
    if x <= 0:
        return 0.0
    if x >= 1:
        return 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
                     + a * math.log(x) + b * math.log1p(-x))  # fmt: skip
    if x < (a + 1) / (a + b + 2):
        return front * _beta_fraction(a, b, x) / a
    return 1 - front * _beta_fraction(b, a, 1 - x) / b


def t_sf2(t: float, df: float) -> float:
    """P(|T| >= |t|) for Student's t with `df` (> 0, need not be whole) degrees of freedom:
    the two-sided p-value of a t statistic."""
    if df <= 0:
        raise ValueError(f"degrees of freedom must be > 0, not {df}")
    if math.isinf(t):
        return 0.0
    return beta_reg(df / 2, 0.5, df / (df + t * t))


def t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with `df` degrees of freedom."""
    tail = t_sf2(t, df) / 2
    return 1 - tail if t > 0 else tail


@functools.lru_cache(maxsize=4096)
def t_quantile(q: float, df: float) -> float:
    """The `q` quantile of Student's t with `df` degrees of freedom (0 < q < 1), by bisection
    on t_cdf (to 1e-9 relative)."""
    if not 0 < q < 1:
        raise ValueError(f"a quantile's probability is in (0, 1), not {q}")
    if q < 0.5:
        return -t_quantile(1 - q, df)
    lo, hi = 0.0, 1.0
    while t_cdf(hi, df) < q:
        lo, hi = hi, hi * 2
    while hi - lo > 1e-9 * max(1.0, hi):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if t_cdf(mid, df) < q else (lo, mid)
    return (lo + hi) / 2


def mean_var(values: list[float]) -> tuple[float, float]:
    """The mean and the sample variance (n - 1) of two values or more, in floating point
    (statistics.variance computes exactly, in fractions: a hundred times slower)."""
    n = len(values)
    m = math.fsum(values) / n
    return m, math.fsum((x - m) ** 2 for x in values) / (n - 1)


def welch(a: list[float], b: list[float]) -> tuple[float, float, float]:
    """Welch's two-sample t test of mean(a) = mean(b): (t, degrees of freedom, two-sided p),
    t > 0 when a's mean is the larger. Both samples need two values or more. Identical
    values on both sides: t 0 and p 1 when the means are equal, else t infinite and p 0."""
    na, nb = len(a), len(b)
    if na < 2 or nb < 2:
        raise ValueError(f"Welch's test needs two values a side, not {na} and {nb}")
    (ma, va), (mb, vb) = mean_var(a), mean_var(b)
    diff = ma - mb
    va, vb = va / na, vb / nb
    se2 = va + vb
    if se2 == 0:
        return (0.0, float(na + nb - 2), 1.0) if diff == 0 else \
            (math.copysign(math.inf, diff), float(na + nb - 2), 0.0)  # fmt: skip
    df = se2 * se2 / (va * va / (na - 1) + vb * vb / (nb - 1))
    t = diff / math.sqrt(se2)
    return t, df, t_sf2(t, df)
