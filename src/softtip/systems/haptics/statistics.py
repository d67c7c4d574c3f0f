"""The study's statistics as published: Friedman across methods, Wilcoxon signed-rank post hoc with
Bonferroni's correction, and the Wilcoxon W both as scipy gives it and as a signed-rank sum.

scipy's ``wilcoxon`` returns W = min(W+, W−) for a two-sided test: W+ and W− are the sums of the
ranks of |x − y| over the pairs where x > y and where x < y (zero differences dropped, tied
magnitudes sharing their mean rank). Statistics packages that print a W with a sign print the
signed-rank sum W+ − W− (positive: x mostly above y). Both are reported, named as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class FriedmanResult:
    """Friedman's test across methods on paired samples: χ², its p-value, samples and methods."""

    chi_square: float
    p_value: float
    samples: int
    methods: int


@dataclass(frozen=True)
class WilcoxonResult:
    """A Wilcoxon signed-rank test of x against y (paired).

    ``w_scipy`` = min(W+, W−), scipy's statistic; ``signed_rank_sum`` = W+ − W−, the sum of the
    signed ranks; ``p_value`` two-sided as scipy computes it; ``p_bonferroni`` = min(1, p × tests)."""

    w_plus: float
    w_minus: float
    w_scipy: float
    signed_rank_sum: float
    p_value: float
    p_bonferroni: float
    pairs: int
    tests: int


def _paired(samples) -> np.ndarray:
    samples = np.asarray(samples, dtype=float)
    if samples.ndim != 2 or samples.shape[0] < 2 or samples.shape[1] < 2:
        raise ValueError(f"samples have shape {samples.shape}: expected (methods >= 2, pairs >= 2)")
    if not np.all(np.isfinite(samples)):
        raise ValueError("samples: expected finite numbers (a NaN error cannot be ranked)")
    return samples


def friedman(samples) -> FriedmanResult:
    """Friedman's test on ``samples`` (methods, paired samples), by scipy."""
    samples = _paired(samples)
    if samples.shape[0] < 3:
        raise ValueError(f"samples have {samples.shape[0]} methods: Friedman's test needs at least 3")
    chi_square, p_value = stats.friedmanchisquare(*samples)
    return FriedmanResult(float(chi_square), float(p_value), samples.shape[1], samples.shape[0])


def signed_ranks(x, y) -> tuple[float, float]:
    """(W+, W−): the rank sums of |x − y| where x > y and where x < y; zeros dropped, ties averaged."""
    difference = np.diff(_paired([y, x]), axis=0)[0]
    difference = difference[difference != 0]
    ranks = stats.rankdata(np.abs(difference))
    return float(ranks[difference > 0].sum()), float(ranks[difference < 0].sum())


def wilcoxon(x, y, tests: int = 1) -> WilcoxonResult:
    """The Wilcoxon signed-rank test of paired ``x`` and ``y`` (scipy's, two-sided), with its
    p-value corrected by Bonferroni over ``tests`` tests."""
    if int(tests) != tests or tests < 1:
        raise ValueError(f"tests = {tests!r}: expected a positive integer")
    w_plus, w_minus = signed_ranks(x, y)
    if w_plus + w_minus == 0:
        raise ValueError("x and y are equal in every pair: the signed-rank test has nothing to rank")
    result = stats.wilcoxon(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return WilcoxonResult(w_plus, w_minus, float(result.statistic), w_plus - w_minus, float(result.pvalue),
                          min(1.0, float(result.pvalue) * tests), len(np.asarray(x)), int(tests))


def rank_sum(value: float) -> float | int:
    """A Wilcoxon rank sum, as an integer when it is one (ties make halves)."""
    return int(value) if float(value).is_integer() else float(value)
