"""Statistics for campaign reports: Wilson intervals for rates, bootstrap intervals for means, paired comparisons,
and rates of two independent samples (ours against a published table).

All resampling is seeded, so a report is the same every time it is made from the same results.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import stats as scipy_stats

Z95 = 1.959963984540054
BOOTSTRAP_RESAMPLES = 2000


@dataclass(frozen=True)
class Estimate:
    """A value with its 95 % confidence interval and the sample size it came from."""

    value: float
    low: float
    high: float
    n: int

    def format(self, digits: int = 2, percent: bool = False) -> str:
        """``value [low, high]``, as a percentage when asked; ``n/a`` without data."""
        if self.n == 0 or not math.isfinite(self.value):
            return "n/a"
        scale, unit = (100.0, " %") if percent else (1.0, "")
        v, lo, hi = (x * scale for x in (self.value, self.low, self.high))
        return f"{v:.{digits}f}{unit} [{lo:.{digits}f}, {hi:.{digits}f}]"


def wilson(successes: int, n: int) -> Estimate:
    """The rate ``successes / n`` with its Wilson score interval (95 %)."""
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan, 0)
    p = successes / n
    denominator = 1.0 + Z95**2 / n
    centre = (p + Z95**2 / (2 * n)) / denominator
    half = Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n)) / denominator
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return Estimate(p, low, high, n)


def bootstrap_mean(values: Sequence[float], seed: int = 0) -> Estimate:
    """The mean of the finite ``values`` with a percentile bootstrap interval (95 %, seeded)."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=np.float64)
    if len(x) == 0:
        return Estimate(math.nan, math.nan, math.nan, 0)
    if len(x) == 1:
        return Estimate(float(x[0]), float(x[0]), float(x[0]), 1)
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), size=(BOOTSTRAP_RESAMPLES, len(x)))].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return Estimate(float(x.mean()), float(low), float(high), len(x))


@dataclass(frozen=True)
class PairedRates:
    """Two strategies' binary outcomes on the same scenes: discordant pairs and the exact McNemar test."""

    n_pairs: int
    only_a: int
    only_b: int
    p_value: float


def mcnemar_exact(
    a: Sequence[bool], b: Sequence[bool], alternative: Literal["two-sided", "greater", "less"] = "two-sided"
) -> PairedRates:
    """Exact (binomial) McNemar test of paired outcomes ``a[i]``, ``b[i]``.

    ``alternative="greater"``: one-sided, "pairs where only ``a`` holds are more frequent than chance" (the
    regression gate's question, with ``a`` the baseline being good).
    """
    if len(a) != len(b):
        raise ValueError(f"paired outcomes need equal lengths, got {len(a)} and {len(b)}")
    only_a = sum(1 for x, y in zip(a, b, strict=True) if x and not y)
    only_b = sum(1 for x, y in zip(a, b, strict=True) if y and not x)
    discordant = only_a + only_b
    p = 1.0 if discordant == 0 else float(scipy_stats.binomtest(only_a, discordant, 0.5, alternative).pvalue)
    return PairedRates(len(a), only_a, only_b, p)


def paired_mean_difference(a: Sequence[float], b: Sequence[float], seed: int = 0) -> Estimate:
    """Mean of ``a[i] - b[i]`` over pairs where both are finite, with a bootstrap interval (95 %)."""
    if len(a) != len(b):
        raise ValueError(f"paired values need equal lengths, got {len(a)} and {len(b)}")
    diffs = [
        x - y
        for x, y in zip(a, b, strict=True)
        if x is not None and y is not None and math.isfinite(x) and math.isfinite(y)
    ]
    return bootstrap_mean(diffs, seed)


@dataclass(frozen=True)
class RateDifference:
    """Two independent rates: ``a - b`` with its 95 % interval, and Fisher's exact test of equal rates."""

    difference: Estimate
    p_value: float


def rate_difference(successes_a: int, n_a: int, successes_b: int, n_b: int) -> RateDifference:
    """The difference of two independent rates, ``successes_a / n_a - successes_b / n_b``.

    The interval is Newcombe's hybrid score interval (his method 10: from the two Wilson intervals; Newcombe 1998,
    Statistics in Medicine 17:873), the test Fisher's exact test, two-sided. ``difference.n`` is ``n_a + n_b``.
    """
    if n_a <= 0 or n_b <= 0:
        raise ValueError(f"two rates need samples, got n_a={n_a} and n_b={n_b}")
    for k, n in ((successes_a, n_a), (successes_b, n_b)):
        if not 0 <= k <= n:
            raise ValueError(f"successes must lie in [0, n], got {k} of {n}")
    a, b = wilson(successes_a, n_a), wilson(successes_b, n_b)
    d = a.value - b.value
    low = d - math.sqrt((a.value - a.low) ** 2 + (b.high - b.value) ** 2)
    high = d + math.sqrt((a.high - a.value) ** 2 + (b.value - b.low) ** 2)
    table = np.array([[successes_a, n_a - successes_a], [successes_b, n_b - successes_b]], dtype=np.int64)
    p = float(scipy_stats.fisher_exact(table, alternative="two-sided").pvalue)
    return RateDifference(Estimate(d, low, high, n_a + n_b), p)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values (same order as given; each at most 1).

    Reject the hypotheses whose adjusted p is below alpha: the chance of any false rejection in the family is then
    at most alpha.
    """
    order = sorted(range(len(p_values)), key=lambda i: p_values[i])
    adjusted = [1.0] * len(p_values)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p_values) - rank) * p_values[i]))
        adjusted[i] = running
    return adjusted
