"""Subspace identification of discrete state-space models: N4SID, MOESP and CVA.

The three are weightings of one computation (Van Overschee & De Moor's unifying theorem). With
block Hankel matrices of ``i`` past and ``i`` future samples of inputs and outputs (Up, Uf, Yp,
Yf; past data Wp = [Up; Yp]), the oblique projection O = Yf /_Uf Wp is weighted, W1 O W2, and
its singular value decomposition gives the order and the extended observability matrix
Γ = W1^-1 U1 S1^½:

=======  ================================  ====================
method   W1                                W2
=======  ================================  ====================
n4sid    I                                 I
moesp    I                                 Π⊥Uf (removes Uf)
cva      ((Yf Π⊥Uf)(Yf Π⊥Uf)ᵀ)^-½          Π⊥Uf
=======  ================================  ====================

Every projection runs on the triangular factor L of the LQ decomposition of the stacked data
matrix, not on the data (they share their row-space geometry). Several trials contribute
their Hankel columns side by side. Then:

- C is the first block row of Γ and A solves Γ_up A = Γ_down (shift invariance);
- B, D and each trial's initial state solve a linear least-squares problem on the outputs
  (each output scaled by its standard deviation), which keeps B and D unbiased for coloured
  inputs;
- the state sequences X_i = Γ^+ O_i and X_i+1 = Γ_up^+ O_i-1, regressed jointly with the outputs
  Y_i|i on [X_i; U_i|i] (N4SID's second algorithm), leave the residuals of the state and output
  equations; their covariances (Q, S, R) give the Kalman gain K of the innovations form through
  the discrete Riccati equation (scipy.linalg.solve_discrete_are). (The residuals of A and C from
  Γ and of B and D from the output error would carry those estimators' biases into Q and R, and
  give a worse predictor.)

Order rule (``order="auto"``): the n in 1..max_order with the largest drop between consecutive
singular values, ``argmax log(σ_n / σ_n+1)``. Unstable poles of A are reflected into the unit
circle (λ -> 1/conj λ) before B and D are estimated, and counted, unless ``enforce_stability`` is off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from softtip.sysid.recording import MAGNITUDE_RANGE
from softtip.sysid.simulation import free_response
from softtip.sysid.statespace import IdentificationError, StateSpace

METHODS = ("n4sid", "moesp", "cva")
AUTO = "auto"  # the order from the singular values
MAX_ORDER = 12
_LONGEST_HORIZON = 60  # block rows a data-chosen horizon may take at most


def minimum_horizon(max_order: int, n_outputs: int) -> int:
    """The fewest block rows for ``max_order`` states: (horizon - 1) outputs > order (Γ_up has more rows than states)."""
    return max(2, math.ceil((max_order + 1) / n_outputs) + 1)


def arx_lag(segments: list[tuple[np.ndarray, np.ndarray]], longest: int) -> tuple[int, np.ndarray]:
    """The number of past samples an ARX model y[t] = Σ_k (A_k y[t-k] + B_k u[t-k]) + e needs, by AIC
    over 1..``longest`` (as MATLAB's n4sid chooses its horizon from the data): every lag's residual
    covariance from one QR factor of [Φ_longest | Y] (the regressors ordered by lag, so each smaller
    model's are a prefix). Returns (lag, AIC per lag)."""
    nu, ny = segments[0][0].shape[1], segments[0][1].shape[1]
    blocks = []
    for u, y in segments:
        if len(u) <= longest:
            continue
        t = np.arange(longest, len(u))
        lagged = [np.hstack([y[t - k], u[t - k]]) for k in range(1, longest + 1)]
        blocks.append(np.hstack([*lagged, y[t]]))
    data = np.vstack(blocks)
    N, width = len(data), longest * (nu + ny)
    scale = np.std(data, axis=0)
    R = np.linalg.qr(data / np.where(scale > 0, scale, 1.0), mode="r")
    criteria = np.full(longest, np.inf)
    for lag in range(1, longest + 1):
        k = lag * (nu + ny)
        tail = R[k:, width:]
        _, log_det = np.linalg.slogdet(tail.T @ tail / N)
        criteria[lag - 1] = N * log_det + 2 * k * ny
    return int(np.argmin(criteria)) + 1, criteria


def data_horizon(segments: list[tuple[np.ndarray, np.ndarray]], max_order: int) -> int:
    """Block rows from the data: the ARX lag by AIC (:func:`arx_lag`, up to the longest lag that leaves ten
    samples per regressor and a window of the trial), at least :func:`minimum_horizon`, at most what the
    data can fill (2 horizon (nu + ny) Hankel columns)."""
    nu, ny = segments[0][0].shape[1], segments[0][1].shape[1]
    samples = sum(len(u) for u, _ in segments)
    fewest = minimum_horizon(max_order, ny)
    most = min(max(len(u) for u, _ in segments) // 4, samples // (10 * (nu + ny)), _LONGEST_HORIZON)
    if most <= fewest:
        return fewest
    lag, _ = arx_lag(segments, most)
    # the columns 2 i (nu + ny) <= N - 2 i + 1 must fill the Hankel matrices
    fillable = max(fewest, (samples + 1) // (2 * (nu + ny) + 2))
    return int(min(max(lag, fewest), fillable))


def order_from_singular_values(singular_values: np.ndarray, max_order: int) -> int:
    """The n in 1..max_order whose singular value most exceeds the next: argmax log(σ_n / σ_n+1)."""
    s = np.asarray(singular_values)[:max_order + 1]
    floor = np.finfo(float).tiny
    gaps = np.log(np.maximum(s[:-1], floor)) - np.log(np.maximum(s[1:], floor))
    return int(np.argmax(gaps)) + 1


@dataclass(frozen=True, eq=False)
class SubspaceResult:
    """A subspace identification: the system (discrete, with K), and how it was found."""

    system: StateSpace
    singular_values: np.ndarray
    order: int
    horizon: int
    method: str
    reflected_poles: int
    kalman: str  # how K was obtained


def _hankel_rows(signal: np.ndarray, block_rows: int) -> np.ndarray:
    """The transposed block Hankel matrix: one row per window of ``block_rows`` samples, flattened."""
    windows = np.lib.stride_tricks.sliding_window_view(signal, block_rows, axis=0)  # (j, m, rows)
    return windows.transpose(0, 2, 1).reshape(len(windows), -1)


class _Geometry:
    """Row blocks of the LQ factor of [U_0|2i-1; Y_0|2i-1] and the projections between them."""

    def __init__(self, segments: list[tuple[np.ndarray, np.ndarray]], horizon: int):
        i = horizon
        nu, ny = segments[0][0].shape[1], segments[0][1].shape[1]
        data = np.vstack([np.hstack([_hankel_rows(u, 2 * i), _hankel_rows(y, 2 * i)])
                          for u, y in segments if len(u) >= 2 * i])
        self.columns = len(data)
        with np.errstate(over="ignore", invalid="ignore"):
            self.L = np.linalg.qr(data, mode="r").T
        if not np.all(np.isfinite(self.L)):
            # a least-squares solve on a matrix of NaN may never return: refuse before it
            raise IdentificationError("subspace identification: the data's triangular factor is not finite "
                                      "(magnitudes too large for double precision: rescale the signals)")
        self.nu, self.ny = nu, ny
        self._first_y = 2 * i * nu

    def u(self, first: int, last: int) -> np.ndarray:
        """The rows of input block rows ``first`` .. ``last`` - 1."""
        return np.arange(first * self.nu, last * self.nu)

    def y(self, first: int, last: int) -> np.ndarray:
        """The rows of output block rows ``first`` .. ``last`` - 1."""
        return self._first_y + np.arange(first * self.ny, last * self.ny)

    def rows(self, *blocks: np.ndarray) -> np.ndarray:
        return self.L[np.concatenate(blocks)]

    @staticmethod
    def regress(target: np.ndarray, regressors: np.ndarray) -> np.ndarray:
        """θ minimising ||target - θ regressors|| (row spaces; least-norm where rank-deficient)."""
        return np.linalg.lstsq(regressors.T, target.T, rcond=None)[0].T

    def oblique(self, future_y: np.ndarray, future_u: np.ndarray, past: np.ndarray) -> np.ndarray:
        """Yf /_Uf Wp: the part along the past of the projection of the future outputs on past and future inputs."""
        theta = self.regress(future_y, np.vstack([past, future_u]))
        return theta[:, :len(past)] @ past

    def remove(self, rows: np.ndarray, along: np.ndarray) -> np.ndarray:
        """rows Π⊥along: what of ``rows`` is orthogonal to the row space of ``along``."""
        return rows - self.regress(rows, along) @ along


def _reflect_unstable(A: np.ndarray) -> tuple[np.ndarray, int]:
    """A with every eigenvalue outside the unit circle reflected to 1/conj(λ), and how many were."""
    values, vectors = np.linalg.eig(A)
    outside = np.abs(values) >= 1
    if not outside.any():
        return A, 0
    values = np.where(outside, 1 / np.conj(values), values)
    return np.real(vectors @ np.diag(values) @ np.linalg.inv(vectors)), int(outside.sum())


def filtered_inputs(A: np.ndarray, C: np.ndarray, u: np.ndarray) -> np.ndarray:
    """For every sample t, C Σ_s<t A^(t-1-s) E_ab u_b(s) for every entry (a, b) of B: (N, ny, nu n),
    column b n + a, the outputs' sensitivity to B in x[t+1] = A x + B u, y = C x (from the zero state)."""
    n, nu = A.shape[0], u.shape[1]
    diagonal = (np.arange(n)[None, :] * (nu * n) + np.arange(nu)[:, None] * n + np.arange(n)[None, :]).ravel()
    response = np.zeros((n, nu * n))
    out = np.empty((len(u), C.shape[0], nu * n))
    for t in range(len(u)):
        out[t] = C @ response
        response = A @ response
        response.flat[diagonal] += np.repeat(u[t], n)
    return out


def input_matrices(A: np.ndarray, C: np.ndarray, segments: list[tuple[np.ndarray, np.ndarray]],
                   scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """B and D minimising the scaled output error of x[t+1] = A x + B u, y = C x + D u, each trial from
    an initial state of its own (estimated alongside and dropped)."""
    n, ny, nu = A.shape[0], C.shape[0], segments[0][0].shape[1]
    shared = nu * n + ny * nu
    blocks, targets = [], []
    for k, (u, y) in enumerate(segments):
        N = len(u)
        rows = np.zeros((N, ny, shared + n * len(segments)))
        rows[:, :, :nu * n] = filtered_inputs(A, C, u)
        rows[:, :, nu * n:shared] = np.einsum("ac,tb->tacb", np.eye(ny), u).reshape(N, ny, ny * nu)
        rows[:, :, shared + k * n:shared + (k + 1) * n] = free_response(A, C, N)
        blocks.append((rows / scale[None, :, None]).reshape(N * ny, -1))
        targets.append((y / scale).ravel())
    theta = np.linalg.lstsq(np.vstack(blocks), np.concatenate(targets), rcond=None)[0]
    B = theta[:nu * n].reshape(nu, n).T
    D = theta[nu * n:shared].reshape(ny, nu)
    return B, D


def _kalman_gain(A: np.ndarray, C: np.ndarray, covariance: np.ndarray, output_scale: float
                 ) -> tuple[np.ndarray, np.ndarray, str]:
    """K and the innovations covariance from the residual covariance [[Q, S], [Sᵀ, R]] (DARE)."""
    n = A.shape[0]
    covariance = (covariance + covariance.T) / 2
    Q, S, R = covariance[:n, :n], covariance[:n, n:], covariance[n:, n:]
    if np.max(np.linalg.eigvalsh(R)) <= 1e-12 * output_scale:
        return np.zeros((n, C.shape[0])), R, "no output noise in the residuals: K = 0"
    try:
        P = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R, s=S)
    except (np.linalg.LinAlgError, ValueError) as problem:
        return np.zeros((n, C.shape[0])), R, f"Riccati equation unsolved ({problem}): K = 0"
    innovations = C @ P @ C.T + R
    K = np.linalg.solve(innovations.T, (A @ P @ C.T + S).T).T
    return K, (innovations + innovations.T) / 2, "Kalman gain from the residual covariances (Riccati)"


def subspace_identify(segments: list[tuple[np.ndarray, np.ndarray]], ts: float, order: int | str = AUTO,
                      method: str = "moesp", *, horizon: int | None = None, max_order: int = MAX_ORDER,
                      enforce_stability: bool = True) -> SubspaceResult:
    """A discrete innovations-form model of the trials ``segments`` ((u, y) each) at sample time ``ts``."""
    if method not in METHODS:
        raise IdentificationError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    largest_value = max(float(np.max(np.abs(signal), initial=0.0)) for pair in segments for signal in pair)
    if not largest_value <= MAGNITUDE_RANGE[1]:
        # beyond it the Hankel matrices' squares overflow, and LAPACK's least squares on them may never return
        raise IdentificationError(f"subspace identification: values up to {largest_value:.3g}, beyond "
                                  f"{MAGNITUDE_RANGE[1]:g}: rescale the signals")
    nu, ny = segments[0][0].shape[1], segments[0][1].shape[1]
    largest = max_order if order == AUTO else order
    i = data_horizon(segments, largest) if horizon is None else horizon
    if i * ny <= largest or (i - 1) * ny < largest:
        raise IdentificationError(f"horizon = {i}: too short for order {largest} with {ny} output(s) "
                                  f"(needs (horizon - 1) x outputs >= order)")
    needed = 2 * i * (nu + ny)
    columns = sum(max(len(u) - 2 * i + 1, 0) for u, _ in segments)
    if columns < needed:
        raise IdentificationError(
            f"too few samples for order {largest}: a horizon of {i} needs trials longer than {2 * i} samples and at "
            f"least {needed} windows of {2 * i} samples in all (a trial of N samples gives N - {2 * i - 1}); "
            f"the recording gives {columns}")
    g = _Geometry(segments, i)
    past, future_u, future_y = g.rows(g.u(0, i), g.y(0, i)), g.rows(g.u(i, 2 * i)), g.rows(g.y(i, 2 * i))
    projection = g.oblique(future_y, future_u, past)
    if method == "n4sid":
        weighted, unweight = projection, None
    else:
        weighted = g.remove(projection, future_u)
        unweight = None
        if method == "cva":
            residual = g.remove(future_y, future_u)
            values, vectors = np.linalg.eigh(residual @ residual.T)
            keep = values > 1e-12 * values.max()
            values, vectors = values[keep], vectors[:, keep]
            weighted = (vectors / np.sqrt(values)) @ vectors.T @ weighted
            unweight = (vectors * np.sqrt(values)) @ vectors.T
    left, singular_values, _ = np.linalg.svd(weighted, full_matrices=False)
    n = order_from_singular_values(singular_values, min(max_order, len(singular_values) - 1)) \
        if order == AUTO else int(order)
    gamma = left[:, :n] * np.sqrt(singular_values[:n])
    if unweight is not None:
        gamma = unweight @ gamma
    C = gamma[:ny]
    A = np.linalg.lstsq(gamma[:-ny], gamma[ny:], rcond=None)[0]
    reflected = 0
    if enforce_stability:
        A, reflected = _reflect_unstable(A)
    scale = np.std(np.vstack([y for _, y in segments]), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    B, D = input_matrices(A, C, segments, scale)

    # the innovations' statistics from the state sequences X_i and X_i+1
    states = np.linalg.pinv(gamma) @ projection
    shifted_projection = g.oblique(g.rows(g.y(i + 1, 2 * i)), g.rows(g.u(i + 1, 2 * i)),
                                   g.rows(g.u(0, i + 1), g.y(0, i + 1)))
    next_states = np.linalg.pinv(gamma[:-ny]) @ shifted_projection
    u_now, y_now = g.rows(g.u(i, i + 1)), g.rows(g.y(i, i + 1))
    regressors, targets = np.vstack([states, u_now]), np.vstack([next_states, y_now])
    residuals = targets - _Geometry.regress(targets, regressors) @ regressors
    covariance = residuals @ residuals.T / g.columns
    K, innovations, kalman = _kalman_gain(A, C, covariance, np.trace(y_now @ y_now.T) / (g.columns * ny))
    system = StateSpace(A, B, C, D, ts, K, innovations)
    return SubspaceResult(system, singular_values, n, i, method, reflected, kalman)
