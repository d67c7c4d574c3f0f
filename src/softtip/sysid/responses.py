"""Time responses of identified models, with confidence bands, and the measured-against-simulated plot
(MATLAB's ``step``, ``impulse`` with ``showConfidence``, and ``compare``).

A step is a unit step on one input from rest; an impulse a pulse of unit area (1 / ts for one sample),
so that a model's impulse response approximates its continuous one. Bands are first-order (delta
method): the response's gradient along each parameter by central differences of the responses of the
perturbed models, σ² = gᵀ C g with the model's parameter covariance C.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from softtip.sysid.simulation import simulate
from softtip.sysid.statespace import IdentificationError, StateSpace

if TYPE_CHECKING:
    from matplotlib.figure import Figure

KINDS = ("step", "impulse")
_SETTLE = 5.0  # time constants of the slowest pole a response shows
_MIN_STEPS, _MAX_STEPS = 20, 2000
_RELATIVE_STEP = 1e-6  # central-difference step, relative to a parameter's size


def response_length(system: StateSpace) -> int:
    """Samples that show ``_SETTLE`` time constants of the slowest pole (between 20 and 2,000)."""
    moduli = np.abs(system.poles())
    slowest = float(np.max(moduli)) if moduli.size else 0.0
    if slowest >= 1:
        return _MAX_STEPS
    samples = _SETTLE / -np.log(max(slowest, 1e-300))
    return int(np.clip(np.ceil(samples), _MIN_STEPS, _MAX_STEPS))


def time_responses(system: StateSpace, steps: int, kind: str) -> np.ndarray:
    """(steps, ny, nu): the outputs of the discrete ``system`` from rest to a unit step (``"step"``) or a
    unit-area pulse (``"impulse"``) on each input in turn."""
    if kind not in KINDS:
        raise IdentificationError(f"response kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    signal = np.ones(steps) if kind == "step" else np.r_[1.0 / system.ts, np.zeros(steps - 1)]
    responses = np.empty((steps, system.n_outputs, system.n_inputs))
    for j in range(system.n_inputs):
        u = np.zeros((steps, system.n_inputs))
        u[:, j] = signal
        responses[:, :, j] = simulate(system, u)
    return responses


def response_spread(perturbed: Callable[[int, float], StateSpace], scales: np.ndarray, covariance: np.ndarray,
                    steps: int, kind: str) -> np.ndarray:
    """Variance (steps, ny, nu) of the responses, to first order: ``perturbed(k, h)`` is the system with
    parameter k moved by h, ``scales`` each parameter's size (its difference step is 1e-6 of it, at
    least 1e-6), ``covariance`` the parameters' covariance."""
    gradient = []
    for k, scale in enumerate(scales):
        h = _RELATIVE_STEP * max(abs(float(scale)), 1.0)
        gradient.append((time_responses(perturbed(k, h), steps, kind) -
                         time_responses(perturbed(k, -h), steps, kind)) / (2 * h))
    gradient = np.array(gradient)
    return np.maximum(np.einsum("ptyu,pq,qtyu->tyu", gradient, covariance, gradient), 0.0)


@dataclass(frozen=True)
class TimeResponse:
    """A model's ``kind`` response: ``time`` (s), ``response`` (T, ny, nu), its standard deviation
    (None without a parameter covariance) and the interval's quantile ``z``."""

    kind: str
    time: np.ndarray
    response: np.ndarray
    std: np.ndarray | None
    z: float
    confidence: float

    def to_dict(self) -> dict:
        return {"kind": self.kind, "time_s": self.time.tolist(), "response": self.response.tolist(),
                "std": None if self.std is None else self.std.tolist(), "z": self.z, "confidence": self.confidence}


def response_figure(found: TimeResponse, names: tuple[Sequence[str], Sequence[str]],
                    units: tuple[Sequence[str], Sequence[str]]) -> Figure:
    """Every entry's response against time, with its band when there is one."""
    from matplotlib.figure import Figure

    _, ny, nu = found.response.shape
    figure = Figure(figsize=(4.0 * nu, 2.8 * ny), constrained_layout=True)
    axes = figure.subplots(ny, nu, squeeze=False, sharex=True)
    for i in range(ny):
        for j in range(nu):
            axis = axes[i, j]
            value = found.response[:, i, j]
            if found.std is not None:
                reach = found.z * found.std[:, i, j]
                axis.fill_between(found.time, value - reach, value + reach, alpha=0.3,
                                  label=f"{100 * found.confidence:g} % band")
            axis.plot(found.time, value, label="model")
            axis.set_title(f"{found.kind}: {names[0][j]} → {names[1][i]}")
            output, input = units[1][i] or "1", units[0][j] or "1"
            # a step's response per unit of input; a unit-area pulse's per unit of input and second
            unit = f"{output}/{input}" if found.kind == "step" else f"{output}/({input}·s)"
            axis.set_ylabel(f"{names[1][i]} ({unit})")
            axis.grid(True, alpha=0.3)
        axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].legend(loc="best", fontsize="small")
    return figure


def compare_figure(measured: Sequence[np.ndarray], simulated: Sequence[np.ndarray], ts: float,
                   outputs: Sequence[str], units: Sequence[str], fits: np.ndarray, source: str,
                   initial_state: str) -> Figure:
    """Measured against simulated outputs, one axis per output, the trials end to end (dotted lines at
    their joins), each output's fit % in its title."""
    from matplotlib.figure import Figure

    ny = len(outputs)
    figure = Figure(figsize=(10.0, 2.6 * ny), constrained_layout=True)
    axes = figure.subplots(ny, 1, squeeze=False, sharex=True)[:, 0]
    lengths = [len(y) for y in measured]
    time = np.arange(sum(lengths)) * ts
    joins = np.cumsum(lengths)[:-1] * ts
    y, yhat = np.vstack(measured), np.vstack(simulated)
    for i, axis in enumerate(axes):
        axis.plot(time, y[:, i], color="0.3", linewidth=1.0, label="measured")
        axis.plot(time, yhat[:, i], linewidth=1.0, label=f"simulated ({initial_state} initial state)")
        for join in joins:
            axis.axvline(join, color="0.6", linestyle=":", linewidth=0.8)
        axis.set_title(f"{outputs[i]}: fit {fits[i]:.1f} %")
        axis.set_ylabel(f"{outputs[i]} ({units[i]})" if units[i] else outputs[i])
        axis.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize="small")
    axes[-1].set_xlabel(f"time (s): {source}" if len(lengths) == 1 else
                        f"time (s): the {len(lengths)} trials of {source} end to end")
    return figure
