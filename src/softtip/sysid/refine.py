"""Prediction-error refinement of a discrete innovations-form model (MATLAB's ``ssest`` after ``n4sid``).

The one-step predictor x^[t+1] = Ā x^[t] + B̄ u[t] + K y[t], ŷ[t] = C x^[t] + D u[t], with
Ā = A - KC and B̄ = B - KD, is fitted by scipy's trust-region least squares to the one-step
prediction errors of every trial (each from the zero state; each output divided by its standard
deviation, so that outputs in different units weigh alike). Parameters: every entry of Ā, B̄,
K, C and D, moved only across the n² directions of the similarity transforms x -> T x, which
change nothing of the predictor (MATLAB's data-driven local coordinates: θ = θ0 + Q η, Q an
orthonormal basis of the complement of those directions at the start). The Jacobian is exact:
the predictor's sensitivities to each entry are the responses of Ā to the signals x, u and y. The
states of one parameter vector serve both its errors and its Jacobian (the solver asks for both).

It stops when a step lowers the cost by less than ``tolerance`` of it (default 1e-4, MATLAB's
0.01 %) or after ``max_iterations`` evaluations (default 20, MATLAB's ``ssest`` default).

Stability: a refined model whose A (simulation) or Ā (predictor) is unstable, or whose cost is
not lower, is not used: the starting model is kept and the report says why. A run that stops at
its evaluation limit reports ``converged = False``.

:func:`parameter_covariance` gives the asymptotic covariance of the predictor's parameters in those
local coordinates (Ljung 1999, §9.3, for a weighted criterion: H⁻¹ (Σ_t J_tᵀ W Λ W J_t) H⁻¹, H =
JᵀJ, Λ the innovations' covariance), and the derivatives of (A, B, C, D) along each coordinate
(central differences, exact: the matrices are at most quadratic in the parameters), from which
:mod:`softtip.sysid.uncertainty` carries it to poles and frequency responses.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from softtip.sysid.simulation import state_sequence
from softtip.sysid.statespace import IdentificationError, StateSpace
from softtip.sysid.subspace import filtered_inputs


@dataclass(frozen=True)
class RefinementReport:
    """What the prediction-error refinement did."""

    converged: bool
    evaluations: int
    cost_before: float  # mean squared scaled one-step error of the starting model
    cost_after: float  # of the model returned
    used: bool  # False: the starting model was kept
    message: str

    def to_dict(self) -> dict:
        return asdict(self)


class _Predictor:
    """The scaled one-step errors of the trials and their exact Jacobian, as functions of the parameters."""

    def __init__(self, segments: list[tuple[np.ndarray, np.ndarray]], n: int, scale: np.ndarray):
        self.segments = segments
        self.n, self.nu, self.ny = n, segments[0][0].shape[1], segments[0][1].shape[1]
        self.scale = scale
        self.samples = sum(len(u) for u, _ in segments)
        n, nu, ny = self.n, self.nu, self.ny
        self.sizes = (n * n, n * nu, n * ny, ny * n, ny * nu)
        signals = n + nu + ny
        # sensitivity column c n + a (signal c into state a) -> parameter index of Ā, B̄ or K entry (a, c)
        a, c = np.meshgrid(np.arange(n), np.arange(signals), indexing="xy")
        within = np.where(c < n, a * n + c, np.where(c < n + nu, n * n + a * nu + (c - n),
                                                     n * n + n * nu + a * ny + (c - n - nu)))
        self.order = np.empty(signals * n, dtype=np.intp)
        self.order[within.ravel()] = np.arange(signals * n)
        self._last: tuple[np.ndarray, list[np.ndarray]] | None = None  # the parameters last run and their states

    def pack(self, system: StateSpace) -> np.ndarray:
        A, B, C, D, K = system.A, system.B, system.C, system.D, system.K
        return np.concatenate([(A - K @ C).ravel(), (B - K @ D).ravel(), K.ravel(), C.ravel(), D.ravel()])

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, ...]:
        n, nu, ny = self.n, self.nu, self.ny
        parts = np.split(theta, np.cumsum(self.sizes)[:-1])
        return (parts[0].reshape(n, n), parts[1].reshape(n, nu), parts[2].reshape(n, ny), parts[3].reshape(ny, n),
                parts[4].reshape(ny, nu))

    def local_coordinates(self, theta: np.ndarray) -> np.ndarray:
        """An orthonormal basis (p, p - n²) of the parameter directions that are not similarity
        transforms at ``theta``: the tangent of T -> (T Ā T⁻¹, T B̄, T K, C T⁻¹, D) at T = I is
        (EĀ - ĀE, E B̄, E K, -C E, 0) for every n x n E."""
        A_bar, B_bar, K, C, D = self.unpack(theta)
        n = self.n
        tangents = np.empty((n * n, theta.size))
        for index in range(n * n):
            E = np.zeros((n, n))
            E.flat[index] = 1.0
            tangents[index] = np.concatenate([(E @ A_bar - A_bar @ E).ravel(), (E @ B_bar).ravel(), (E @ K).ravel(),
                                              (-C @ E).ravel(), np.zeros(D.size)])
        left, singular, _ = np.linalg.svd(tangents.T, full_matrices=True)
        rank = int(np.sum(singular > 1e-10 * singular[0])) if singular.size and singular[0] > 0 else 0
        return left[:, rank:]

    def system(self, theta: np.ndarray, ts: float, covariance: np.ndarray) -> StateSpace:
        A_bar, B_bar, K, C, D = self.unpack(theta)
        return StateSpace(A_bar + K @ C, B_bar + K @ D, C, D, ts, K, covariance)

    def _states(self, theta: np.ndarray) -> list[np.ndarray]:
        """The predictor's states of every trial, run once per parameter vector."""
        if self._last is None or not np.array_equal(self._last[0], theta):
            A_bar, B_bar, K, _, _ = self.unpack(theta)
            self._last = theta.copy(), [state_sequence(A_bar, u @ B_bar.T + y @ K.T, np.zeros(self.n))
                                        for u, y in self.segments]
        return self._last[1]

    def errors(self, theta: np.ndarray) -> np.ndarray:
        """(N, ny) one-step errors, unscaled."""
        _, _, _, C, D = self.unpack(theta)
        with np.errstate(over="ignore", invalid="ignore"):
            return np.vstack([y - x @ C.T - u @ D.T
                              for (u, y), x in zip(self.segments, self._states(theta), strict=True)])

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        if np.max(np.abs(np.linalg.eigvals(self.unpack(theta)[0]))) >= 1:
            return np.full(self.samples * self.ny, np.inf)  # an unstable predictor: the solver steps back
        return (self.errors(theta) / self.scale).ravel() / np.sqrt(self.samples)

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        A_bar, _, _, C, _ = self.unpack(theta)
        n, nu, ny = self.n, self.nu, self.ny
        blocks = []
        for (u, y), x in zip(self.segments, self._states(theta), strict=True):
            N = len(u)
            dynamic = filtered_inputs(A_bar, C, np.hstack([x, u, y]))
            eye = np.eye(ny)
            static = np.concatenate([np.einsum("ab,tc->tabc", eye, x).reshape(N, ny, ny * n),
                                     np.einsum("ab,tc->tabc", eye, u).reshape(N, ny, ny * nu)], axis=2)
            blocks.append(-np.concatenate([dynamic[:, :, self.order], static], axis=2)
                          / self.scale[None, :, None])
        return np.vstack([block.reshape(-1, block.shape[2]) for block in blocks]) / np.sqrt(self.samples)


