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


# a simulation whose outputs spread this many times wider than the measured ones has run away
RUNAWAY = 1e3


def runs_away(simulated: np.ndarray, measured: np.ndarray) -> bool:
    """Whether a simulation (N, ny) has run away from the measured outputs (N, ny): not finite, or an output
    spread more than :data:`RUNAWAY` times as wide, whatever the moduli of the system's poles say (a pole a
    hair inside the unit circle, or a badly conditioned realisation, grows for longer than any record)."""
    with np.errstate(over="ignore", invalid="ignore"):
        spread = np.std(simulated, axis=0)
    return bool(not np.all(np.isfinite(spread)) or np.any(spread > RUNAWAY * np.std(measured, axis=0)))


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
    """A discrete system run one frame at a time: ``step(u_k) -> y_k`` keeps the state between frames.

    y_k = C x_k + D u_k and x_{k+1} = A x_k + B u_k are one product of the precomputed matrix
    [[A, B], [C, D]] with the preallocated vector [x_k; u_k]: a few microseconds per frame.
    ``trend`` (a :class:`~softtip.sysid.trends.Trend`): the levels the model's deviations are taken
    from, their clock starting at the first frame (and at every reset); ``step`` then takes and
    gives values in the recording's own units.
    """

    def __init__(self, system: StateSpace, x0: np.ndarray | None = None, trend=None):
        if not system.is_discrete:
            raise IdentificationError("StreamingSimulator: the system is continuous; discretise it first")
        self.system = system
        n, nu = system.n_states, system.n_inputs
        self._n = n
        self._joint = np.ascontiguousarray(np.block([[system.A, system.B], [system.C, system.D]]))
        self._stacked = np.zeros(n + nu)
        self._next = np.zeros(n + system.n_outputs)
        self._outputs = self._next[n:]
        self._trend = None if trend is None or trend.kind == "none" else trend
        if self._trend is not None:
            self.step = self._step_about_levels
        self.reset(x0)

    def reset(self, x0: np.ndarray | None = None) -> None:
        """Back to the state ``x0`` (zero by default) and, with a trend, to its time 0."""
        self._stacked[:self._n] = _initial(self.system, x0)
        if self._trend is not None:
            self._input_level = self._trend.input_offset.copy()
            self._output_level = self._trend.output_offset.copy()

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

    def _step_about_levels(self, u_k) -> np.ndarray:
        stacked = self._stacked
        stacked[self._n:] = u_k
        stacked[self._n:] -= self._input_level
        np.dot(self._joint, stacked, out=self._next)
        stacked[:self._n] = self._next[:self._n]
        y_k = self._outputs + self._output_level
        trend, ts = self._trend, self.system.ts
        if trend.kind == "linear":
            self._input_level += trend.input_slope * ts
            self._output_level += trend.output_slope * ts
        return y_k


def free_response(A: np.ndarray, C: np.ndarray, samples: int) -> np.ndarray:
    """C A^t for t = 0 .. samples - 1: the outputs' response to each initial state, (samples, ny, n)."""
    blocks = np.empty((samples, *C.shape))
    power = C
    for t in range(samples):
        blocks[t] = power
        power = power @ A
    return blocks


def estimate_initial_state(system: StateSpace, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The initial state x0 that best explains ``y`` (N, ny) from ``u`` (N, nu) in simulation: the least-squares
    solution of y - simulate(u, 0) = [C; CA; CA²; ...] x0 (MATLAB's ``findstates`` for an output-error fit;
    ``compare``'s estimated initial condition). Unobservable directions get the minimum-norm answer."""
    u = _inputs(system, u, "estimate_initial_state")
    y = np.asarray(y, dtype=np.float64)
    if y.shape != (len(u), system.n_outputs):
        raise IdentificationError(f"estimate_initial_state: y: expected shape ({len(u)}, {system.n_outputs}), "
                                  f"got {y.shape}")
    if not system.n_states:
        return np.zeros(0)
    observability = free_response(system.A, system.C, len(u)).reshape(-1, system.n_states)
    forced = simulate(system, u)
    scale = np.linalg.norm(observability, axis=0)
    scale[scale == 0] = 1.0
    solution = np.linalg.lstsq(observability / scale, (y - forced).ravel(), rcond=None)[0]
    return solution / scale
