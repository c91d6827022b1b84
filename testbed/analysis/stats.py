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
"""

from __future__ import annotations

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
