"""Linear time-invariant state-space systems, discrete or continuous, and zero-order-hold conversions.

A :class:`StateSpace` is x' = A x + B u, y = C x + D u in continuous time (``ts`` None) or
x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k] at the sample time ``ts``. A discrete system may
carry the gain ``K`` of its innovations form, x[k+1] = A x[k] + B u[k] + K e[k], y[k] = C x[k] +
D u[k] + e[k], with the covariance of e: that is its steady-state Kalman predictor.

Zero-order hold: :meth:`StateSpace.to_discrete` is exact for inputs held constant over each
sample (the matrix exponential of [[A, B], [0, 0]] ts, as scipy.signal.cont2discrete computes it);
:meth:`StateSpace.to_continuous` inverts it with the matrix
logarithm of [[Ad, Bd], [0, I]], which exists as a real continuous system only when Ad has no
eigenvalue on the closed negative real axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from softtip._core.config import PositiveNumber, checked


class IdentificationError(ValueError):
    """A system or identification that cannot be what was asked of it (shapes, orders, conversions)."""


def _matrix(name: str, value, shape: tuple[int, int]) -> np.ndarray:
    array = np.array(value, dtype=np.float64)
    if array.shape != shape:
        raise IdentificationError(f"{name}: expected shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise IdentificationError(f"{name}: not all entries are finite")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class StateSpace:
    """(A, B, C, D), continuous (``ts`` None) or at sample time ``ts`` (s); validated, read-only.

    ``K`` (n, ny) and ``noise_covariance`` (ny, ny): the innovations form of a discrete system.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    ts: float | None = None
    K: np.ndarray | None = None
    noise_covariance: np.ndarray | None = None

    def __post_init__(self):
        n = np.shape(self.A)[0] if np.ndim(self.A) == 2 else 0
        if np.ndim(self.B) != 2 or np.ndim(self.C) != 2:
            raise IdentificationError(f"B and C must be 2-D, got shapes {np.shape(self.B)} and {np.shape(self.C)}")
        nu, ny = np.shape(self.B)[1], np.shape(self.C)[0]
        object.__setattr__(self, "A", _matrix("A", self.A, (n, n)))
        object.__setattr__(self, "B", _matrix("B", self.B, (n, nu)))
        object.__setattr__(self, "C", _matrix("C", self.C, (ny, n)))
        object.__setattr__(self, "D", _matrix("D", self.D, (ny, nu)))
        if self.ts is not None:
            object.__setattr__(self, "ts", float(checked(PositiveNumber, "ts", self.ts, IdentificationError)))
        if self.K is not None:
            if self.ts is None:
                raise IdentificationError("K: an innovations gain belongs to a discrete system (give ts)")
            object.__setattr__(self, "K", _matrix("K", self.K, (n, ny)))
        if self.noise_covariance is not None:
            object.__setattr__(self, "noise_covariance", _matrix("noise_covariance", self.noise_covariance, (ny, ny)))

    # -- sizes -------------------------------------------------------------

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    @property
    def is_discrete(self) -> bool:
        return self.ts is not None

    def _require(self, discrete: bool, what: str) -> None:
        if self.is_discrete != discrete:
            raise IdentificationError(f"{what} needs a {'discrete' if discrete else 'continuous'} system, this one "
                                      f"is {'discrete' if self.is_discrete else 'continuous'}")

    # -- properties of the dynamics -------------------------------------------

    def poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.A) if self.n_states else np.zeros(0, dtype=complex)

    def is_stable(self) -> bool:
        poles = self.poles()
        if not poles.size:
            return True
        return bool(np.max(np.abs(poles)) < 1) if self.is_discrete else bool(np.max(poles.real) < 0)

    def frequency_response(self, omega: np.ndarray) -> np.ndarray:
        """G at the angular frequencies ``omega`` (rad/s), shape (len(omega), ny, nu): C (zI - A)^-1 B + D
        with z = exp(j omega ts), or s = j omega in continuous time."""
        omega = np.atleast_1d(np.asarray(omega, dtype=np.float64))
        points = np.exp(1j * omega * self.ts) if self.is_discrete else 1j * omega
        n = self.n_states
        if not n:
            return np.broadcast_to(self.D, (len(omega), *self.D.shape)).astype(complex)
        resolvent = points[:, None, None] * np.eye(n) - self.A
        return self.C @ np.linalg.solve(resolvent, np.broadcast_to(self.B, (len(omega), *self.B.shape))) + self.D

    def dc_gain(self) -> np.ndarray:
        """G at zero frequency (ny, nu)."""
        return self.frequency_response(np.zeros(1))[0].real

    def markov_parameters(self, count: int) -> np.ndarray:
        """D, CB, CAB, ... CA^(count-2)B of a discrete system: its impulse response, (count, ny, nu)."""
        self._require(True, "markov_parameters")
        blocks = [self.D]
        power = self.B
        for _ in range(count - 1):
            blocks.append(self.C @ power)
            power = self.A @ power
        return np.array(blocks[:count])

    # -- zero-order hold ------------------------------------------------------

    def to_discrete(self, ts: float) -> StateSpace:
        """The exact zero-order-hold equivalent at sample time ``ts``."""
        self._require(False, "to_discrete")
        ts = checked(PositiveNumber, "ts", ts, IdentificationError)
        n, nu = self.n_states, self.n_inputs
        # exp of [[A, B], [0, 0]] ts holds [[Ad, Bd], [0, I]] (what scipy.signal.cont2discrete computes)
        augmented = np.zeros((n + nu, n + nu))
        augmented[:n, :n], augmented[:n, n:] = self.A, self.B
        held = scipy.linalg.expm(augmented * ts)
        return StateSpace(held[:n, :n], held[:n, n:], self.C, self.D, ts)

    def to_continuous(self) -> StateSpace:
        """The continuous system whose zero-order-hold equivalent this one is (matrix logarithm)."""
        self._require(True, "to_continuous")
        n, nu = self.n_states, self.n_inputs
        poles = self.poles()
        on_axis = poles[(np.abs(poles.imag) <= 1e-12 * np.maximum(1, np.abs(poles))) & (poles.real <= 0)]
        if on_axis.size:
            raise IdentificationError(f"no continuous system has this discrete one as its zero-order hold: it has "
                                      f"a pole at {on_axis[0].real:.4g} on the negative real axis (keep it discrete)")
        block = np.zeros((n + nu, n + nu))
        block[:n, :n], block[:n, n:], block[n:, n:] = self.A, self.B, np.eye(nu)
        logarithm = scipy.linalg.logm(block) / self.ts
        if np.max(np.abs(np.imag(logarithm)), initial=0) > 1e-8 * max(1.0, np.max(np.abs(logarithm))):
            raise IdentificationError("the matrix logarithm of this system is not real: no continuous system "
                                      "has it as its zero-order hold (keep it discrete)")
        logarithm = np.real(logarithm)
        return StateSpace(logarithm[:n, :n], logarithm[:n, n:], self.C, self.D)
