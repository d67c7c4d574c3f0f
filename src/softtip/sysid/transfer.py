"""Continuous-time transfer-function matrices identified from sampled data (what MATLAB's ``tfest`` does).

Model. Each of the ``ny`` outputs is a multiple-input single-output (MISO) problem

    y_i(t_k) = sum_j B_ij(s)/A_ij(s) u_j(t) |_(t = t_k) + e_i(t_k),

every entry with its own monic denominator ``A_ij`` (``n_poles`` roots) and numerator ``B_ij``
(``n_zeros`` roots). The inputs are held constant between samples (zero-order hold, MATLAB's
``InterSample = 'zoh'``) and every segment (trial) starts from rest, so each entry's response at the
sample times is computed exactly: the continuous state equation is discretised by the matrix
exponential of an augmented matrix (Van Loan), and the discrete recursion x[k+1] = Phi x[k] +
Gamma v[k] of all entries and segments runs at once, lifted to blocks of steps (matrix products
inside a block, a short loop over blocks).

Method.

1. Initialisation by the simplified refined instrumental-variable method for continuous-time
   systems, SRIVC (Young & Jakeman 1980): the data are prefiltered by 1/A of the current estimate
   and (A, B) re-estimated by instrumental variables whose instruments are the prefiltered
   noise-free response B/A u, until the estimate stops moving. For MISO systems with different
   denominators it runs in two stages (Garnier, Gilson, Young & Huselstein 2007):
   a. the MISO model with one common denominator per output (of each order its entries have),
      started from a state-variable filter 1/(s + lambda)^n as prefilter and least squares, lambda
      the output's root-mean-square frequency (no setting), taken to a loose tolerance;
   b. every entry with its own denominator from there by iterative backfitting: entry (i, j) is
      re-estimated from the output less the current simulated responses of the other inputs
      (Gauss–Seidel over the inputs), sweep after sweep.
   With ZOH inputs filtered exactly the true parameters are a fixed point of the iteration whatever
   the output's intersample behaviour (Pan, González, Welsh & Rojas 2020); the output is
   interpolated linearly between samples (first-order hold), filtered exactly too. An estimate with
   unstable poles is reflected into the left half-plane before it serves as a prefilter (as in the
   CONTSID toolbox). The iteration is not a contraction for every order and noise level (high orders
   with poorly determined poles wander), so each problem stops when its simulation error has not
   improved for a few sweeps and keeps its best iterate; the report says whether SRIVC converged.
2. Refinement (``refine=True``) by prediction-error minimisation for the output-error model: the
   sum of squared simulation errors over all segments, output by output, by
   ``scipy.optimize.least_squares`` (trust region reflective) with the analytic Jacobian. The output
   sensitivities are filtered signals, d y/d b_k = s^k/A u and d y/d a_k = -s^k B/A^2 u: they are the
   states of the 2n-state system 1/A driven by u followed by 1/A driven by B/A u, simulated with the
   same exact ZOH machinery (they are also SRIVC's instruments). Its tolerance bounds the relative
   decrease of the cost in an iteration (like MATLAB's); steps and gradients must fall below its square.
3. Stability (``enforce_stability=True``): if the refined estimate of an output has unstable poles,
   they are mirrored into the left half-plane, that output's numerators re-fitted by linear least
   squares (the simulation error is linear in them) and the refinement run again among stable
   models only (an unstable trial step is refused); the number of mirrored poles is reported.

Scaling: every entry is parametrised in a time unit of its own, 1/omega with omega the geometric
mean of its poles' magnitudes (the state-variable filter's cutoff at the start), so that the
coefficients of high orders stay of order one and the companion forms are well conditioned; the
public coefficients are in seconds.

References.
- P. C. Young, A. J. Jakeman, "Refined instrumental variable methods of recursive time-series
  analysis Part III. Extensions", Int. J. Control 31(4), 741–764, 1980.
- H. Garnier, M. Gilson, P. C. Young, E. Huselstein, "An optimal IV technique for identifying
  continuous-time transfer function model of multiple input systems", Control Eng. Practice 15(4),
  471–486, 2007.
- H. Garnier, L. Wang (eds.), "Identification of Continuous-time Models from Sampled Data",
  Springer, 2008 (chapters on SRIVC and the CONTSID toolbox).
- S. Pan, R. A. González, J. S. Welsh, C. R. Rojas, "Consistency analysis of the simplified refined
  instrumental variable method for continuous-time systems", Automatica 113, 108767, 2020.
- L. Ljung, "System Identification: Theory for the User", 2nd ed., Prentice Hall, 1999 (output-error
  prediction-error method; the fit percentage).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from math import comb

import numpy as np
from scipy import linalg

from softtip._core.threads import single_threaded_blas
from softtip.sysid.metrics import fit_percent
from softtip.sysid.realisation import companion, output_map
from softtip.sysid.robust import COVARIANCES, SANDWICH, sandwich_covariance
from softtip.sysid.statespace import IdentificationError

# SRIVC sweeps without a relative improvement of the simulation error after which an SRIVC problem
# keeps its best iterate; the common-denominator stage before backfitting only starts it, to this
# relative change of its parameters
_PATIENCE, _IMPROVEMENT, _STARTING_TOLERANCE = 5, 1e-5, 1e-3
# steps per block of the lifted state recursion; samples per chunk of a long simulation
_BLOCK, _CHUNK = 16, 1 << 15


# ------------------------------------------------------------------------------------------ the model


def _polynomial(value, name: str) -> np.ndarray:
    array = np.array(value, dtype=float, ndmin=1)
    if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected a non-empty 1-D array of finite coefficients")
    array.setflags(write=False)
    return array


def _table(rows, name: str) -> tuple[tuple[np.ndarray, ...], ...]:
    if not isinstance(rows, Sequence) or not rows or not all(isinstance(row, Sequence) and row for row in rows):
        raise ValueError(f"{name}: expected a non-empty [output][input] table of coefficient arrays")
    if len({len(row) for row in rows}) != 1:
        raise ValueError(f"{name}: expected every output to have the same number of inputs")
    return tuple(tuple(_polynomial(entry, f"{name}[{i}][{j}]") for j, entry in enumerate(row))
                 for i, row in enumerate(rows))


# numpy arrays have no truth value: equality is identity (eq=False), the arrays are read-only
@dataclass(frozen=True, eq=False)
class TransferFunctionMatrix:
    """G(s): ny x nu scalar continuous-time transfer functions, numerators/denominators as coefficient
    arrays in descending powers of s, each denominator monic."""

    numerators: tuple[tuple[np.ndarray, ...], ...]  # [output][input]
    denominators: tuple[tuple[np.ndarray, ...], ...]

    def __post_init__(self):
        numerators = _table(self.numerators, "numerators")
        denominators = _table(self.denominators, "denominators")
        if len(numerators) != len(denominators) or len(numerators[0]) != len(denominators[0]):
            raise ValueError(f"numerators ({len(numerators)} x {len(numerators[0])}) and denominators "
                             f"({len(denominators)} x {len(denominators[0])}): expected the same ny x nu shape")
        for i, (row_b, row_a) in enumerate(zip(numerators, denominators)):
            for j, (b, a) in enumerate(zip(row_b, row_a)):
                if a[0] != 1.0:
                    raise ValueError(f"denominators[{i}][{j}]: expected a monic polynomial (leading coefficient 1), "
                                     f"got {a[0]:g}")
                if len(b) > len(a):
                    raise ValueError(f"numerators[{i}][{j}]: degree {len(b) - 1} exceeds the denominator's "
                                     f"{len(a) - 1} (expected a proper transfer function)")
        object.__setattr__(self, "numerators", numerators)
        object.__setattr__(self, "denominators", denominators)

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.denominators), len(self.denominators[0])

    @property
    def n_poles(self) -> np.ndarray:
        """Degree of each entry's denominator, (ny, nu)."""
        return np.array([[len(a) - 1 for a in row] for row in self.denominators])

    @property
    def n_zeros(self) -> np.ndarray:
        """Degree of each entry's numerator as stored (leading zeros count), (ny, nu)."""
        return np.array([[len(b) - 1 for b in row] for row in self.numerators])

    def poles(self) -> list[list[np.ndarray]]:
        """The roots of each entry's denominator, [output][input]."""
        return [[np.roots(a) for a in row] for row in self.denominators]

    def is_stable(self) -> bool:
        """Whether every pole of every entry lies strictly in the left half-plane."""
        return all(np.all(p.real < 0) for row in self.poles() for p in row)

    def frequency_response(self, omega: np.ndarray) -> np.ndarray:
        """G(j omega) at the angular frequencies ``omega`` (rad/s): (len(omega), ny, nu) complex."""
        omega = np.asarray(omega, dtype=float)
        if omega.ndim != 1 or not np.all(np.isfinite(omega)):
            raise ValueError("omega: expected a 1-D array of finite angular frequencies in rad/s")
        s = 1j * omega
        return np.stack([np.stack([np.polyval(b, s) / np.polyval(a, s) for b, a in zip(row_b, row_a)], axis=-1)
                         for row_b, row_a in zip(self.numerators, self.denominators)], axis=-2)

    def dc_gain(self) -> np.ndarray:
        """G(0), (ny, nu); ±inf for an entry with a pole at the origin."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.array([[b[-1] / a[-1] for b, a in zip(row_b, row_a)]
                             for row_b, row_a in zip(self.numerators, self.denominators)])


# ------------------------------------------------------------------------- exact ZOH simulation kernels


def _rescaled(a: np.ndarray, numerators: list[np.ndarray], ratio: float):
    """Ascending coefficients of A (monic, degree len(a)) and of its numerators in a time unit
    ``ratio`` times shorter: a_k ratio^(n - k)."""
    n = len(a)
    return a * ratio ** (n - np.arange(n)), [b * ratio ** (n - np.arange(len(b))) for b in numerators]


def _discretised(matrices: np.ndarray, inputs: np.ndarray, steps: np.ndarray, linear: bool):
    """Exact discretisation of x' = M x + g v over the steps h (E,) for v held constant between
    samples (``linear`` false: zero-order hold) or linear between them (first-order hold):
    x[k+1] = Phi x[k] + Gamma0 v[k] + Gamma1 v[k+1], from the exponential of [[M, g, 0], [0, 0, 1/h],
    [0, 0, 0]] h (Van Loan): its blocks are Phi = e^{Mh}, G0 = int_0^h e^{M s} g ds and
    G1 = int_0^h e^{M s} g (h - s)/h ds, the response to a unit ramp over the step, so that
    Gamma0 = G0 - G1 and Gamma1 = G1 (ZOH: Gamma0 = G0, Gamma1 = 0). Returns (Phi, Gamma0, Gamma1)."""
    count, n, _ = matrices.shape
    size = n + 2 if linear else n + 1
    augmented = np.zeros((count, size, size))
    augmented[:, :n, :n] = matrices * steps[:, None, None]
    augmented[:, :n, n] = inputs * steps[:, None]
    if linear:
        augmented[:, n, n + 1] = 1.0
    exponential = linalg.expm(augmented)
    phi, hold = exponential[:, :n, :n], exponential[:, :n, n]
    if not linear:
        return phi, hold, np.zeros_like(hold)
    ramp = exponential[:, :n, n + 1]
    return phi, hold - ramp, ramp


def _recursion_states(phi: np.ndarray, gamma: np.ndarray, v: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """States x[k], k = 0..N-1, of x[k+1] = Phi x[k] + gamma v[k], x[0] = ``initial``, for E systems
    and c signals each: phi (E, n, n), gamma (E, n), v (E, c, N), initial (E, n, c) -> (E, n, c, N).

    The recursion is lifted to blocks of L steps: inside a block the states are the powers Phi^r
    applied to the block's first state plus the convolution of its inputs with the Markov
    parameters Phi^d gamma, both one matrix product for all blocks at once; only the first states
    of the blocks are carried from block to block in a loop, N/L steps long."""
    count, n = gamma.shape
    signals, length = v.shape[1:]
    steps = min(_BLOCK, length)
    blocks = -(-length // steps)
    padded = np.zeros((count, signals, blocks * steps))
    padded[:, :, :length] = v
    by_step = padded.reshape(count, signals * blocks, steps).transpose(0, 2, 1)  # (E, L, c blocks)
    powers = np.empty((count, steps + 1, n, n))
    powers[:, 0] = np.eye(n)
    for r in range(1, steps + 1):
        powers[:, r] = phi @ powers[:, r - 1]
    markov = (powers[:, :steps] @ gamma[:, None, :, None])[..., 0]  # Phi^d gamma, (E, L, n)
    row, column = np.indices((steps + 1, steps))
    lag = row - 1 - column
    toeplitz = markov[:, np.maximum(lag, 0)]  # input j's effect on the state r steps into the block
    toeplitz[:, lag < 0] = 0.0
    forced = (toeplitz.transpose(0, 1, 3, 2).reshape(count, (steps + 1) * n, steps) @ by_step)
    forced = forced.reshape(count, steps + 1, n, signals, blocks)
    carried = np.ascontiguousarray(forced[:, steps].transpose(3, 0, 1, 2))
    starts = np.empty((blocks, count, n, signals))
    state = initial
    for block in range(blocks):
        starts[block] = state
        state = powers[:, steps] @ state + carried[block]
    free = powers[:, :steps].reshape(count, steps * n, n) @ starts.transpose(1, 2, 3, 0).reshape(count, n, -1)
    states = free.reshape(count, steps, n, signals, blocks) + forced[:, :steps]
    return states.transpose(0, 2, 3, 4, 1).reshape(count, n, signals, blocks * steps)[..., :length]


def _discrete_systems(systems, steps, linear: bool = False):
    """E continuous systems (M, g) of any sizes, padded to the largest, discretised over their steps:
    (Phi, Gamma0, Gamma1) as :func:`_discretised` gives them."""
    size = max(len(g) for _, g in systems)
    matrices = np.zeros((len(systems), size, size))
    gains = np.zeros((len(systems), size))
    for e, (matrix, gain) in enumerate(systems):
        matrices[e, :len(gain), :len(gain)] = matrix
        gains[e, :len(gain)] = gain
    return _discretised(matrices, gains, np.asarray(steps, dtype=float), linear)


def _advanced(phi, gamma, ramp, v: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """States x[k], k = 0..N-1, of x[k+1] = Phi x[k] + Gamma0 v[k] + Gamma1 v[k+1] from x[0] = ``initial``
    (E, n, c): z[k] = x[k] - Gamma1 v[k] follows z[k+1] = Phi z[k] + (Gamma0 + Phi Gamma1) v[k]."""
    states = _recursion_states(phi, gamma + (phi @ ramp[..., None])[..., 0], v,
                               initial - ramp[:, :, None] * v[:, None, :, 0])
    states += ramp[:, :, None, None] * v[:, None]
    return states


def _states(systems, steps, v: np.ndarray, linear: bool = False) -> list[np.ndarray]:
    """Exact states from rest of E continuous systems (M, g) of any sizes, each driven by its own c
    signals held between samples (``linear``: interpolated linearly): v (E, c, N) -> [(n_e, c, N)]."""
    phi, gamma, ramp = _discrete_systems(systems, steps, linear)
    states = _advanced(phi, gamma, ramp, v, np.zeros(gamma.shape + v.shape[1:2]))
    return [states[e, :len(gain)] for e, (_, gain) in enumerate(systems)]


def _filter_systems(a_list) -> list[tuple[np.ndarray, np.ndarray]]:
    """The filters 1/A (ascending normalised coefficients ``a``) in controllable canonical form."""
    systems = []
    for a in a_list:
        gain = np.zeros(len(a))
        gain[-1] = 1.0
        systems.append((companion(a), gain))
    return systems


def _filter_states(a_list, steps, v: np.ndarray, linear: bool = False) -> list[np.ndarray]:
    """States s^k/A v (k < n) of the filters 1/A for v held between samples (``linear``:
    interpolated linearly)."""
    return _states(_filter_systems(a_list), steps, v, linear)


def _sensitivity_states(a_list, b_list, steps, v: np.ndarray) -> list[np.ndarray]:
    """States of 1/A v (xi_k = s^k/A v) followed by 1/A driven by B/A v (eta_k = s^k B/A^2 v):
    (2n, c, N) per entry. They give the response, its derivatives with respect to b (xi) and a
    (-eta), and SRIVC's instruments."""
    systems = []
    for a, b in zip(a_list, b_list):
        n = len(a)
        output, direct = output_map(a, b)
        matrix = np.zeros((2 * n, 2 * n))
        matrix[:n, :n] = matrix[n:, n:] = companion(a)
        matrix[-1, :n] += output
        gain = np.zeros(2 * n)
        gain[n - 1], gain[-1] = 1.0, direct
        systems.append((matrix, gain))
    return _states(systems, steps, v)