def refine(system: StateSpace, segments: list[tuple[np.ndarray, np.ndarray]], *, max_iterations: int = 20,
           tolerance: float = 1e-4) -> tuple[StateSpace, RefinementReport]:
    """The prediction-error refinement of the discrete innovations-form ``system`` on ``segments``."""
    K = np.zeros((system.n_states, system.n_outputs)) if system.K is None else system.K
    start = StateSpace(system.A, system.B, system.C, system.D, system.ts, K, system.noise_covariance)
    scale = np.std(np.vstack([y for _, y in segments]), axis=0)
    problem = _Predictor(segments, system.n_states, np.where(scale > 0, scale, 1.0))
    theta0 = problem.pack(start)
    before = problem.residuals(theta0)
    cost_before = float(before @ before)
    if not np.isfinite(cost_before):
        return start, RefinementReport(False, 0, cost_before, cost_before, False,
                                       "the starting predictor A - KC is unstable: not refined")
    basis = problem.local_coordinates(theta0)
    import scipy.optimize  # here, not at import: a command that refines nothing need not load it

    result = scipy.optimize.least_squares(lambda eta: problem.residuals(theta0 + basis @ eta), np.zeros(basis.shape[1]),
                                          jac=lambda eta: problem.jacobian(theta0 + basis @ eta) @ basis,
                                          method="trf", x_scale="jac", ftol=tolerance, max_nfev=max_iterations)
    theta = theta0 + basis @ result.x
    converged = result.status > 0
    notes = [result.message if converged else f"stopped after {result.nfev} evaluations without converging"]
    errors = problem.errors(theta)
    refined = problem.system(theta, system.ts, errors.T @ errors / len(errors))
    if not refined.is_stable():
        notes.append(f"the refined A is unstable (largest pole modulus {np.max(np.abs(refined.poles())):.4f}): "
                     "kept the subspace model")
    elif not 2 * result.cost < cost_before:
        notes.append("refinement did not lower the cost: kept the subspace model")
    else:
        return refined, RefinementReport(converged, result.nfev, cost_before, float(2 * result.cost), True,
                                         "; ".join(notes))
    return start, RefinementReport(converged, result.nfev, cost_before, cost_before, False, "; ".join(notes))


