"""Residual analysis as MATLAB's ``resid`` and Ljung (1999, §16.6) do it: are the model's residuals white,
and independent of past inputs?

The residuals e are the model's one-step prediction errors (an output-error model, which has no
noise model, predicts by simulation: its residuals are its simulation errors). With N samples
and normalised correlations ρ at lags up to M:

- whiteness: ρ_ee(τ), τ = 1..M, each within ± z/√N under the hypothesis; the portmanteau
  statistic N Σ ρ_ee(τ)² is χ²(M);
- independence of the inputs: ρ_eu(τ) = Σ e(t+τ) u(t) / (N σ_e σ_u), τ = -M..M (τ > 0: inputs
  before the residual, which a right model leaves none of; τ < 0: feedback), each within
  ± z √(Σ_k ρ_ee(k) ρ_uu(k)) / √N (the variance of a cross-correlation of two independent
  series, Box & Jenkins); Σ_τ (ρ_eu(τ)/σ_τ)² is χ²(2M + 1).

A test passes when its statistic stays below the χ² quantile of the ``confidence``. Trials are
pooled lag by lag (no lag crosses from one trial into the next).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.special

from softtip.sysid.statespace import IdentificationError
from softtip.sysid.uncertainty import normal_quantile

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _correlation(first: list[np.ndarray], second: list[np.ndarray], lags: np.ndarray) -> np.ndarray:
    """Σ_t a(t + τ) b(t) over every trial for each lag τ, divided by the samples and both signals' rms."""
    total = np.zeros(len(lags))
    for a, b in zip(first, second, strict=True):
        N = len(a)
        for k, lag in enumerate(lags):
            if abs(lag) < N:
                total[k] += a[lag:] @ b[:N - lag] if lag >= 0 else a[:N + lag] @ b[-lag:]
    scale = np.sqrt(sum(a @ a for a in first) * sum(b @ b for b in second))
    return total / scale if scale > 0 else total


@dataclass(frozen=True, eq=False)
class ResidualTests:
    """The correlations, their bounds and the two tests per output (and per input for the cross-correlation)."""

    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    lags: int
    samples: int
    confidence: float
    autocorrelation: np.ndarray  # (ny, lags + 1), lag 0..M
    auto_bound: float
    cross_lags: np.ndarray  # -M..M
    cross_correlation: np.ndarray  # (ny, nu, 2M + 1)
    cross_bound: np.ndarray  # (ny, nu, 2M + 1)
    whiteness: np.ndarray  # (ny,) statistic
    independence: np.ndarray  # (ny, nu) statistic

    @property
    def whiteness_limit(self) -> float:
        # chi2.ppf(confidence, lags), without importing scipy.stats
        return float(scipy.special.chdtri(self.lags, 1 - self.confidence))

    @property
    def independence_limit(self) -> float:
        return float(scipy.special.chdtri(2 * self.lags + 1, 1 - self.confidence))

    @property
    def white(self) -> np.ndarray:
        return self.whiteness < self.whiteness_limit

    @property
    def independent(self) -> np.ndarray:
        return self.independence < self.independence_limit

    def to_dict(self) -> dict:
        """JSON-able: per output the two tests (statistic, limit, passed, lags outside the bounds)."""
        per_output = {}
        for i, name in enumerate(self.outputs):
            outside = int(np.sum(np.abs(self.autocorrelation[i, 1:]) > self.auto_bound))
            per_output[name] = {
                "whiteness": {"statistic": float(self.whiteness[i]), "limit": self.whiteness_limit,
                              "passed": bool(self.white[i]), "lags_outside_bound": outside},
                "input_independence": {
                    source: {"statistic": float(self.independence[i, j]), "limit": self.independence_limit,
                             "passed": bool(self.independent[i, j]),
                             "lags_outside_bound": int(np.sum(np.abs(self.cross_correlation[i, j])
                                                              > self.cross_bound[i, j]))}
                    for j, source in enumerate(self.inputs)}}
        return {"outputs": per_output, "lags": self.lags, "samples": self.samples, "confidence": self.confidence,
                "passed": bool(self.white.all() and self.independent.all()),
                "test": "portmanteau N Σρ² ~ χ²(M) (whiteness) and Σ(ρ_eu/σ)² ~ χ²(2M+1) (inputs)"}

    def figure(self) -> Figure:
        """Per output: the residuals' autocorrelation and their cross-correlation with every input, with bounds."""
        from matplotlib.figure import Figure

        ny, nu = len(self.outputs), len(self.inputs)
        figure = Figure(figsize=(4.0 * (nu + 1), 3.0 * ny), constrained_layout=True)
        axes = figure.subplots(ny, nu + 1, squeeze=False)
        lags = np.arange(self.lags + 1)
        for i, output in enumerate(self.outputs):
            axis = axes[i, 0]
            axis.vlines(lags, 0, self.autocorrelation[i])
            axis.axhspan(-self.auto_bound, self.auto_bound, alpha=0.2)
            axis.set_title(f"{output}: residual autocorrelation ({'white' if self.white[i] else 'NOT white'})")
            axis.set_xlabel("lag (samples)")
            for j, source in enumerate(self.inputs):
                axis = axes[i, j + 1]
                axis.vlines(self.cross_lags, 0, self.cross_correlation[i, j])
                axis.fill_between(self.cross_lags, -self.cross_bound[i, j], self.cross_bound[i, j], alpha=0.2)
                axis.set_title(f"{source} → {output} residual ({'independent' if self.independent[i, j] else 'NOT independent'})")
                axis.set_xlabel("lag (samples)")
        return figure


