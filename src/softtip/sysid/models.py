"""Identified models as estimators, scikit-learn style as far as it fits time series.

``fit(recording)`` identifies, then ``simulate``, ``predict(recording, k)``, ``score`` (the mean R²
over outputs, simulated), ``evaluate`` (every metric per output), ``streaming()`` (frame by frame),
``summary()`` (a JSON-able dict) and ``get_params``/``set_params``:

- :class:`StateSpaceModel`: subspace identification (N4SID, MOESP or CVA) with optional
  prediction-error refinement; discrete, or continuous through the inverse zero-order hold;
- :class:`TransferFunctionModel`: a continuous transfer-function matrix (SRIVC and output-error
  refinement, :func:`softtip.sysid.transfer.fit`), realised as state space and discretised by
  zero-order hold so that it too runs frame by frame.

Both run as a discrete system ``system_`` at the recording's sample time, from the zero state
(a recording starts at rest, or is detrended). :func:`order_table` fits a range of orders.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Annotated, Any, Optional, Self, Union

import numpy as np
from sklearn.base import BaseEstimator

from softtip._core.config import Flag, OpenFraction, PositiveInteger, checked, choice, expect, integer
from softtip._core.threads import single_threaded_blas
from softtip.sysid import transfer
from softtip.sysid.metrics import MEASURED, FullScale, Scores, fit_percent, score_outputs
from softtip.sysid.realisation import realise
from softtip.sysid.recording import Recording
from softtip.sysid.refine import RefinementReport, refine
from softtip.sysid.simulation import StreamingSimulator, predict, simulate
from softtip.sysid.statespace import IdentificationError, StateSpace
from softtip.sysid.subspace import AUTO, MAX_ORDER, METHODS, subspace_identify

DOMAINS = ("discrete", "continuous")
ORDER = Annotated[Union[choice(AUTO), PositiveInteger], expect(f'"{AUTO}" or a positive integer')]
_TS_TOLERANCE = 1e-6  # relative: a recording at another sample time needs another discretisation


def _poles(values: np.ndarray) -> list[list[float]]:
    return [[float(p.real), float(p.imag)] for p in sorted(values, key=lambda p: (-abs(p), p.imag))]


class IdentifiedModel(BaseEstimator):
    """What both kinds share once fitted: the discrete system ``system_`` at the sample time ``ts_``.

    Each kind identifies itself in ``_identify(recording)``, which returns its simulation of the
    recording (what ``fit_percent_`` scores, and :func:`order_table` reuses).
    """

    _PARAMETERS: dict[str, Any] = {}  # parameter -> the type it must have

    def _check_params(self) -> None:
        for name, kind in self._PARAMETERS.items():
            checked(kind, name, getattr(self, name), IdentificationError)

    def fit(self, recording: Recording) -> Self:
        """Identifies the model on ``recording``; returns it."""
        self._identify(recording)
        return self

    def _remember(self, recording: Recording, started: float) -> list[np.ndarray]:
        """Keeps what the fit was made on and how well it simulates it; returns that simulation."""
        self.ts_ = recording.ts
        self.inputs_, self.outputs_ = recording.inputs, recording.outputs
        self.input_units_, self.output_units_ = recording.input_units, recording.output_units
        self.data_ = recording.describe()
        simulated = self.simulate(recording)
        self.fit_percent_ = fit_percent(np.vstack([trial.y for trial in recording.trials]), np.vstack(simulated))
        self.fit_seconds_ = time.perf_counter() - started
        return simulated

    def _check_fitted(self) -> None:
        if not hasattr(self, "system_"):
            raise IdentificationError(f"this {type(self).__name__} is not fitted: call fit(recording) first")

    def _check_recording(self, recording: Recording) -> None:
        self._check_fitted()
        if not isinstance(recording, Recording):
            raise IdentificationError(f"expected a Recording, got {type(recording).__name__}")
        if recording.inputs != self.inputs_:
            raise IdentificationError(f"{recording.source}: inputs {list(recording.inputs)}, the model takes "
                                      f"{list(self.inputs_)}")
        if abs(recording.ts - self.ts_) > _TS_TOLERANCE * self.ts_:
            raise IdentificationError(f"{recording.source}: sample time {recording.ts:g} s, the model runs at "
                                      f"{self.ts_:g} s")

    def _check_outputs(self, recording: Recording) -> None:
        self._check_recording(recording)
        if recording.outputs != self.outputs_:
            raise IdentificationError(f"{recording.source}: outputs {list(recording.outputs)}, the model gives "
                                      f"{list(self.outputs_)}")

    def simulate(self, data: Recording | np.ndarray) -> list[np.ndarray] | np.ndarray:
        """The simulated outputs from the zero state: of every trial of a recording (a list of (N, ny)),
        or of an input array u (N, nu)."""
        self._check_fitted()
        if isinstance(data, Recording):
            self._check_recording(data)
            return [simulate(self.system_, trial.u) for trial in data.trials]
        return simulate(self.system_, data)

    def predict(self, recording: Recording, k: int | None = 1) -> list[np.ndarray]:
        """k-step-ahead predictions of every trial (``k`` None: simulation); see
        :func:`softtip.sysid.simulation.predict`."""
        self._check_outputs(recording)
        if k is None:
            return self.simulate(recording)
        return [predict(self.system_, trial.u, trial.y, k) for trial in recording.trials]

    def evaluate(self, recording: Recording, k: int | None = None, full_scale: FullScale = MEASURED) -> Scores:
        """Every metric per output on the scored samples of ``recording``, simulated (``k`` None) or
        predicted ``k`` steps ahead."""
        return self.evaluate_predictions(recording, self.predict(recording, k), full_scale)

    def evaluate_predictions(self, recording: Recording, predicted: list[np.ndarray],
                             full_scale: FullScale = MEASURED) -> Scores:
        """Every metric per output of the model's outputs ``predicted`` for ``recording`` (one array per
        trial: its simulation or predictions) on the scored samples of ``recording``."""
        self._check_outputs(recording)
        masks = [np.ones(len(trial), bool) if trial.scored is None else trial.scored for trial in recording.trials]
        y = np.vstack([trial.y[mask] for trial, mask in zip(recording.trials, masks, strict=True)])
        yhat = np.vstack([values[mask] for values, mask in zip(predicted, masks, strict=True)])
        return score_outputs(y, yhat, self.outputs_, self.output_units_, full_scale)

    def score(self, recording: Recording, k: int | None = None) -> float:
        """The mean over outputs of R² (scikit-learn's ``score``), simulated unless ``k`` is given."""
        return self.evaluate(recording, k).mean("r2")

    def streaming(self) -> StreamingSimulator:
        """The model as a frame-by-frame simulator from the zero state."""
        self._check_fitted()
        return StreamingSimulator(self.system_)

    def residuals(self, recording: Recording) -> np.ndarray:
        """One-step prediction errors of every trial, stacked (N, ny)."""
        return _errors(recording, self.predict(recording, 1))

    # -- model files (softtip.sysid.files) ----------------------------------------

    def _export(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(JSON-able fitted state, arrays) of a fitted model."""
        self._check_fitted()
        system = self.system_
        arrays = {f"system/{name}": getattr(system, name) for name in ("A", "B", "C", "D")}
        if system.K is not None:
            arrays["system/K"] = system.K
            arrays["system/noise_covariance"] = system.noise_covariance
        state = {"ts": self.ts_, "inputs": list(self.inputs_), "outputs": list(self.outputs_),
                 "input_units": list(self.input_units_), "output_units": list(self.output_units_),
                 "data": self.data_, "fit_percent": [float(v) for v in self.fit_percent_],
                 "fit_seconds": self.fit_seconds_}
        return state, arrays

    def _restore_common(self, state: dict, arrays: dict[str, np.ndarray]) -> None:
        self.ts_ = float(state["ts"])
        self.inputs_, self.outputs_ = tuple(state["inputs"]), tuple(state["outputs"])
        self.input_units_, self.output_units_ = tuple(state["input_units"]), tuple(state["output_units"])
        self.data_ = state["data"]
        self.fit_percent_ = np.asarray(state["fit_percent"], dtype=np.float64)
        self.fit_seconds_ = float(state["fit_seconds"])
        self.system_ = StateSpace(arrays["system/A"], arrays["system/B"], arrays["system/C"], arrays["system/D"],
                                  self.ts_, arrays.get("system/K"), arrays.get("system/noise_covariance"))
        sizes = (self.system_.n_inputs, self.system_.n_outputs, len(self.fit_percent_))
        if sizes != (len(self.inputs_), len(self.outputs_), len(self.outputs_)) or \
                len(self.input_units_) != len(self.inputs_) or len(self.output_units_) != len(self.outputs_):
            raise IdentificationError(f"{len(self.inputs_)} inputs and {len(self.outputs_)} outputs named, the "
                                      f"system has {sizes[0]} and {sizes[1]}")

    def _summary(self, kind: str) -> dict:
        self._check_fitted()
        return {"kind": kind, "params": self.get_params(), "ts": self.ts_, "inputs": list(self.inputs_),
                "outputs": list(self.outputs_), "input_units": list(self.input_units_),
                "output_units": list(self.output_units_), "states": self.system_.n_states,
                "parameters": self.n_parameters, "discrete_poles": _poles(self.system_.poles()),
                "stable": self.system_.is_stable(),
                "fit_percent": {name: float(v) for name, v in zip(self.outputs_, self.fit_percent_, strict=True)},
                "fit_seconds": self.fit_seconds_, "data": self.data_}


class StateSpaceModel(IdentifiedModel):
    """x[t+1] = A x + B u + K e, y = C x + D u + e identified by subspace methods (MATLAB's ``n4sid``;
    with ``refine``, its prediction-error refinement as in ``ssest``).

    ``order``: the number of states, or ``"auto"`` (the largest drop in the singular values, up to
    ``max_order``; see :mod:`softtip.sysid.subspace`); ``method``: ``"n4sid"``, ``"moesp"`` or
    ``"cva"``; ``horizon``: past/future block rows (default from the order); ``domain``:
    ``"continuous"`` also gives ``continuous_``, the system whose zero-order hold is ``system_``;
    ``max_iterations`` and ``tolerance``: the refinement's stopping rules (:mod:`softtip.sysid.refine`).
    """

    _PARAMETERS = {"order": ORDER, "method": choice(*METHODS), "domain": choice(*DOMAINS), "refine": Flag,
                   "enforce_stability": Flag, "horizon": Optional[integer(2)], "max_order": PositiveInteger,
                   "max_iterations": PositiveInteger, "tolerance": OpenFraction}

    def __init__(self, order: int | str = AUTO, method: str = "n4sid", *, refine: bool = False,
                 domain: str = "discrete", horizon: int | None = None, max_order: int = MAX_ORDER,
                 enforce_stability: bool = True, max_iterations: int = 20, tolerance: float = 1e-4):
        self.order = order
        self.method = method
        self.refine = refine
        self.domain = domain
        self.horizon = horizon
        self.max_order = max_order
        self.enforce_stability = enforce_stability
        self.max_iterations = max_iterations
        self.tolerance = tolerance

    def _identify(self, recording: Recording) -> list[np.ndarray]:
        started = time.perf_counter()
        self._check_params()
        recording.require_excitation()
        with single_threaded_blas():
            found = subspace_identify(recording.segments, recording.ts, self.order, self.method,
                                      horizon=self.horizon, max_order=self.max_order,
                                      enforce_stability=self.enforce_stability)
            system, report = found.system, None
            if self.refine:
                system, report = refine(system, recording.segments, max_iterations=self.max_iterations,
                                        tolerance=self.tolerance)
        self.continuous_ = system.to_continuous() if self.domain == "continuous" else None
        self.system_ = system
        self.order_, self.horizon_ = found.order, found.horizon
        self.singular_values_ = found.singular_values
        self.reflected_poles_, self.kalman_ = found.reflected_poles, found.kalman
        self.refinement_: RefinementReport | None = report
        return self._remember(recording, started)

    @property
    def n_parameters(self) -> int:
        """Free parameters of (A, B, C, D, K) up to a change of state basis: n (nu + 2 ny) + ny nu."""
        system = self.system_
        n, nu, ny = system.n_states, system.n_inputs, system.n_outputs
        return n * (nu + 2 * ny) + ny * nu

    def _export(self) -> tuple[dict, dict[str, np.ndarray]]:
        state, arrays = super()._export()
        arrays["singular_values"] = self.singular_values_
        state |= {"order": self.order_, "horizon": self.horizon_, "reflected_poles": self.reflected_poles_,
                  "kalman": self.kalman_, "refinement": None if self.refinement_ is None else self.refinement_.to_dict()}
        return state, arrays

    def _restore(self, state: dict, arrays: dict[str, np.ndarray]) -> None:
        self._restore_common(state, arrays)
        if self.system_.K is None:
            raise IdentificationError("a state-space model needs its Kalman gain K")
        self.order_, self.horizon_ = int(state["order"]), int(state["horizon"])
        self.singular_values_ = np.asarray(arrays["singular_values"], dtype=np.float64)
        self.reflected_poles_, self.kalman_ = int(state["reflected_poles"]), str(state["kalman"])
        self.refinement_ = None if state["refinement"] is None else RefinementReport(**state["refinement"])
        self.continuous_ = self.system_.to_continuous() if self.domain == "continuous" else None
        if self.order_ != self.system_.n_states:
            raise IdentificationError(f"order {self.order_}, but A has {self.system_.n_states} states")

    def summary(self) -> dict:
        summary = self._summary("state space") | {
            "method": self.method, "order": self.order_, "horizon": self.horizon_, "domain": self.domain,
            "singular_values": [float(v) for v in self.singular_values_[:2 * MAX_ORDER]],
            "reflected_poles": self.reflected_poles_, "kalman": self.kalman_,
            "refinement": None if self.refinement_ is None else self.refinement_.to_dict()}
        if self.continuous_ is not None:
            summary["continuous_poles"] = _poles(self.continuous_.poles())
        return summary


class TransferFunctionModel(IdentifiedModel):
    """Y(s) = G(s) U(s), G an ny x nu matrix of continuous transfer functions, every entry with
    ``n_poles`` poles and ``n_zeros`` zeros (default ``n_poles - 1``); MATLAB's ``tfest``.

    ``tf_`` is G; ``system_`` its block-diagonal canonical realisation discretised by zero-order
    hold at the recording's sample time (:mod:`softtip.sysid.realisation`), which runs it.
    """

    _PARAMETERS = {"n_poles": PositiveInteger, "refine": Flag, "enforce_stability": Flag,
                   "max_iterations": PositiveInteger}

    def __init__(self, n_poles: int = 6, n_zeros: int | None = None, *, refine: bool = True,
                 enforce_stability: bool = True, max_iterations: int = 100):
        self.n_poles = n_poles
        self.n_zeros = n_zeros
        self.refine = refine
        self.enforce_stability = enforce_stability
        self.max_iterations = max_iterations

    def _check_params(self) -> None:
        super()._check_params()
        if self.n_zeros is not None:
            checked(integer(0, self.n_poles, f"an integer 0..n_poles ({self.n_poles})"), "n_zeros", self.n_zeros,
                    IdentificationError)

    def _identify(self, recording: Recording) -> list[np.ndarray]:
        started = time.perf_counter()
        self._check_params()
        recording.require_excitation()
        tf, report = transfer.fit(recording.segments, recording.ts, self.n_poles, self.n_zeros, refine=self.refine,
                                  max_iterations=self.max_iterations, enforce_stability=self.enforce_stability)
        self._set_transfer_function(tf, recording.ts)
        self.report_ = report
        return self._remember(recording, started)

    def _set_transfer_function(self, tf: transfer.TransferFunctionMatrix, ts: float) -> None:
        self.tf_ = tf
        self.continuous_ = realise(tf.numerators, tf.denominators)
        self.system_ = self.continuous_.to_discrete(ts)

    def _export(self) -> tuple[dict, dict[str, np.ndarray]]:
        state, arrays = super()._export()
        for role in ("numerators", "denominators"):
            for i, row in enumerate(getattr(self.tf_, role)):
                for j, coefficients in enumerate(row):
                    arrays[f"tf/{role}/{i}/{j}"] = coefficients
        state["report"] = self.report_.to_dict()
        return state, arrays

    def _restore(self, state: dict, arrays: dict[str, np.ndarray]) -> None:
        self._restore_common(state, arrays)
        ny, nu = self.system_.n_outputs, self.system_.n_inputs
        table = {role: [[arrays.get(f"tf/{role}/{i}/{j}") for j in range(nu)] for i in range(ny)]
                 for role in ("numerators", "denominators")}
        if any(entry is None for rows in table.values() for row in rows for entry in row):
            raise IdentificationError(f"the transfer function lacks entries of its {ny} x {nu} table")
        saved = self.system_
        self._set_transfer_function(transfer.TransferFunctionMatrix(table["numerators"], table["denominators"]),
                                    self.ts_)
        if self.system_.n_states != saved.n_states or not all(
                np.allclose(getattr(self.system_, name), getattr(saved, name), rtol=1e-9, atol=1e-12)
                for name in ("A", "B", "C", "D")):
            raise IdentificationError("the saved discrete system is not the realisation of the saved transfer function")
        self.report_ = transfer.FitReport.from_dict(state["report"])

    @property
    def n_parameters(self) -> int:
        """Coefficients of every entry: n_poles (monic denominator) + n_zeros + 1."""
        return int(np.sum(self.tf_.n_poles + self.tf_.n_zeros + 1))

    def summary(self) -> dict:
        return self._summary("transfer function") | {
            "n_poles": self.tf_.n_poles.tolist(), "n_zeros": self.tf_.n_zeros.tolist(),
            "continuous_stable": self.tf_.is_stable(),
            "numerators": [[b.tolist() for b in row] for row in self.tf_.numerators],
            "denominators": [[a.tolist() for a in row] for row in self.tf_.denominators],
            # the summary's fit % per output is by name, above
            "report": {key: value for key, value in self.report_.to_dict().items() if key != "per_output_fit_percent"}}


# ------------------------------------------------------------------------------------------- order tables

KINDS = {"tf": TransferFunctionModel, "ss": StateSpaceModel}
DEFAULT_ORDERS = {"tf": range(2, 9), "ss": range(2, 13)}


def _errors(recording: Recording, predicted: list[np.ndarray]) -> np.ndarray:
    """The errors of ``predicted`` (one array per trial) against the outputs of ``recording``, stacked (N, ny)."""
    return np.vstack([trial.y - yhat for trial, yhat in zip(recording.trials, predicted, strict=True)])


def information_criteria(errors: np.ndarray, n_parameters: int) -> tuple[float, float]:
    """(AIC, BIC) of residuals ``errors`` (N, ny) of a model of ``n_parameters`` parameters (MATLAB's
    ``aic(sys)`` and ``aic(sys, 'BIC')``): with Σ = EᵀE / N,
    AIC = N ln det Σ + 2 p + N ny (ln 2π + 1) and BIC = N ln det Σ + p ln N + N ny (ln 2π + 1)."""
    N, ny = errors.shape
    _, log_det = np.linalg.slogdet(errors.T @ errors / N)
    common = N * log_det + N * ny * (np.log(2 * np.pi) + 1)
    return float(common + 2 * n_parameters), float(common + n_parameters * np.log(N))


def order_table(recording: Recording, kind: str, orders: Iterable[int] | None = None,
                validation: Recording | None = None, **params) -> list[dict]:
    """One fit per order (``kind`` "tf": poles per entry, default 2-8; "ss": states, default 2-12),
    each row with the order, the parameter count, the fit % per output and its mean (on ``validation``
    when given, else on the estimation data; simulated), AIC and BIC (one-step prediction errors on the
    estimation data; the simulation errors of a transfer function, which has no noise model), whether
    it is stable, and the seconds the fit took."""
    if kind not in KINDS:
        raise IdentificationError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    orders = list(DEFAULT_ORDERS[kind] if orders is None else orders)
    if not orders:
        raise IdentificationError("orders: none given")
    rows = []
    for order in orders:
        model = KINDS[kind](order, **params) if kind == "ss" else KINDS[kind](n_poles=order, **params)
        started = time.perf_counter()
        simulated = model._identify(recording)
        seconds = time.perf_counter() - started
        # the fit's simulation of the estimation data scores it there, and is the one-step prediction of a
        # model without a noise model
        if validation is None:
            scores = model.evaluate_predictions(recording, simulated)
        else:
            scores = model.evaluate(validation)
        one_step = simulated if model.system_.K is None else model.predict(recording, 1)
        aic, bic = information_criteria(_errors(recording, one_step), model.n_parameters)
        fits = scores.values["fit_percent"]
        rows.append({"order": order, "parameters": model.n_parameters, "fit_percent": float(np.mean(fits)),
                     "fit_percent_per_output": {name: float(v) for name, v in zip(model.outputs_, fits, strict=True)},
                     "aic": aic, "bic": bic, "stable": model.system_.is_stable(), "seconds": seconds})
    return rows