@dataclass(frozen=True, eq=False)
class StateSpaceCovariance:
    """The covariance (p, p) of a discrete innovations-form model's parameters in local coordinates η and
    the derivatives of its matrices along them: ``derivatives`` = (dA (p, n, n), dB (p, n, nu),
    dC (p, ny, n), dD (p, ny, nu))."""

    covariance: np.ndarray
    derivatives: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def parameter_covariance(system: StateSpace, segments: list[tuple[np.ndarray, np.ndarray]]) -> StateSpaceCovariance:
    """The parameter covariance of ``system`` (discrete, with K) from its one-step prediction errors on
    ``segments``; see the module notes. At a model that the refinement did not reach (a subspace
    estimate) it is the Gauss–Newton approximation at that point."""
    K = np.zeros((system.n_states, system.n_outputs)) if system.K is None else system.K
    start = StateSpace(system.A, system.B, system.C, system.D, system.ts, K, system.noise_covariance)
    scale = np.std(np.vstack([y for _, y in segments]), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    problem = _Predictor(segments, system.n_states, scale)
    theta0 = problem.pack(start)
    basis = problem.local_coordinates(theta0)
    jacobian = problem.jacobian(theta0) @ basis  # rows: sample-major, output-minor, as errors.ravel()
    errors = problem.errors(theta0)
    samples, ny = errors.shape
    parameters = basis.shape[1]
    if samples * ny <= parameters:
        raise IdentificationError(f"{samples} samples for {parameters} parameters: no covariance")
    innovations = errors.T @ errors / (samples - parameters / ny)
    weight = innovations / np.outer(scale, scale) / samples
    by_sample = jacobian.reshape(samples, ny, parameters)
    inverse = np.linalg.pinv(jacobian.T @ jacobian)
    middle = np.einsum("tip,ij,tjq->pq", by_sample, weight, by_sample)
    covariance = inverse @ middle @ inverse

    def matrices(theta):
        A_bar, B_bar, K, C, D = problem.unpack(theta)
        return A_bar + K @ C, B_bar + K @ D, C, D

    steps = 1e-6 * np.maximum(1.0, np.abs(basis.T @ theta0))
    derivatives = [[] for _ in range(4)]
    for k in range(parameters):
        ahead, behind = matrices(theta0 + steps[k] * basis[:, k]), matrices(theta0 - steps[k] * basis[:, k])
        for slot, (a, b) in enumerate(zip(ahead, behind)):
            derivatives[slot].append((a - b) / (2 * steps[k]))
    return StateSpaceCovariance((covariance + covariance.T) / 2, tuple(np.array(d) for d in derivatives))