def residual_tests(residuals: Sequence[np.ndarray], inputs: Sequence[np.ndarray], *, lags: int = 25,
                   confidence: float = 0.99, output_names: Sequence[str] | None = None,
                   input_names: Sequence[str] | None = None) -> ResidualTests:
    """The two tests (see the module notes) on ``residuals`` (one (N, ny) array per trial) and the trials'
    ``inputs`` ((N, nu) each)."""
    z = normal_quantile(confidence)
    if isinstance(lags, bool) or not isinstance(lags, (int, np.integer)) or lags < 1:
        raise IdentificationError(f"lags: expected a positive integer, got {lags!r}")
    errors = [np.asarray(e, dtype=np.float64) for e in residuals]
    signals = [np.asarray(u, dtype=np.float64) for u in inputs]
    samples = sum(len(e) for e in errors)
    if samples < 4 * lags:
        raise IdentificationError(f"residual tests: {samples} samples, too few for {lags} lags (needs {4 * lags})")
    ny, nu = errors[0].shape[1], signals[0].shape[1]
    errors = [e - np.concatenate(errors).mean(axis=0) for e in errors]
    signals = [u - np.concatenate(signals).mean(axis=0) for u in signals]
    positive, both = np.arange(lags + 1), np.arange(-lags, lags + 1)
    auto = np.array([_correlation([e[:, i] for e in errors], [e[:, i] for e in errors], positive) for i in range(ny)])
    input_auto = np.array([_correlation([u[:, j] for u in signals], [u[:, j] for u in signals], positive)
                           for j in range(nu)])
    cross = np.array([[_correlation([e[:, i] for e in errors], [u[:, j] for u in signals], both) for j in range(nu)]
                      for i in range(ny)])
    # Σ_k ρ_ee(k) ρ_uu(k) over k = -M..M (both even in k)
    overlap = np.einsum("ik,jk->ij", auto[:, 1:], input_auto[:, 1:]) * 2 + 1
    cross_std = np.sqrt(np.maximum(overlap, 1e-12) / samples)
    cross_bound = np.broadcast_to((z * cross_std)[:, :, None], cross.shape).copy()
    whiteness = samples * np.sum(auto[:, 1:] ** 2, axis=1)
    independence = np.sum((cross / cross_std[:, :, None]) ** 2, axis=2)
    return ResidualTests(tuple(output_names or [f"y{i}" for i in range(ny)]),
                         tuple(input_names or [f"u{j}" for j in range(nu)]), int(lags), samples, confidence,
                         auto, z / np.sqrt(samples), both, cross, cross_bound, whiteness, independence)
