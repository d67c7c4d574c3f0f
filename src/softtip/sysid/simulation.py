"""Running discrete state-space systems: open-loop simulation, k-step-ahead prediction, frame by frame.

- :func:`simulate`: y from u alone, from a given initial state (zero by default);
- :func:`predict`: y[t] predicted from the outputs measured up to t - k and the inputs up to t,
  through the innovations form's Kalman predictor (a system without ``K`` predicts by
  simulation: an output-error model ignores past outputs, as in MATLAB's ``predict``);
- :class:`StreamingSimulator`: one ``step(u_k) -> y_k`` per frame, the state kept between frames,
  equal to :func:`simulate` on the same inputs.
"""

from __future__ import annotations

import numpy as np

from softtip.sysid.statespace import IdentificationError, StateSpace


def _inputs(system: StateSpace, u: np.ndarray, what: str) -> np.ndarray:
    if not system.is_discrete:
        raise IdentificationError(f"{what}: the system is continuous; discretise it first (to_discrete(ts))")
    u = np.asarray(u, dtype=np.float64)
    if u.ndim == 1 and system.n_inputs == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != system.n_inputs:
        raise IdentificationError(f"{what}: u: expected shape (samples, {system.n_inputs}), got {u.shape}")
    return u


def _initial(system: StateSpace, x0: np.ndarray | None) -> np.ndarray:
    if x0 is None:
        return np.zeros(system.n_states)
    x0 = np.asarray(x0, dtype=np.float64)
    if x0.shape != (system.n_states,):
        raise IdentificationError(f"x0: expected {system.n_states} states, got shape {x0.shape}")
    return x0


def state_sequence(A: np.ndarray, drive: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """x[0] = x0, x[t+1] = A x[t] + drive[t]: the states (N, n) for t = 0 .. N-1."""
    states = np.empty_like(drive)
    transposed = np.ascontiguousarray(A.T)
    x = x0
    for t in range(len(drive)):
        states[t] = x
        x = x @ transposed + drive[t]
    return states


def simulate(system: StateSpace, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """The outputs (N, ny) of the discrete ``system`` driven by ``u`` (N, nu) from the state ``x0``."""
    u = _inputs(system, u, "simulate")
    states = state_sequence(system.A, u @ system.B.T, _initial(system, x0))
    return states @ system.C.T + u @ system.D.T


def predict(system: StateSpace, u: np.ndarray, y: np.ndarray, horizon: int,
            x0: np.ndarray | None = None) -> np.ndarray:
    """k-step-ahead predictions (N, ny): row t is y[t] predicted from y[:t - k + 1] and u[:t + 1].

    The Kalman predictor x^[t+1|t] = (A - KC) x^[t|t-1] + (B - KD) u[t] + K y[t] gives the
    one-step states; k - 1 steps of the model without the outputs carry them to t. The first
    k - 1 rows, with no output old enough, are simulated from ``x0``.
    """
    u = _inputs(system, u, "predict")
    y = np.asarray(y, dtype=np.float64)
    if y.shape != (len(u), system.n_outputs):
        raise IdentificationError(f"predict: y: expected shape ({len(u)}, {system.n_outputs}), got {y.shape}")
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
        raise IdentificationError(f"horizon: expected an integer >= 1, got {horizon!r}")
    x0 = _initial(system, x0)
    if system.K is None:
        return simulate(system, u, x0)
    A, B, C, D, K = system.A, system.B, system.C, system.D, system.K
    states = state_sequence(A - K @ C, u @ (B - K @ D).T + y @ K.T, x0)
    drive = u @ B.T
    for _ in range(min(int(horizon), len(u)) - 1):
        ahead = np.empty_like(states)
        ahead[0] = x0
        ahead[1:] = states[:-1] @ A.T + drive[:-1]
        states = ahead
    return states @ C.T + u @ D.T


class StreamingSimulator:
    """A discrete system run one frame at a time: ``step(u_k)`` returns y_k and keeps the state.

    y_k = C x_k + D u_k and x_{k+1} = A x_k + B u_k are one product of the precomputed matrix
    [[A, B], [C, D]] with the preallocated vector [x_k; u_k]: a few microseconds per frame.
    """

    def __init__(self, system: StateSpace, x0: np.ndarray | None = None):
        if not system.is_discrete:
            raise IdentificationError("StreamingSimulator: the system is continuous; discretise it first")
        self.system = system
        n, nu = system.n_states, system.n_inputs
        self._n = n
        self._joint = np.ascontiguousarray(np.block([[system.A, system.B], [system.C, system.D]]))
        self._stacked = np.zeros(n + nu)
        self._next = np.zeros(n + system.n_outputs)
        self._outputs = self._next[n:]
        self.reset(x0)

    def reset(self, x0: np.ndarray | None = None) -> None:
        """Back to the state ``x0`` (zero by default)."""
        self._stacked[:self._n] = _initial(self.system, x0)

    @property
    def state(self) -> np.ndarray:
        return self._stacked[:self._n].copy()

    def step(self, u_k) -> np.ndarray:
        """y_k for the input u_k (nu values); the state moves on to x_{k+1}."""
        stacked = self._stacked
        stacked[self._n:] = u_k
        np.dot(self._joint, stacked, out=self._next)
        stacked[:self._n] = self._next[:self._n]
        return self._outputs.copy()