def _response(a: np.ndarray, b: np.ndarray, xi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """B/A v from the states xi_k = s^k/A v (n, ...) and v."""
    output, direct = output_map(a, b)
    return np.tensordot(output, xi, axes=1) + direct * v


def _normalised(tf: TransferFunctionMatrix, omega: float):
    """Ascending coefficients of every entry in the time unit 1/omega: a_k omega^(k - n)."""
    scaled = [_rescaled(a[:0:-1], [b[::-1]], 1.0 / omega) for row_b, row_a in zip(tf.numerators, tf.denominators)
              for b, a in zip(row_b, row_a)]
    return [a for a, _ in scaled], [b for _, (b,) in scaled]


def simulate(tf: TransferFunctionMatrix, u: np.ndarray, ts: float) -> np.ndarray:
    """The response y (N, ny) of ``tf`` from rest to the input u (N, nu) held constant between
    samples (zero-order hold), exact at the sample times t_k = k ts."""
    ts = _sample_time(ts)
    u = np.asarray(u, dtype=float)
    ny, nu = tf.shape
    if u.ndim != 2 or u.shape[1] != nu or len(u) == 0:
        raise ValueError(f"u: expected an (N, {nu}) array of input samples, got shape {u.shape}")
    if not np.all(np.isfinite(u)):
        raise ValueError("u: contains NaN or infinite values")
    # time in samples: the entries' coefficients in units of ts
    a_list, b_list = _normalised(tf, 1.0 / ts)
    y = np.empty((len(u), ny))
    with single_threaded_blas():
        phi, gamma, ramp = _discrete_systems(_filter_systems(a_list), np.ones(ny * nu))
        state = np.zeros(gamma.shape + (1,))
        for start in range(0, len(u), _CHUNK):  # the states of a long record in chunks
            inputs = np.tile(u[start:start + _CHUNK].T[:, None, :], (ny, 1, 1))  # entry (i, j) is driven by u_j
            states = _advanced(phi, gamma, ramp, inputs, state)
            responses = [_response(a, b, x[:len(a), 0], v[0]) for a, b, x, v in zip(a_list, b_list, states, inputs)]
            y[start:start + _CHUNK] = np.reshape(responses, (ny, nu, -1)).sum(axis=1).T
            state = phi @ states[..., -1] + gamma[..., None] * inputs[:, None, :, -1]
    return y


# --------------------------------------------------------------------------------------- argument checks


def _sample_time(ts) -> float:
    try:
        value = float(ts)
    except (TypeError, ValueError):
        raise ValueError(f"ts: expected a positive sample time in seconds, got {ts!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"ts: expected a positive finite sample time in seconds, got {ts!r}")
    return value


def _segments(segments) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs (nu, S, N) and outputs (ny, S, N) of S segments padded with zeros to the longest,
    and the mask (S, N) of real samples."""
    if isinstance(segments, np.ndarray) or not isinstance(segments, Sequence) or len(segments) == 0:
        raise ValueError("segments: expected a non-empty sequence of (u, y) pairs, one per trial")
    pairs = []
    for k, pair in enumerate(segments):
        if not isinstance(pair, Sequence) or len(pair) != 2:
            raise ValueError(f"segments[{k}]: expected a (u, y) pair of arrays")
        u, y = (np.asarray(signal, dtype=float) for signal in pair)
        if u.ndim != 2 or y.ndim != 2 or len(u) != len(y) or len(u) < 2:
            raise ValueError(f"segments[{k}]: expected u (N, nu) and y (N, ny) with the same N >= 2 samples, "
                             f"got {u.shape} and {y.shape}")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise ValueError(f"segments[{k}]: u or y contains NaN or infinite values")
        if pairs and (u.shape[1], y.shape[1]) != (pairs[0][0].shape[1], pairs[0][1].shape[1]):
            raise ValueError(f"segments[{k}]: {u.shape[1]} inputs and {y.shape[1]} outputs, expected "
                             f"{pairs[0][0].shape[1]} and {pairs[0][1].shape[1]} as in segments[0]")
        pairs.append((u, y))
    length = max(len(u) for u, _ in pairs)
    mask = np.arange(length)[None, :] < np.array([len(u) for u, _ in pairs])[:, None]
    inputs, outputs = (np.zeros((pairs[0][side].shape[1], len(pairs), length)) for side in (0, 1))
    for k, (u, y) in enumerate(pairs):
        inputs[:, k, :len(u)] = u.T
        outputs[:, k, :len(y)] = y.T
    for name, signals in (("input", inputs), ("output", outputs)):
        values = signals[:, mask]
        for channel in np.flatnonzero(np.ptp(values, axis=1) == 0):
            raise IdentificationError(f"segments: {name} {channel} is constant ({values[channel, 0]:g}) in every "
                                      f"segment: expected a signal that varies")
    return inputs, outputs, mask


def _orders(n_poles, n_zeros, ny: int, nu: int) -> tuple[np.ndarray, np.ndarray]:
    def table(value, name, minimum):
        array = np.asarray(value)
        if array.ndim == 0:
            array = np.full((ny, nu), array)
        if array.shape != (ny, nu) or not np.issubdtype(array.dtype, np.integer) or np.any(array < minimum):
            raise ValueError(f"{name}: expected an integer >= {minimum} or a ({ny}, {nu}) array of them, "
                             f"got {array.tolist()!r}")
        return array.astype(int)

    n_poles = table(n_poles, "n_poles", 1)
    n_zeros = n_poles - 1 if n_zeros is None else table(n_zeros, "n_zeros", 0)
    if np.any(n_zeros > n_poles):
        raise ValueError(f"n_zeros: expected at most n_poles zeros per entry (a proper model), got {n_zeros.tolist()} "
                         f"for n_poles {n_poles.tolist()}")
    return n_poles, n_zeros


# ---------------------------------------------------------------------------------------- estimation


@dataclass(frozen=True, eq=False)
class FitReport:
    """What the estimation did, output by output summed up. ``converged``: the refinement of every
    output met its tolerance (without ``refine``: SRIVC converged for every output); ``iterations``:
    the most model evaluations one output's refinement used (``max_iterations`` caps each pass);
    ``srivc_iterations``: SRIVC's sweeps (common-denominator stage, then backfitting); ``cost``:
    half the sum of squared simulation errors of the returned model over all outputs and samples;
    ``reflected_poles``: poles of the returned model that were mirrored from the right into the left
    half-plane; ``per_output_fit_percent``: MATLAB's NRMSE fit 100 (1 - |y - y_hat| / |y - mean y|)
    over all segments together."""

    converged: bool
    iterations: int
    cost: float
    message: str
    srivc_iterations: int
    reflected_poles: int
    per_output_fit_percent: np.ndarray

    def to_dict(self) -> dict:
        """JSON-able: every field, the fit % per output as a list."""
        return {"converged": bool(self.converged), "iterations": int(self.iterations), "cost": float(self.cost),
                "message": self.message, "srivc_iterations": int(self.srivc_iterations),
                "reflected_poles": int(self.reflected_poles),
                "per_output_fit_percent": [float(v) for v in self.per_output_fit_percent]}

    @classmethod
    def from_dict(cls, fields: dict) -> FitReport:
        """The report :meth:`to_dict` gave."""
        return cls(**{**fields, "per_output_fit_percent": np.asarray(fields["per_output_fit_percent"],
                                                                     dtype=np.float64)})


def _roots(a: np.ndarray) -> np.ndarray:
    return np.roots(np.concatenate([[1.0], a[::-1]]))


def _reflected(a: np.ndarray) -> tuple[np.ndarray, int]:
    """The denominator with its right-half-plane poles mirrored into the left half-plane, and how many."""
    roots = _roots(a)
    unstable = roots.real > 0
    if not np.any(unstable):
        return a, 0
    return np.poly(np.where(unstable, -roots.conj(), roots)).real[:0:-1].copy(), int(np.count_nonzero(unstable))


def _updated(a, numerators, omega, bounds):
    """A new SRIVC estimate made usable as the next prefilter, stable (unstable poles mirrored), in
    the time unit of the geometric mean of its poles' magnitudes (within bounds)."""
    a = _reflected(a)[0]
    magnitudes = np.abs(_roots(a)) * omega
    scale = float(np.clip(np.exp(np.mean(np.log(np.maximum(magnitudes, bounds[0])))), *bounds))
    return (*_rescaled(a, numerators, omega / scale), scale)


@dataclass
class _Row:
    """One output's estimate: per input, the ascending lower coefficients of the entry's monic
    denominator (a) and of its numerator (b), in the entry's own time unit 1/omega (omega in rad/s)."""

    a: list
    b: list
    omega: np.ndarray

    def copy(self) -> _Row:
        return _Row(list(self.a), list(self.b), self.omega.copy())

    def parameters(self) -> np.ndarray:
        return np.concatenate([part for a, b in zip(self.a, self.b) for part in (a, b)])

    def with_parameters(self, theta: np.ndarray) -> _Row:
        sizes = np.cumsum([size for a, b in zip(self.a, self.b) for size in (len(a), len(b))])[:-1]
        parts = np.split(theta, sizes)
        return _Row(parts[0::2], parts[1::2], self.omega)

    def is_stable(self) -> bool:
        return all(np.all(_roots(a).real < 0) for a in self.a)


def _transfer_function(rows: list[_Row]) -> TransferFunctionMatrix:
    """The estimate in seconds: a_k omega^(n - k), b_k omega^(n - k), descending."""
    numerators, denominators = [], []
    for row in rows:
        scaled = [_rescaled(a, [b], omega) for a, b, omega in zip(row.a, row.b, row.omega)]
        denominators.append([np.concatenate([[1.0], a[::-1]]) for a, _ in scaled])
        numerators.append([b[::-1] for _, (b,) in scaled])
    return TransferFunctionMatrix(numerators, denominators)


def _responses(rows: list[_Row], inputs: np.ndarray, ts: float) -> np.ndarray:
    """Every entry's simulated response to its input, (rows, nu, S, N)."""
    a_list = [a for row in rows for a in row.a]
    b_list = [b for row in rows for b in row.b]
    driven = np.tile(inputs, (len(rows), 1, 1))
    states = _filter_states(a_list, ts * np.concatenate([row.omega for row in rows]), driven)
    responses = np.stack([_response(a, b, xi, v) for a, b, xi, v in zip(a_list, b_list, states, driven)])
    return responses.reshape((len(rows),) + inputs.shape)


def _derivatives(a: np.ndarray, n_b: int, xi: np.ndarray, v: np.ndarray) -> np.ndarray:
    """s^k/A v for k < n_b from the states xi_k = s^k/A v (k < n) and v (s^n/A v = v - a . xi)."""
    if n_b <= len(a):
        return xi[:n_b]
    return np.concatenate([xi, (v - np.tensordot(a, xi, axes=1))[None]])


def _iv_estimate(a, filtered, y, input_columns, instruments, mask) -> np.ndarray:
    """One SRIVC step: A/Ahat y = sum_j B_j/Ahat u_j solved for (a, b_1, b_2, ...) with the prefilter
    1/Ahat (the current ``a``): ``filtered`` holds s^k/Ahat y (k < n), ``input_columns`` the s^k/Ahat u_j
    of every numerator coefficient, ``instruments`` s^k/Ahat yhat of the current noise-free response
    yhat (None: least squares)."""
    inputs = np.concatenate(input_columns)
    regressors = np.concatenate([-filtered, inputs])[:, mask]
    target = (y - np.tensordot(a, filtered, axes=1))[mask]
    scale = np.linalg.norm(regressors, axis=1)
    scale[scale == 0] = 1.0
    regressors = (regressors / scale[:, None]).T
    if instruments is None:
        return np.linalg.lstsq(regressors, target, rcond=None)[0] / scale
    # (Z'Phi) theta = Z'y through an orthonormal basis Q of the instruments' span: Q'Phi has about
    # the condition of Phi, where the normal matrix Z'Phi would have its square
    basis = np.linalg.qr(np.concatenate([-instruments, inputs])[:, mask].T)[0]
    return np.linalg.lstsq(basis.T @ regressors, basis.T @ target, rcond=None)[0] / scale


def _rms_frequency(outputs: np.ndarray, mask: np.ndarray, ts: float) -> np.ndarray:
    """Each output's root-mean-square angular frequency, |dy/dt| / |y - mean y| (rad/s)."""
    steps = np.diff(outputs, axis=-1)[:, mask[:, 1:]]
    centred = outputs[:, mask] - outputs[:, mask].mean(axis=1, keepdims=True)
    return np.sqrt(np.mean(steps**2, axis=1) / np.mean(centred**2, axis=1)) / ts


def _relative_change(new: np.ndarray, old: np.ndarray) -> float:
    return float(np.linalg.norm(new - old) / max(np.linalg.norm(new), np.finfo(float).tiny))


class _Progress:
    """The sweeps of one SRIVC problem. It stops when the estimate no longer moves (converged) or when
    the simulation error has not improved by a relative ``_IMPROVEMENT`` for ``_PATIENCE`` sweeps:
    the iteration is not a contraction at every noise level and order, so its best iterate by
    simulation error is kept."""

    def __init__(self, estimate):
        self.estimate, self.best, self.error, self.best_sweep = estimate, estimate, np.inf, 0
        self.converged = self.stopped = False

    def record(self, sweep: int, error: float, estimate, change: float, tolerance: float):
        """The simulation ``error`` of the current estimate, the next ``estimate`` and how far it moved."""
        if error < self.error:
            if error < self.error * (1.0 - _IMPROVEMENT):
                self.best_sweep = sweep
            self.best, self.error = self.estimate, error
        self.estimate = estimate
        self.converged = sweep > 1 and change < tolerance
        self.stopped = self.converged or sweep - self.best_sweep >= _PATIENCE

    def result(self):
        return self.estimate if self.converged else self.best


def _common_sweep(models, problems, inputs, outputs, mask, ts, bounds, instruments: bool):
    """One SRIVC step of each MISO model y_i = sum_j B_j/A u_j with one denominator: for every
    problem the simulation error of its model, the next model and how far it moved."""
    nu = len(inputs)
    steps = ts * np.array([omega for _, _, omega in models])
    sensitivities = _sensitivity_states([a for a, _, _ in models for _ in range(nu)],
                                        [b for _, numerators, _ in models for b in numerators],
                                        np.repeat(steps, nu), np.tile(inputs, (len(models), 1, 1)))
    filtered = _filter_states([a for a, _, _ in models], steps, outputs[[i for i, _, _ in problems]], linear=True)
    for slot, ((i, n, sizes), (a, numerators, omega)) in enumerate(zip(problems, models)):
        states = sensitivities[slot * nu:(slot + 1) * nu]
        simulated = sum(_response(a, b, x[:n], u) for b, x, u in zip(numerators, states, inputs))
        columns = [_derivatives(a, size, x[:n], u) for size, x, u in zip(sizes, states, inputs)]
        theta = _iv_estimate(a, filtered[slot], outputs[i], columns, sum(x[n:] for x in states) if instruments else None,
                             mask)
        parts = np.split(theta, np.cumsum([n, *sizes])[:-1])
        yield (np.linalg.norm((outputs[i] - simulated)[mask]), _updated(parts[0], parts[1:], omega, bounds),
               _relative_change(theta, np.concatenate([a, *numerators])))


def _backfitting_sweep(rows: list[_Row], inputs, outputs, mask, ts, bounds):
    """One SRIVC sweep over the inputs of each output's MISO model (Gauss-Seidel backfitting): entry
    j is re-estimated from the output less the current responses of the other entries. Updates
    ``rows`` in place; returns the simulation errors of the rows as they were and how far they moved."""
    responses = _responses(rows, inputs, ts)
    errors = np.linalg.norm((outputs - responses.sum(axis=1))[:, mask], axis=1)
    changes = np.zeros(len(rows))
    driven_shape = (len(rows),) + mask.shape
    for j, u in enumerate(inputs):
        a_list, b_list = [row.a[j] for row in rows], [row.b[j] for row in rows]
        steps = ts * np.array([row.omega[j] for row in rows])
        sensitivities = _sensitivity_states(a_list, b_list, steps, np.broadcast_to(u, driven_shape))
        others = outputs - responses.sum(axis=1) + responses[:, j]
        filtered = _filter_states(a_list, steps, others, linear=True)
        for slot, row in enumerate(rows):
            a, b, x = a_list[slot], b_list[slot], sensitivities[slot]
            n = len(a)
            theta = _iv_estimate(a, filtered[slot], others[slot], [_derivatives(a, len(b), x[:n], u)], x[n:], mask)
            changes[slot] = max(changes[slot], _relative_change(theta, np.concatenate([a, b])))
            row.a[j], (row.b[j],), row.omega[j] = _updated(theta[:n], [theta[n:]], row.omega[j], bounds)
        states = _filter_states([row.a[j] for row in rows], ts * np.array([row.omega[j] for row in rows]),
                                np.broadcast_to(u, driven_shape))
        responses[:, j] = [_response(row.a[j], row.b[j], xi, u) for row, xi in zip(rows, states)]
    return errors, changes


def _srivc(inputs, outputs, mask, n_poles, n_zeros, ts, bounds, max_iterations, tolerance):
    """SRIVC of every entry with its own denominator, all outputs at once: first the MISO model with
    one common denominator of each order an output's entries have, from the state-variable filter
    1/(s + lambda)^n (lambda the output's rms frequency; least squares in the first sweep), then
    backfitting from it. Returns (rows, sweeps, converged)."""
    ny, nu = n_poles.shape
    problems = [(i, n, [min(m, n) + 1 for m in n_zeros[i]]) for i in range(ny) for n in np.unique(n_poles[i])]
    cutoff = np.clip(_rms_frequency(outputs, mask, ts), *bounds)
    progress = [_Progress((np.array([comb(n, k) for k in range(n)], dtype=float), [np.zeros(size) for size in sizes],
                           cutoff[i])) for i, n, sizes in problems]

    def sweep_common(active, sweep):
        return _common_sweep([progress[p].estimate for p in active], [problems[p] for p in active], inputs, outputs,
                             mask, ts, bounds, instruments=sweep > 1)

    common_sweeps = _run(progress, max_iterations, tolerance if nu == 1 else max(tolerance, _STARTING_TOLERANCE),
                         sweep_common)
    common = {problems[p][:2]: state.result() for p, state in enumerate(progress)}
    converged = all(state.converged for state in progress)
    rows = [_Row([common[i, n][0] for n in n_poles[i]], [common[i, n][1][j] for j, n in enumerate(n_poles[i])],
                 np.array([common[i, n][2] for n in n_poles[i]])) for i in range(ny)]
    if nu == 1:  # the common-denominator model is the entry's SRIVC estimate
        return rows, common_sweeps, converged
    progress = [_Progress(row) for row in rows]

    def sweep_rows(active, sweep):
        working = [progress[i].estimate.copy() for i in active]
        errors, changes = _backfitting_sweep(working, inputs, outputs[active], mask, ts, bounds)
        return zip(errors, working, changes)

    sweeps = _run(progress, max_iterations, tolerance, sweep_rows)
    return ([state.result() for state in progress], common_sweeps + sweeps,
            converged and all(state.converged for state in progress))


def _run(progress: list[_Progress], max_iterations: int, tolerance: float, sweep) -> int:
    """Sweeps until every problem has stopped or ``max_iterations``; ``sweep(active, number)`` yields
    (error, next estimate, change) per active problem. Returns the number of sweeps."""
    number = 0
    while number < max_iterations and not all(state.stopped for state in progress):
        number += 1
        active = [p for p, state in enumerate(progress) if not state.stopped]
        for p, (error, estimate, change) in zip(active, sweep(active, number)):
            progress[p].record(number, error, estimate, change, tolerance)
    return number


def _simulation_and_sensitivities(row: _Row, inputs, mask, ts) -> tuple[np.ndarray, np.ndarray]:
    """One output's simulated response at the real samples and its derivatives with respect to the row's
    parameters, (samples,) and (samples, parameters): d y/d a_k = -s^k B/A^2 u, d y/d b_k = s^k/A u."""
    states = _sensitivity_states(row.a, row.b, ts * row.omega, inputs)
    prediction, columns = 0.0, []
    for a, b, x, v in zip(row.a, row.b, states, inputs):
        n = len(a)
        prediction = prediction + _response(a, b, x[:n], v)
        columns += [-x[n:], _derivatives(a, len(b), x[:n], v)]
    return prediction[mask], np.concatenate(columns)[:, mask].T


def parameter_covariance(tf: TransferFunctionMatrix, segments: Sequence[tuple[np.ndarray, np.ndarray]],
                         ts: float, residuals: str = SANDWICH
                         ) -> tuple[list[np.ndarray], list[int | None], list[bool]]:
    """The covariance of each output's coefficients, the lags its middle took (None: white) and whether its
    scores were prewhitened. With
    ``residuals="white"`` the output-error estimate's asymptotic covariance (Ljung 1999, §9.3):
    σ² (JᵀJ)⁻¹, J the Jacobian of the simulated output with respect to the coefficients at ``tf`` on
    ``segments`` and σ² the residual variance, sum of squares / (N - p); with ``"sandwich"`` (the
    default) the sandwich estimate of :func:`softtip.sysid.robust.sandwich_covariance`, which holds
    for coloured residuals too.

    One matrix per output over the coefficients of its entries in order, entry j: the denominator's
    coefficients after the leading 1, then the numerator's, both in descending powers of s (as
    ``tf`` stores them). (JᵀJ is computed in each entry's own time unit, where it is well
    conditioned, and carried to seconds by the diagonal scaling between the two.) The white estimate
    holds for white output errors: with coloured ones (the residual whiteness test fails) it
    understates the spread, as MATLAB's for an output-error model does."""
    if residuals not in COVARIANCES:
        raise ValueError(f"residuals: expected one of {', '.join(COVARIANCES)}, got {residuals!r}")
    ts = _sample_time(ts)
    inputs, outputs, mask = _segments(segments)
    ny, nu = tf.shape
    if (len(outputs), len(inputs)) != (ny, nu):
        raise ValueError(f"segments: {len(inputs)} inputs and {len(outputs)} outputs, the model has {nu} and {ny}")
    covariances, all_lags, all_prewhitened = [], [], []
    groups = np.nonzero(mask)[0]  # each real sample's trial, trials in order
    for i in range(ny):
        omega = np.array([max(float(np.exp(np.mean(np.log(np.maximum(np.abs(np.roots(a)), 1e-300))))), 1e-300)
                          if len(a) > 1 else 1.0 for a in tf.denominators[i]])
        scaled = [_rescaled(a[:0:-1], [b[::-1]], 1.0 / w) for a, b, w in
                  zip(tf.denominators[i], tf.numerators[i], omega)]
        row = _Row([a for a, _ in scaled], [b for _, (b,) in scaled], omega)
        with single_threaded_blas():
            prediction, jacobian = _simulation_and_sensitivities(row, inputs, mask, ts)
        residual = outputs[i][mask] - prediction
        count, parameters = jacobian.shape
        if count <= parameters:
            raise IdentificationError(f"output {i}: {count} samples for {parameters} coefficients: no covariance")
        if residuals == SANDWICH:
            covariance, lags, prewhitened = sandwich_covariance(jacobian, residual, groups)
        else:
            variance = float(residual @ residual) / (count - parameters)
            covariance, lags, prewhitened = variance * np.linalg.pinv(jacobian.T @ jacobian), None, False
        all_lags.append(lags)
        all_prewhitened.append(prewhitened)
        # the row's ascending coefficients in 1/omega units -> descending in seconds: a_k omega^(n-k)
        factors, order, first = [], [], 0
        for a, b, w in zip(row.a, row.b, omega):
            n = len(a)
            factors += [w ** (n - np.arange(n)), w ** (n - np.arange(len(b)))]
            order += [first + np.arange(n)[::-1], first + n + np.arange(len(b))[::-1]]
            first += n + len(b)
        factor, order = np.concatenate(factors), np.concatenate(order)
        covariance = covariance * np.outer(factor, factor)
        covariances.append(covariance[np.ix_(order, order)])
    return covariances, all_lags, all_prewhitened


def _refined(row: _Row, inputs, target, mask, ts, max_iterations, tolerance, stable_only: bool):
    """Output-error refinement of one output's row by least squares on the simulation error with the
    analytic Jacobian (an unstable trial model is refused when ``stable_only``): (row, result)."""
    last = {}

    def evaluate(theta):
        if last.get("theta") is None or not np.array_equal(last["theta"], theta):
            trial = row.with_parameters(theta)
            with np.errstate(over="ignore", invalid="ignore"):
                prediction, sensitivities = _simulation_and_sensitivities(trial, inputs, mask, ts)
                residual = target - prediction
            # a trial model that blew up (or left the stable ones) is refused: the trust region shrinks
            if not np.all(np.abs(residual) < 1e150) or (stable_only and not trial.is_stable()):
                residual = np.full_like(residual, np.nan)
            last.update(theta=theta.copy(), residual=residual, jacobian=-sensitivities)
        return last

    from scipy import optimize  # here, not at import: a command that fits nothing need not load it

    result = optimize.least_squares(lambda theta: evaluate(theta)["residual"], row.parameters(),
                                    jac=lambda theta: evaluate(theta)["jacobian"], method="trf", x_scale="jac",
                                    ftol=tolerance, xtol=tolerance**2, gtol=tolerance**2, max_nfev=max_iterations)
    return row.with_parameters(result.x), result


def _with_refitted_numerators(row: _Row, inputs, target, mask, ts) -> _Row:
    """The row's numerators by linear least squares for its denominators (the simulation error is
    linear in them)."""
    states = _filter_states(row.a, ts * row.omega, inputs)
    regressors = np.concatenate([_derivatives(a, len(b), xi, v)
                                 for a, b, xi, v in zip(row.a, row.b, states, inputs)])[:, mask].T
    scale = np.linalg.norm(regressors, axis=0)
    scale[scale == 0] = 1.0
    theta = np.linalg.lstsq(regressors / scale, target, rcond=None)[0] / scale
    return _Row(row.a, np.split(theta, np.cumsum([len(b) for b in row.b])[:-1]), row.omega)


def fit(segments: Sequence[tuple[np.ndarray, np.ndarray]], ts: float, n_poles, n_zeros=None, *,
        refine: bool = True, max_iterations: int = 100, tolerance: float = 1e-6, enforce_stability: bool = True,
        ) -> tuple[TransferFunctionMatrix, FitReport]:
    """A continuous-time transfer-function matrix G(s) (ny x nu) from sampled input/output records.

    ``segments``: one (u (N_k, nu), y (N_k, ny)) pair per trial, each starting from rest, never
    joined; the inputs are held constant between samples (zero-order hold). ``n_poles`` and
    ``n_zeros``: an integer for every entry or (ny, nu) integer arrays; ``n_zeros`` defaults to
    ``n_poles - 1`` (strictly proper). ``refine``: follow SRIVC by the output-error refinement.
    ``max_iterations`` caps SRIVC's sweeps (each stage) and each refinement pass's model evaluations;
    ``tolerance`` is their relative convergence threshold. ``enforce_stability``: mirror the
    unstable poles of a refined estimate into the left half-plane, re-fit its numerators and refine
    again among stable models only (counted in the report); without it an unstable estimate is
    returned and said so in the report's message (SRIVC's own estimates are always stable: they
    serve as its prefilters). See the module notes for the method.

    A mistaken argument raises ValueError; data that cannot identify the model (fewer samples than one
    output's parameters, a signal constant in every segment) raise :class:`IdentificationError`, as in
    the rest of :mod:`softtip.sysid`.
    """
    ts = _sample_time(ts)
    inputs, outputs, mask = _segments(segments)
    nu, ny = len(inputs), len(outputs)
    n_poles, n_zeros = _orders(n_poles, n_zeros, ny, nu)
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 1:
        raise ValueError(f"max_iterations: expected an integer >= 1, got {max_iterations!r}")
    if not (isinstance(tolerance, (int, float, np.floating)) and 0 < tolerance < 1):
        raise ValueError(f"tolerance: expected a number between 0 and 1, got {tolerance!r}")
    samples = int(mask.sum())
    parameters = int((n_poles + n_zeros + 1).sum(axis=1).max())
    if samples < parameters:
        raise IdentificationError(f"segments: {samples} samples in all, fewer than the {parameters} parameters "
                                  f"of one output's model")
    with single_threaded_blas():  # small thin products: a second BLAS thread only thrashes
        return _estimated(inputs, outputs, mask, ts, n_poles, n_zeros, refine, max_iterations, tolerance,
                          enforce_stability)


def _estimated(inputs, outputs, mask, ts, n_poles, n_zeros, refine, max_iterations, tolerance, enforce_stability):
    """``fit`` on checked arguments."""
    bounds = (1.0 / (ts * mask.sum()), np.pi / ts)
    # SRIVC only starts a refinement: to the square root of its tolerance then
    rows, sweeps, converged = _srivc(inputs, outputs, mask, n_poles, n_zeros, ts, bounds, max_iterations,
                                     np.sqrt(tolerance) if refine else tolerance)
    notes = [] if converged else [f"SRIVC stopped after {sweeps} sweeps without converging"]
    iterations = reflected = 0
    if refine:
        converged = True
        for i, row in enumerate(rows):
            target = outputs[i][mask]
            row, result = _refined(row, inputs, target, mask, ts, max_iterations, tolerance, stable_only=False)
            evaluations = result.nfev
            moved = 0
            if enforce_stability:
                mirrored = [_reflected(a) for a in row.a]
                moved = sum(count for _, count in mirrored)
            if moved:
                row = _with_refitted_numerators(_Row([a for a, _ in mirrored], row.b, row.omega), inputs, target,
                                                mask, ts)
                row, result = _refined(row, inputs, target, mask, ts, max_iterations, tolerance, stable_only=True)
                evaluations += result.nfev
                reflected += moved
                notes.append(f"output {i}: {moved} unstable poles mirrored into the left half-plane, "
                             f"then refined among stable models")
            if result.status <= 0:
                converged = False
                notes.append(f"output {i}: refinement did not converge ({result.message})")
            iterations = max(iterations, evaluations)
            rows[i] = row
    model = _transfer_function(rows)
    for i, row in enumerate(model.poles()):
        for j, poles in enumerate(row):
            if np.any(poles.real >= 0):
                converged = converged and not enforce_stability
                notes.append(f"entry ({i}, {j}) is unstable")
    measured, simulated = outputs[:, mask], _responses(rows, inputs, ts).sum(axis=1)[:, mask]
    errors = measured - simulated
    report = FitReport(
        converged=converged, iterations=iterations, cost=0.5 * float(np.sum(errors**2)),
        message="; ".join(notes) if notes else "converged", srivc_iterations=sweeps, reflected_poles=reflected,
        per_output_fit_percent=fit_percent(measured.T, simulated.T))
    return model, report
