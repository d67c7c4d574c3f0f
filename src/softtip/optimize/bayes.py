"""Sample-efficient search: Gaussian-process Bayesian optimisation on a discrete candidate set.

The candidates are the study's grid (rows of the unit cube, one column per
parameter), so the search can be checked against the full sweep. A small Latin
hypercube snapped to the grid starts it; then each step fits a Gaussian process
(Matern 5/2 kernel with one length scale per parameter, a constant amplitude
and a small white-noise term that absorbs the remeshing jitter of FE results)
to the standardised observations and asks for the candidate with the largest
expected improvement. Several candidates per step (``batch``) are chosen by the
"kriging believer" heuristic: each pick is assumed to return the GP mean, so the
next pick goes elsewhere.

The search stops when the budget is spent, when every candidate has been
evaluated, or when the largest expected improvement has stayed below
``ei_tolerance`` standard deviations of the observations for ``patience``
steps in a row (one low step is not enough: a start that missed the best
region fits a flat, overconfident model). Everything random derives from
``seed``, so a search is reproducible.

Use it ask/tell style::

    search = BayesianSearch(points, budget=20, seed=0)
    while batch := search.ask():
        for index in batch:
            search.tell(index, f(points[index]))     # or search.tell(index, None) if it failed
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.stats import norm
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel
from threadpoolctl import threadpool_limits


def expected_improvement(mean: np.ndarray, std: np.ndarray, best: float, xi: float = 0.01) -> np.ndarray:
    """E[max(f - best - xi, 0)] for f ~ N(mean, std^2) (maximisation)."""
    std = np.maximum(std, 1e-12)
    z = (mean - best - xi) / std
    return (mean - best - xi) * norm.cdf(z) + std * norm.pdf(z)


def latin_hypercube_indices(points: np.ndarray, count: int, rng: np.random.Generator) -> list[int]:
    """``count`` distinct rows of ``points`` nearest to a random Latin hypercube sample of the unit cube."""
    dims = points.shape[1]
    strata = np.column_stack([rng.permutation(count) for _ in range(dims)])
    targets = (strata + rng.random((count, dims))) / count
    chosen: list[int] = []
    for target in targets:
        distance = ((points - target) ** 2).sum(axis=1)
        distance[chosen] = np.inf
        chosen.append(int(np.argmin(distance)))
    return chosen


def gaussian_process(dims: int, seed: int) -> GaussianProcessRegressor:
    kernel = (ConstantKernel(1.0, (1e-3, 1e3))
              * Matern(length_scale=np.full(dims, 0.5), length_scale_bounds=(1e-2, 1e2), nu=2.5)
              + WhiteKernel(1e-4, (1e-8, 1e-1)))
    return GaussianProcessRegressor(kernel, normalize_y=False, n_restarts_optimizer=3, random_state=seed)


class BayesianSearch:
    """GP expected-improvement search over ``points`` (N, d) in the unit cube, maximising."""

    def __init__(self, points: np.ndarray, budget: int, seed: int = 0, initial: int | None = None,
                 batch: int = 1, ei_tolerance: float = 1e-3, patience: int = 3, xi: float = 0.01):
        if len(points) == 0:
            raise ValueError("the search has no candidates")
        self.points = np.asarray(points, dtype=float)
        self.budget = min(budget, len(points))
        self.seed, self.batch, self.ei_tolerance, self.patience, self.xi = seed, batch, ei_tolerance, patience, xi
        self._low_ei_steps = 0
        self.rng = np.random.default_rng(seed)
        dims = self.points.shape[1]
        count = min(initial if initial is not None else 2 * dims + 1, self.budget)
        self._initial = latin_hypercube_indices(self.points, count, self.rng)
        self.values: dict[int, float] = {}  # index -> observed value
        self.failed: set[int] = set()
        self.asked: list[int] = []
        self.stop_reason = ""
        self.last_max_ei: float | None = None  # in standard deviations of the observations

    @property
    def remaining(self) -> int:
        return self.budget - len(self.asked)

    def tell(self, index: int, value: float | None) -> None:
        """The observed value at ``index``; ``None`` (or a non-finite value) if the evaluation failed."""
        if value is None or not np.isfinite(value):
            self.failed.add(index)
        else:
            self.values[index] = float(value)

    def ask(self) -> list[int]:
        """The next candidates to evaluate (all of the initial design first); [] when the search is over."""
        if self.stop_reason:
            return []
        if not self.asked:
            picks = self._initial
        elif self.remaining <= 0:
            picks, self.stop_reason = [], f"budget of {self.budget} evaluations spent"
        elif len(self.asked) == len(self.points):
            picks, self.stop_reason = [], "every candidate evaluated"
        else:
            picks = self._propose(min(self.batch, self.remaining, len(self.points) - len(self.asked)))
        self.asked.extend(picks)
        return list(picks)

    def _propose(self, count: int) -> list[int]:
        open_ = np.setdiff1d(np.arange(len(self.points)), self.asked)
        observed = np.array(sorted(self.values), dtype=int)
        if len(observed) < 2:  # nothing to model yet (failures): keep exploring at random
            return [int(i) for i in self.rng.choice(open_, size=count, replace=False)]
        y = np.array([self.values[i] for i in observed])
        scale = y.std() or 1.0
        x_fit, y_fit = self.points[observed], (y - y.mean()) / scale
        gp = gaussian_process(self.points.shape[1], self.seed)
        picks: list[int] = []
        # one BLAS thread: on matrices this small, thread hand-offs cost 10x the arithmetic (L-BFGS-B)
        with warnings.catch_warnings(), threadpool_limits(limits=1):
            warnings.simplefilter("ignore", ConvergenceWarning)  # a length scale at its bound is fine here
            gp.fit(x_fit, y_fit)
            for _ in range(count):
                mean, std = gp.predict(self.points[open_], return_std=True)
                ei = expected_improvement(mean, std, y_fit.max(), self.xi)
                best = int(np.argmax(ei))
                if not picks:
                    self.last_max_ei = float(ei[best])
                    self._low_ei_steps = self._low_ei_steps + 1 if ei[best] < self.ei_tolerance else 0
                    if self._low_ei_steps >= self.patience:
                        self.stop_reason = (f"expected improvement below {self.ei_tolerance:g} sd "
                                            f"for {self.patience} steps in a row (last {ei[best]:.2g} sd)")
                        return []
                picks.append(int(open_[best]))
                # kriging believer: pretend the pick returned the GP mean, refit without re-tuning
                x_fit, y_fit = np.vstack([x_fit, self.points[open_[best]]]), np.append(y_fit, mean[best])
                open_ = np.delete(open_, best)
                if len(picks) < count:
                    gp = GaussianProcessRegressor(gp.kernel_, optimizer=None, normalize_y=False).fit(x_fit, y_fit)
        return picks
