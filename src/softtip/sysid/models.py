"""Identified models as estimators, scikit-learn style as far as it fits time series.

``fit(recording)`` identifies, then ``simulate``, ``predict(recording, k)``, ``score`` (the mean R²
over outputs, simulated), ``evaluate`` (every metric per output), ``streaming()`` (frame by frame),
``summary()`` (a JSON-able dict) and ``get_params``/``set_params``:

- :class:`StateSpaceModel`: subspace identification (N4SID, MOESP or CVA) with optional
  prediction-error refinement; discrete, or continuous through the inverse zero-order hold;
- :class:`TransferFunctionModel`: a continuous transfer-function matrix (SRIVC and output-error
  refinement, :func:`softtip.sysid.transfer.fit`), realised as state space and discretised by
  zero-order hold so that it too runs frame by frame.

Both run as a discrete system ``system_`` at the recording's sample time, from the zero state or
from each trial's estimated initial state (``initial_state="estimate"``), about the levels
``trend_`` (``detrend``) and behind the input delays ``delays_`` (``delay``); both carry the
covariance of their parameters (``covariance_``, ``uncertainty()``, ``bode()``; not computed with
``estimate_covariance=False``, for fits that never read it) and test their residuals
(``residual_tests``). :func:`order_table` fits a range of orders.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Iterable
from dataclasses import replace
from typing import TYPE_CHECKING, Annotated, Any, Optional, Self, Union

import numpy as np

from softtip._core.config import Flag, OpenFraction, PositiveInteger, checked, choice, expect, integer
from softtip._core.threads import single_threaded_blas
from softtip.sysid import transfer
from softtip.sysid.delays import (
    ESTIMATE,
    estimate_delays,
    resolve,
    shift_inputs,
    with_input_delays,
    without_input_delays,
)
from softtip.sysid.metrics import MEASURED, FullScale, Scores, fit_percent, score_outputs
from softtip.sysid.realisation import realise
from softtip.sysid.recording import Recording
from softtip.sysid.refine import RefinementReport, StateSpaceCovariance, parameter_covariance, refine
from softtip.sysid.residuals import ResidualTests, residual_tests
from softtip.sysid.responses import (
    TimeResponse,
    compare_figure,
    response_figure,
    response_length,
    response_spread,
    time_responses,
)
from softtip.sysid.robust import COVARIANCES, SANDWICH, WHITE, WHITE_ASSUMPTION, sandwich_assumption
from softtip.sysid.simulation import (
    StreamingSimulator,
    estimate_initial_state,
    free_response,
    predict,
    runs_away,
    simulate,
)
from softtip.sysid.statespace import IdentificationError, StateSpace
from softtip.sysid.subspace import AUTO, MAX_ORDER, METHODS, subspace_identify
from softtip.sysid.trends import TREND_KINDS, Trend, estimate_trend
from softtip.sysid.uncertainty import (
    bode_figure,
    empirical_transfer_function,
    frequency_band,
    intervals,
    normal_quantile,
    state_space_bands,
    state_space_intervals,
)
from softtip.sysid.verdicts import stability

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DOMAINS = ("discrete", "continuous")
ORDER = Annotated[Union[choice(AUTO), PositiveInteger], expect(f'"{AUTO}" or a positive integer')]
INITIAL_STATES = ("zero", "estimate")
_LEVEL_RATIO = 1e4
_LEVEL_ROUNDS = 20  # rounds of output-level estimation at most
_ETFE_SAMPLES = 128  # a trial shorter gives too few averaged windows for an empirical transfer function
_COVARIANCE_BUDGET = 3e7  # numbers (8 bytes each) a state-space covariance's Jacobian may hold
_DELAY_NEIGHBOURS = 2  # delays either side of the ARX choice that the model's own fit decides between
_TS_TOLERANCE = 1e-6  # relative: a recording at another sample time needs another discretisation


def _poles(values: np.ndarray) -> list[list[float]]:
    return [[float(p.real), float(p.imag)] for p in sorted(values, key=lambda p: (-abs(p), p.imag))]


def _require_levels_within_reach(recording: Recording) -> None:
    """Refuses a recording whose level dwarfs its variation (|mean| > ``_LEVEL_RATIO`` x std in a channel)
    when no trend is taken out: a model of deviations from zero would spend its digits on the level
    (the estimators' squared quantities keep about eps x ratio² of the variation)."""
    for role, names, signals in (("input", recording.inputs, [trial.u for trial in recording.trials]),
                                 ("output", recording.outputs, [trial.y for trial in recording.trials])):
        values = np.vstack(signals)
        level, variation = np.abs(values.mean(axis=0)), values.std(axis=0)
        for name, a, b in zip(names, level, variation, strict=True):
            if a > _LEVEL_RATIO * b:
                raise IdentificationError(f"{recording.source}: {role} {name!r} sits at {a:.6g}, {a / b:.3g} times "
                                          f"its variation ({b:.3g}): take the level out (detrend 'mean' or "
                                          "'linear'; --detrend on the command line)")


class Estimator:
    """scikit-learn's estimator convention, without importing scikit-learn (whose import takes seconds,
    longer than a command's start may): the keyword parameters of ``__init__`` are the estimator's
    parameters, stored as given; ``get_params``/``set_params`` read and change them as
    ``sklearn.base.BaseEstimator``'s do, so ``sklearn.base.clone`` copies one."""

    @classmethod
    def _parameter_names(cls) -> list[str]:
        return sorted(name for name in inspect.signature(cls.__init__).parameters if name != "self")

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The parameters by name (``deep`` as scikit-learn's: no parameter here is an estimator)."""
        return {name: getattr(self, name) for name in self._parameter_names()}

    def set_params(self, **params) -> Self:
        """Changes the parameters named; refuses a name that is not one."""
        names = self._parameter_names()
        for name, value in params.items():
            if name not in names:
                raise IdentificationError(f"{name}: not a parameter of {type(self).__name__} "
                                          f"(parameters: {', '.join(names)})")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        signature = inspect.signature(type(self).__init__).parameters
        defaults = {name: parameter.default for name, parameter in signature.items()}
        changed = [f"{name}={value!r}" for name, value in self.get_params().items() if value != defaults[name]]
        return f"{type(self).__name__}({', '.join(changed)})"


class IdentifiedModel(Estimator):
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

    def _check_common_params(self) -> None:
        if self.detrend not in TREND_KINDS:
            raise IdentificationError(f"detrend: expected one of {', '.join(TREND_KINDS)}, got {self.detrend!r}")
        if self.initial_state not in INITIAL_STATES:
            raise IdentificationError(f"initial_state: expected one of {', '.join(INITIAL_STATES)}, "
                                      f"got {self.initial_state!r}")
        if self.delay != ESTIMATE:
            resolve(self.delay, np.size(self.delay))
        checked(PositiveInteger, "max_delay", self.max_delay, IdentificationError)

    def _identify(self, recording: Recording) -> list[np.ndarray]:
        """Identifies on ``recording``; returns the model's simulation of it (what ``fit_percent_`` scores)."""
        started = time.perf_counter()
        self.delay_search_ = self.level_rounds_ = None  # set by the delay search and the level estimation
        segments, delays = self._prepared(recording)
        if delays is None:
            delays = self._searched_delays(segments, recording.ts)
        self.delays_ = delays
        shifted = [(shift_inputs(u, delays), y) for u, y in segments]
        try:
            with single_threaded_blas():
                core = self._fit_delay_free(shifted, recording.ts)
                if self.detrend == "estimate" or self.initial_state == "estimate":
                    core, shifted = self._with_estimated_initial_states(core, shifted, recording.ts,
                                                                        levels=self.detrend == "estimate")
                if self.estimate_covariance:
                    self._estimate_uncertainty(core, shifted, recording.ts)
                else:
                    self.covariance_, self.covariance_note_ = None, "not computed (estimate_covariance=False)"
        except np.linalg.LinAlgError as problem:
            raise IdentificationError(f"{recording.source}: the identification failed numerically ({problem}): "
                                      "try a lower order or detrend") from None
        self.system_ = with_input_delays(core, delays)
        return self._remember(recording, started)

    def _with_estimated_initial_states(self, core: StateSpace, segments: list[tuple[np.ndarray, np.ndarray]],
                                       ts: float, levels: bool) -> tuple[StateSpace, list[tuple[np.ndarray, np.ndarray]]]:
        """Each trial's initial state, and with ``levels`` the output levels, as parameters with the model:
        the simulation error is minimised over the model and over (levels, initial states) in turn, each
        round from the last. Given the model, the levels and states are one linear least-squares problem (a constant and
        the free responses C Aᵗ); given them, the model is identified on the outputs less the levels and
        the free responses. (The level alone would be confounded with the transient of a record that does
        not start at rest.) It stops when the simulation error falls by less than 1e-6 of itself, or after
        ``_LEVEL_ROUNDS`` rounds; ``level_rounds_`` counts them. For an output-error model every round
        lowers the same criterion."""
        deviations = [y for _, y in segments]
        ny = deviations[0].shape[1]
        nl = ny if levels else 0  # level unknowns
        previous = np.inf
        level = np.zeros(ny)
        for rounds in range(1, _LEVEL_ROUNDS + 1):
            simulated = [simulate(core, u) for u, _ in segments]
            n = core.n_states
            rows, targets = [], []
            for k, ((u, y), sim) in enumerate(zip(segments, simulated, strict=True)):
                N = len(u)
                block = np.zeros((N, ny, nl + n * len(segments)))
                block[:, :, :nl] = np.eye(ny)[:, :nl]
                block[:, :, nl + k * n:nl + (k + 1) * n] = free_response(core.A, core.C, N)
                rows.append(block.reshape(N * ny, -1))
                targets.append((deviations[k] - sim).ravel())
            solution = np.linalg.lstsq(np.vstack(rows), np.concatenate(targets), rcond=None)[0]
            level = solution[:nl] if levels else np.zeros(ny)
            states = solution[nl:].reshape(len(segments), n)
            corrected = [y - level - free_response(core.A, core.C, len(y)) @ x0
                         for y, x0 in zip(deviations, states, strict=True)]
            cost = sum(float(np.sum((c - sim) ** 2)) for c, sim in zip(corrected, simulated, strict=True))
            segments = [(u, c) for (u, _), c in zip(segments, corrected, strict=True)]
            if previous - cost <= 1e-6 * cost:
                break
            previous = cost
            core = self._fit_delay_free(segments, ts)
        self.trend_ = replace(self.trend_, output_offset=self.trend_.output_offset + level)
        self.level_rounds_ = rounds
        return core, segments

    def _prepared(self, recording: Recording) -> tuple[list[tuple[np.ndarray, np.ndarray]], tuple[int, ...] | None]:
        """Checks the recording (before any long work) and takes out its trend (kept as ``trend_``): the
        trials to identify on, and the declared input delays (None: to be estimated)."""
        self._check_params()
        self._check_common_params()
        recording.require_excitation()
        delays = None if self.delay == ESTIMATE else resolve(self.delay, recording.n_inputs)
        needed = 2 * self._parameters_per_output(recording.n_inputs, recording.n_outputs) + max(delays or (0,))
        if recording.n_samples < needed:
            raise IdentificationError(f"{recording.source}: {recording.n_samples} samples, too few samples for order "
                                      f"{self._order_text()}: it needs at least {needed} (twice the parameters of one "
                                      "output's model, plus the longest delay)")
        self.trend_ = estimate_trend(recording, self.detrend)
        working = self.trend_.remove(recording)
        if self.detrend == "none":
            _require_levels_within_reach(working)
        return working.segments, delays

    def _searched_delays(self, segments: list[tuple[np.ndarray, np.ndarray]], ts: float) -> tuple[int, ...]:
        """Input delays by ARX loss over 0..max_delay (:func:`~softtip.sysid.delays.estimate_delays`), then
        settled by this model's own simulation fit: each input's delay within ±``_DELAY_NEIGHBOURS`` of the
        ARX choice, the others held, scored by the summed variance-normalised simulation error.
        ``delay_search_`` keeps every (delays, cost) tried."""
        delays = list(estimate_delays(segments, self.max_delay, strictly_proper=self._strictly_proper()))
        spread = np.var(np.vstack([y for _, y in segments]), axis=0)
        tried: dict[tuple[int, ...], float] = {}

        def cost(candidate: tuple[int, ...]) -> float:
            if candidate not in tried:
                shifted = [(shift_inputs(u, candidate), y) for u, y in segments]
                try:
                    with single_threaded_blas(), np.errstate(over="ignore", invalid="ignore"):
                        core = self._fit_delay_free(shifted, ts)
                        errors = np.vstack([y - simulate(core, u) for u, y in shifted])
                    value = float(np.sum(np.mean(errors**2, axis=0) / spread))
                except IdentificationError:  # a candidate that cannot be fitted is no candidate
                    value = np.inf
                tried[candidate] = value if np.isfinite(value) else np.inf
            return tried[candidate]

        for j in range(len(delays)):
            around = range(max(delays[j] - _DELAY_NEIGHBOURS, 0), min(delays[j] + _DELAY_NEIGHBOURS, self.max_delay) + 1)
            delays[j] = min(around, key=lambda c: cost(tuple(delays[:j] + [c] + delays[j + 1:])))
        self.delay_search_ = [{"delays": list(key), "cost": value} for key, value in sorted(tried.items())]
        return tuple(delays)

    def _remember(self, recording: Recording, started: float) -> list[np.ndarray]:
        """Keeps what the fit was made on and how well it simulates it; returns that simulation."""
        self.ts_ = recording.ts
        self.inputs_, self.outputs_ = recording.inputs, recording.outputs
        self.input_units_, self.output_units_ = recording.input_units, recording.output_units
        self.data_ = recording.describe() | {"trend": self.trend_.kind}
        with np.errstate(over="ignore", invalid="ignore"):
            simulated = self.simulate(recording)
        measured = np.vstack([trial.y for trial in recording.trials])
        self.simulation_diverges_ = runs_away(np.vstack(simulated), measured)
        self.fit_percent_ = fit_percent(measured, np.vstack(simulated))
        self.fit_seconds_ = time.perf_counter() - started
        return simulated

    def is_stable(self) -> bool:
        """Whether the discrete system is stable: its poles inside the unit circle and its simulation of the
        fit data not running away (a model whose simulation runs away is not stable, whatever its poles)."""
        self._check_fitted()
        return self.system_.is_stable() and not self.simulation_diverges_

    def _checked_covariance(self):
        """The parameter covariance, or a refusal saying why there is none."""
        self._check_fitted()
        if self.covariance_ is None:
            raise IdentificationError(f"this model's parameter covariance was {self.covariance_note_ or 'not saved'}")
        return self.covariance_

    def _uncertainty_summary(self, confidence: float) -> dict:
        """The summary's ``confidence`` intervals (None without a covariance) and why there are none, and the
        stability they leave: "stable", "unstable" or "uncertain" (a pole's interval reaching the boundary),
        with the warnings that say so."""
        uncertainty = None if self.covariance_ is None else self.uncertainty(confidence)
        verdict, warnings = stability(self.is_stable(), uncertainty)
        return {"uncertainty": uncertainty, "uncertainty_note": self.covariance_note_, "stability": verdict,
                "warnings": warnings}

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
        """The simulated outputs from rest, in the recording's units: of every trial of a recording (a list of
        (N, ny)), or of an input array u (N, nu) whose first sample is at time 0 of the trend (``predict`` with
        ``k`` None simulates from each trial's estimated initial state)."""
        self._check_fitted()
        if isinstance(data, Recording):
            return self._run(data, lambda trial: simulate(self.system_, trial.u))
        u = np.asarray(data, dtype=np.float64)
        t = np.arange(len(u)) * self.ts_
        return simulate(self.system_, u - self.trend_.inputs_at(t)) + self.trend_.outputs_at(t)

    def _run(self, recording: Recording, run) -> list[np.ndarray]:
        """``run(trial)`` on every trial of ``recording`` taken about the model's trend, back in its units."""
        self._check_recording(recording)
        deviations = self.trend_.remove(recording)
        return self.trend_.restore(recording, [run(trial) for trial in deviations.trials])

    def predict(self, recording: Recording, k: int | None = 1, initial_state: str = "zero") -> list[np.ndarray]:
        """k-step-ahead predictions of every trial (``k`` None: simulation), from the zero or the estimated
        initial state; see :func:`softtip.sysid.simulation.predict`."""
        self._check_outputs(recording)
        if initial_state not in INITIAL_STATES:
            raise IdentificationError(f"initial_state: expected one of {', '.join(INITIAL_STATES)}, "
                                      f"got {initial_state!r}")
        estimated = initial_state == "estimate"

        def run(trial):
            x0 = estimate_initial_state(self.system_, trial.u, trial.y) if estimated else None
            if k is None:
                return simulate(self.system_, trial.u, x0)
            return predict(self.system_, trial.u, trial.y, k, x0)

        return self._run(recording, run)

    def evaluate(self, recording: Recording, k: int | None = None, full_scale: FullScale = MEASURED,
                 initial_state: str = "zero") -> Scores:
        """Every metric per output on the scored samples of ``recording``, simulated (``k`` None) or
        predicted ``k`` steps ahead, from the zero or the estimated initial state (the scores say which)."""
        scores = self.evaluate_predictions(recording, self.predict(recording, k, initial_state), full_scale)
        return replace(scores, initial_state="estimated" if initial_state == "estimate" else "zero")

    def evaluate_predictions(self, recording: Recording, predicted: list[np.ndarray],
                             full_scale: FullScale = MEASURED) -> Scores:
        """Every metric per output of the model's outputs ``predicted`` for ``recording`` (one array per
        trial: its simulation or predictions) on the scored samples of ``recording``."""
        self._check_outputs(recording)
        masks = [np.ones(len(trial), bool) if trial.scored is None else trial.scored for trial in recording.trials]
        y = np.vstack([trial.y[mask] for trial, mask in zip(recording.trials, masks, strict=True)])
        yhat = np.vstack([values[mask] for values, mask in zip(predicted, masks, strict=True)])
        return score_outputs(y, yhat, self.outputs_, self.output_units_, full_scale)

    def compare(self, recording: Recording, initial_state: str = "estimate") -> Figure:
        """The measured outputs of ``recording`` against the model's simulation from each trial's estimated
        (or the zero) initial state, one axis per output with its fit % (MATLAB's ``compare``)."""
        simulated = self.predict(recording, None, initial_state)
        fits = self.evaluate_predictions(recording, simulated).values["fit_percent"]
        return compare_figure([trial.y for trial in recording.trials], simulated, self.ts_, self.outputs_,
                              self.output_units_, fits, recording.source,
                              "estimated" if initial_state == "estimate" else "zero")

    def time_response(self, kind: str = "step", steps: int | None = None, confidence: float = 0.95) -> TimeResponse:
        """Each input's ``kind`` response ("step" or "impulse", see :mod:`softtip.sysid.responses`) over
        ``steps`` samples (default: five time constants of the slowest pole, input delays added), with
        its standard deviation where the parameter covariance was estimated."""
        self._check_fitted()
        z = normal_quantile(confidence)
        if steps is None:
            steps = response_length(self.system_) + max(self.delays_)
        steps = checked(PositiveInteger, "steps", steps, IdentificationError)
        response = time_responses(self.system_, steps, kind)
        std = None if self.covariance_ is None else np.sqrt(self._response_variance(steps, kind))
        return TimeResponse(kind, np.arange(steps) * self.ts_, response, std, z, confidence)

    def response_figure(self, kind: str = "step", confidence: float = 0.95) -> Figure:
        """:meth:`time_response` plotted, entry by entry, with its ``confidence`` band."""
        return response_figure(self.time_response(kind, confidence=confidence), (self.inputs_, self.outputs_),
                               (self.input_units_, self.output_units_))

    def score(self, recording: Recording, k: int | None = None) -> float:
        """The mean over outputs of R² (scikit-learn's ``score``), simulated unless ``k`` is given."""
        return self.evaluate(recording, k).mean("r2")

    def streaming(self, levels: bool = False) -> StreamingSimulator:
        """The model as a frame-by-frame simulator from the zero state. By default it takes and gives deviations
        from the trend's levels: what the live pipeline feeds it (each frame's change since the baseline it
        tares) and expects back. ``levels``: it takes and gives values in the recording's own units, the
        trend's levels taken out and put back (its clock starting at the first frame)."""
        self._check_fitted()
        return StreamingSimulator(self.system_, trend=self.trend_ if levels else None)

    def residuals(self, recording: Recording) -> np.ndarray:
        """One-step prediction errors of every trial, stacked (N, ny)."""
        return _errors(recording, self.predict(recording, 1))

    def residual_tests(self, recording: Recording, *, lags: int = 25, confidence: float = 0.99,
                       initial_state: str = "zero") -> ResidualTests:
        """Whiteness of the one-step prediction errors and their independence of the inputs on ``recording``
        (:mod:`softtip.sysid.residuals`), from the zero or the estimated initial state."""
        predicted = self.predict(recording, 1, initial_state)
        return residual_tests([trial.y - values for trial, values in zip(recording.trials, predicted, strict=True)],
                              [trial.u for trial in recording.trials], lags=lags, confidence=confidence,
                              output_names=self.outputs_, input_names=self.inputs_)

    def bode(self, omega: np.ndarray | None = None, *, confidence: float = 0.95,
             recording: Recording | None = None) -> Figure:
        """The Bode plot of every entry with its ``confidence`` band (input delays in the phase) on ``omega``
        (rad/s; default three decades below Nyquist); with ``recording``, the empirical transfer-function
        estimate of its longest trial (about the model's trend; one of 128 samples at least) beside it."""
        self._check_fitted()
        if omega is None:
            nyquist = np.pi / self.ts_
            omega = np.logspace(np.log10(nyquist) - 3, np.log10(nyquist), 400)
        omega = np.asarray(omega, dtype=np.float64)
        measured = None
        if recording is not None:
            self._check_outputs(recording)
            trial = max(self.trend_.remove(recording).trials, key=len)
            if len(trial) >= _ETFE_SAMPLES:
                measured = empirical_transfer_function(trial.u, trial.y, self.ts_)
        response, delays_s, band = self._bode_curves(omega, confidence)
        return bode_figure(response, omega, band=band, confidence=confidence, delays_s=delays_s, measured=measured,
                           names=(list(self.inputs_), list(self.outputs_)),
                           units=(self.input_units_, self.output_units_))

    def _bode_curves(self, omega: np.ndarray, confidence: float):
        """(response (len(ω), ny, nu), delays not in it (s), band per entry or None) for :meth:`bode`: the
        discrete system's response, its delays included, without a band (no parameter covariance)."""
        return self.system_.frequency_response(omega), np.zeros(len(self.inputs_)), None

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
                 "fit_seconds": self.fit_seconds_, "trend": self.trend_.to_dict(), "delays": list(self.delays_),
                 "simulation_diverges": self.simulation_diverges_, "covariance_note": self.covariance_note_}
        return state, arrays

    def _restore_common(self, state: dict, arrays: dict[str, np.ndarray]) -> None:
        self.ts_ = float(state["ts"])
        self.inputs_, self.outputs_ = tuple(state["inputs"]), tuple(state["outputs"])
        self.input_units_, self.output_units_ = tuple(state["input_units"]), tuple(state["output_units"])
        self.data_ = state["data"]
        self.fit_percent_ = np.asarray(state["fit_percent"], dtype=np.float64)
        self.fit_seconds_ = float(state["fit_seconds"])
        self.simulation_diverges_ = bool(state.get("simulation_diverges", False))
        self.covariance_note_ = state.get("covariance_note")
        self.delay_search_ = self.level_rounds_ = None  # not saved
        self.system_ = StateSpace(arrays["system/A"], arrays["system/B"], arrays["system/C"], arrays["system/D"],
                                  self.ts_, arrays.get("system/K"), arrays.get("system/noise_covariance"))
        sizes = (self.system_.n_inputs, self.system_.n_outputs, len(self.fit_percent_))
        if sizes != (len(self.inputs_), len(self.outputs_), len(self.outputs_)) or \
                len(self.input_units_) != len(self.inputs_) or len(self.output_units_) != len(self.outputs_):
            raise IdentificationError(f"{len(self.inputs_)} inputs and {len(self.outputs_)} outputs named, the "
                                      f"system has {sizes[0]} and {sizes[1]}")
        self.trend_ = Trend.from_dict(state["trend"]) if "trend" in state else \
            Trend.zero(len(self.inputs_), len(self.outputs_))
        self.delays_ = resolve(state.get("delays", 0), len(self.inputs_))
        if self.trend_.input_offset.shape != (len(self.inputs_),) or \
                self.trend_.output_offset.shape != (len(self.outputs_),):
            raise IdentificationError("the trend has not one level per input and output")

    def _summary(self, kind: str) -> dict:
        self._check_fitted()
        return {"kind": kind, "params": self.get_params(), "ts": self.ts_, "inputs": list(self.inputs_),
                "outputs": list(self.outputs_), "input_units": list(self.input_units_),
                "output_units": list(self.output_units_), "states": self.system_.n_states,
                "parameters": self.n_parameters, "discrete_poles": _poles(self.system_.poles()),
                "stable": self.is_stable(),
                "simulation_diverges": self.simulation_diverges_,
                "trend": self.trend_.to_dict() | {"estimation_rounds": self.level_rounds_},
                "delays": {name: {"samples": d, "seconds": d * self.ts_}
                           for name, d in zip(self.inputs_, self.delays_, strict=True)},
                "fit_percent": {name: float(v) for name, v in zip(self.outputs_, self.fit_percent_, strict=True)},
                "delay_search": self.delay_search_,
                "fit_percent_initial_state": "zero",
                "fit_seconds": self.fit_seconds_, "data": self.data_}


class StateSpaceModel(IdentifiedModel):
    """x[t+1] = A x + B u + K e, y = C x + D u + e identified by subspace methods (MATLAB's ``n4sid``;
    with ``refine``, its prediction-error refinement as in ``ssest``).

    ``order``: the number of states, or ``"auto"`` (the largest drop in the singular values, up to
    ``max_order``; see :mod:`softtip.sysid.subspace`); ``method``: ``"n4sid"``, ``"moesp"`` or
    ``"cva"``; ``horizon``: past/future block rows (default from the order); ``domain``:
    ``"continuous"`` also gives ``continuous_``, the system whose zero-order hold is ``system_``;
    ``max_iterations`` and ``tolerance``: the refinement's stopping rules (:mod:`softtip.sysid.refine`).
    ``detrend``: "none", "mean" or "linear", the levels taken out before identification and kept
    (:mod:`softtip.sysid.trends`), or "estimate" (the output levels and each trial's initial state
    estimated with the model); ``delay``: input delays in samples, one for all inputs or one per
    input, or "estimate" (searched up to ``max_delay``; :mod:`softtip.sysid.delays`);
    ``estimate_covariance``: False skips the parameter covariance (``covariance_`` None, no intervals
    or bands), for fits that never read it; ``initial_state``: "zero" (every trial starts at rest) or
    "estimate" (each trial's initial state estimated with the model, for records that do not start at
    rest; "estimate" detrending estimates them too).
    """

    _PARAMETERS = {"order": ORDER, "method": choice(*METHODS), "domain": choice(*DOMAINS), "refine": Flag,
                   "enforce_stability": Flag, "horizon": Optional[integer(2)], "max_order": PositiveInteger,
                   "max_iterations": PositiveInteger, "tolerance": OpenFraction, "estimate_covariance": Flag}

    def __init__(self, order: int | str = AUTO, method: str = "moesp", *, refine: bool = False,
                 domain: str = "discrete", horizon: int | None = None, max_order: int = MAX_ORDER,
                 enforce_stability: bool = True, max_iterations: int = 20, tolerance: float = 1e-4,
                 detrend: str = "none", delay: int | list[int] | str = 0, max_delay: int = 40,
                 estimate_covariance: bool = True, initial_state: str = "zero"):
        self.order = order
        self.method = method
        self.refine = refine
        self.domain = domain
        self.horizon = horizon
        self.max_order = max_order
        self.enforce_stability = enforce_stability
        self.max_iterations = max_iterations
        self.tolerance = tolerance
        self.detrend = detrend
        self.delay = delay
        self.max_delay = max_delay
        self.estimate_covariance = estimate_covariance
        self.initial_state = initial_state

    def _parameters_per_output(self, n_inputs: int, n_outputs: int) -> int:
        n = 1 if self.order == AUTO else self.order
        return n * (n_inputs + 2 * n_outputs) // n_outputs + n_inputs

    def _strictly_proper(self) -> bool:
        return False  # its D takes a delayed input's first sample

    def _order_text(self) -> str:
        return str(self.order)

    def _fit_delay_free(self, segments: list[tuple[np.ndarray, np.ndarray]], ts: float) -> StateSpace:
        found = subspace_identify(segments, ts, self.order, self.method, horizon=self.horizon,
                                  max_order=self.max_order, enforce_stability=self.enforce_stability)
        system, report = found.system, None
        if self.refine:
            system, report = refine(system, segments, max_iterations=self.max_iterations, tolerance=self.tolerance)
        self.continuous_ = system.to_continuous() if self.domain == "continuous" else None
        self.order_, self.horizon_ = found.order, found.horizon
        self.singular_values_ = found.singular_values
        self.reflected_poles_, self.kalman_ = found.reflected_poles, found.kalman
        self.refinement_: RefinementReport | None = report
        return system

    def _estimate_uncertainty(self, core: StateSpace, segments: list[tuple[np.ndarray, np.ndarray]],
                              ts: float) -> None:
        n, nu, ny = core.n_states, core.n_inputs, core.n_outputs
        # the predictor's sensitivities, held for every sample at once: N ny n (n + nu + ny) numbers
        size = sum(len(u) for u, _ in segments) * ny * n * (n + nu + ny)
        self.covariance_note_ = None
        if size > _COVARIANCE_BUDGET:
            self.covariance_ = None
            self.covariance_note_ = (f"not computed: its Jacobian would hold {size:.3g} numbers "
                                     f"({8 * size / 1e9:.2g} GB; the limit is {_COVARIANCE_BUDGET:.0e}); "
                                     "identify on fewer samples for intervals")
        else:
            self.covariance_ = parameter_covariance(core, segments)

    def uncertainty(self, confidence: float = 0.95) -> dict:
        """Every pole (continuous with ``domain="continuous"``) and DC gain with its standard deviation and
        ``confidence`` interval (:func:`softtip.sysid.uncertainty.state_space_intervals`)."""
        return state_space_intervals(without_input_delays(self.system_, self.delays_), self._checked_covariance(),
                                     confidence, continuous=self.domain == "continuous")

    def _response_variance(self, steps: int, kind: str) -> np.ndarray:
        core = without_input_delays(self.system_, self.delays_)
        dA, dB, dC, dD = self.covariance_.derivatives

        def perturbed(k: int, h: float) -> StateSpace:
            return with_input_delays(StateSpace(core.A + h * dA[k], core.B + h * dB[k], core.C + h * dC[k],
                                                core.D + h * dD[k], core.ts), self.delays_)

        # local coordinates: unit-sized directions
        return response_spread(perturbed, np.zeros(len(dA)), self.covariance_.covariance, steps, kind)

    def _bode_curves(self, omega: np.ndarray, confidence: float):
        core = without_input_delays(self.system_, self.delays_)
        band = None if self.covariance_ is None else state_space_bands(core, self.covariance_, omega, confidence)
        return core.frequency_response(omega), np.array(self.delays_) * self.ts_, band

    @property
    def n_parameters(self) -> int:
        """Free parameters of (A, B, C, D, K) up to a change of state basis: n (nu + 2 ny) + ny nu."""
        n, nu, ny = self.order_, self.system_.n_inputs, self.system_.n_outputs
        return n * (nu + 2 * ny) + ny * nu

    def _export(self) -> tuple[dict, dict[str, np.ndarray]]:
        state, arrays = super()._export()
        arrays["singular_values"] = self.singular_values_
        if self.covariance_ is not None:
            arrays["ss/covariance"] = self.covariance_.covariance
            for name, derivative in zip("ABCD", self.covariance_.derivatives, strict=True):
                arrays[f"ss/derivatives/{name}"] = derivative
        state |= {"order": self.order_, "horizon": self.horizon_, "reflected_poles": self.reflected_poles_,
                  "kalman": self.kalman_, "refinement": None if self.refinement_ is None else self.refinement_.to_dict()}
        return state, arrays

    def _restore(self, state: dict, arrays: dict[str, np.ndarray]) -> None:
        self._restore_common(state, arrays)
        if self.system_.K is None:
            raise IdentificationError("a state-space model needs its Kalman gain K")
        self.order_, self.horizon_ = int(state["order"]), int(state["horizon"])
        self.singular_values_ = np.asarray(arrays["singular_values"], dtype=np.float64)
        self.covariance_ = None
        if "ss/covariance" in arrays:
            self.covariance_ = StateSpaceCovariance(arrays["ss/covariance"],
                                                    tuple(arrays[f"ss/derivatives/{name}"] for name in "ABCD"))
            core = without_input_delays(self.system_, self.delays_)
            shapes = tuple(np.shape(d)[1:] for d in self.covariance_.derivatives)
            if shapes != tuple(np.shape(getattr(core, name)) for name in "ABCD") or \
                    {len(d) for d in self.covariance_.derivatives} != {len(self.covariance_.covariance)}:
                raise IdentificationError("the saved parameter covariance does not fit the system")
        self.reflected_poles_, self.kalman_ = int(state["reflected_poles"]), str(state["kalman"])
        self.refinement_ = None if state["refinement"] is None else RefinementReport(**state["refinement"])
        if self.order_ + sum(self.delays_) != self.system_.n_states:
            raise IdentificationError(f"order {self.order_} and {sum(self.delays_)} delay states, but A has "
                                      f"{self.system_.n_states} states")
        self.continuous_ = without_input_delays(self.system_, self.delays_).to_continuous() \
            if self.domain == "continuous" else None

    def summary(self, confidence: float = 0.95) -> dict:
        """What was identified, with ``confidence`` intervals where the covariance was estimated."""
        summary = self._summary("state space") | {
            "method": self.method, "order": self.order_, "horizon": self.horizon_, "domain": self.domain,
            "singular_values": [float(v) for v in self.singular_values_[:2 * MAX_ORDER]],
            "reflected_poles": self.reflected_poles_, "kalman": self.kalman_,
            "refinement": None if self.refinement_ is None else self.refinement_.to_dict(),
            **self._uncertainty_summary(confidence)}
        if self.continuous_ is not None:
            summary["continuous_poles"] = _poles(self.continuous_.poles())
        return summary


class TransferFunctionModel(IdentifiedModel):
    """Y(s) = G(s) U(s), G an ny x nu matrix of continuous transfer functions, every entry with
    ``n_poles`` poles and ``n_zeros`` zeros (default ``n_poles - 1``); MATLAB's ``tfest``.

    ``tf_`` is G; ``system_`` its block-diagonal canonical realisation discretised by zero-order
    hold at the recording's sample time (:mod:`softtip.sysid.realisation`), which runs it, behind
    the input delays ``delays_`` (e^{-s d ts}: ``delay`` declared, or "estimate"). ``detrend``,
    ``estimate_covariance`` and ``initial_state`` as for :class:`StateSpaceModel`; ``intervals``: the
    coefficients' covariance, "sandwich" (honest for coloured output errors, which an output-error
    model's usually are; :mod:`softtip.sysid.robust`) or "white" (σ² (JᵀJ)⁻¹, white errors assumed).
    """

    _PARAMETERS = {"n_poles": PositiveInteger, "refine": Flag, "enforce_stability": Flag,
                   "intervals": choice(*COVARIANCES),
                   "max_iterations": PositiveInteger, "estimate_covariance": Flag}

    def __init__(self, n_poles: int = 6, n_zeros: int | None = None, *, refine: bool = True,
                 enforce_stability: bool = True, max_iterations: int = 100, detrend: str = "none",
                 delay: int | list[int] | str = 0, max_delay: int = 40, estimate_covariance: bool = True,
                 initial_state: str = "zero", intervals: str = SANDWICH):
        self.n_poles = n_poles
        self.n_zeros = n_zeros
        self.refine = refine
        self.enforce_stability = enforce_stability
        self.max_iterations = max_iterations
        self.detrend = detrend
        self.delay = delay
        self.max_delay = max_delay
        self.estimate_covariance = estimate_covariance
        self.initial_state = initial_state
        self.intervals = intervals

    def _parameters_per_output(self, n_inputs: int, n_outputs: int) -> int:
        zeros = self.n_poles - 1 if self.n_zeros is None else self.n_zeros
        return n_inputs * (self.n_poles + zeros + 1)

    def _strictly_proper(self) -> bool:
        return self.n_zeros is None or self.n_zeros < self.n_poles

    def _order_text(self) -> str:
        return f"{self.n_poles} (poles per entry)"

    def _check_params(self) -> None:
        super()._check_params()
        if self.n_zeros is not None:
            checked(integer(0, self.n_poles, f"an integer 0..n_poles ({self.n_poles})"), "n_zeros", self.n_zeros,
                    IdentificationError)

    def _fit_delay_free(self, segments: list[tuple[np.ndarray, np.ndarray]], ts: float) -> StateSpace:
        tf, report = transfer.fit(segments, ts, self.n_poles, self.n_zeros, refine=self.refine,
                                  max_iterations=self.max_iterations, enforce_stability=self.enforce_stability)
        self.tf_, self.report_ = tf, report
        self.continuous_ = realise(tf.numerators, tf.denominators)
        return self.continuous_.to_discrete(ts)

    def _estimate_uncertainty(self, core: StateSpace, segments: list[tuple[np.ndarray, np.ndarray]],
                              ts: float) -> None:
        self.covariance_, self.covariance_lags_, self.covariance_prewhitened_ = transfer.parameter_covariance(
            self.tf_, segments, ts, self.intervals)
        self.covariance_note_ = None

    def uncertainty(self, confidence: float = 0.95) -> dict:
        """Every coefficient, pole and zero with its standard deviation and ``confidence`` interval
        (:func:`softtip.sysid.uncertainty.intervals`)."""
        covariance = self._checked_covariance()
        # from the lags the covariance was made with (a file written before sandwich estimates has none)
        if None in self.covariance_lags_:
            method, assumption = WHITE, WHITE_ASSUMPTION
        else:
            method = SANDWICH
            assumption = sandwich_assumption(", ".join(str(lag) for lag in self.covariance_lags_),
                                             ", ".join("yes" if done else "no" for done in self.covariance_prewhitened_))
        return intervals(self.tf_, covariance, confidence) | {"method": method, "assumption": assumption}

    def _response_variance(self, steps: int, kind: str) -> np.ndarray:
        """Each output's coefficients move its row only: the rows' variances, summed."""
        variance = np.zeros((steps, len(self.outputs_), len(self.inputs_)))
        for i, covariance in enumerate(self.covariance_):
            # the row's coefficients in the covariance's order: each entry's denominator after its 1, numerator
            entries = [(a, b) for a, b in zip(self.tf_.denominators[i], self.tf_.numerators[i], strict=True)]
            theta = np.concatenate([np.concatenate([a[1:], b]) for a, b in entries])
            cuts = np.cumsum([0] + [len(a) - 1 + len(b) for a, b in entries])

            def perturbed(k: int, h: float, i: int = i, theta: np.ndarray = theta, cuts: np.ndarray = cuts):
                moved = theta.copy()
                moved[k] += h
                numerators = [list(row) for row in self.tf_.numerators]
                denominators = [list(row) for row in self.tf_.denominators]
                for j, (a, _) in enumerate(entries):
                    part = moved[cuts[j]:cuts[j + 1]]
                    denominators[i][j] = np.r_[1.0, part[:len(a) - 1]]
                    numerators[i][j] = part[len(a) - 1:]
                return with_input_delays(realise(numerators, denominators).to_discrete(self.ts_), self.delays_)

            variance += response_spread(perturbed, theta, covariance, steps, kind)
        return variance

    def _bode_curves(self, omega: np.ndarray, confidence: float):
        band = None if self.covariance_ is None else \
            (lambda i, j: frequency_band(self.tf_, self.covariance_, omega, i, j, confidence))
        return self.tf_.frequency_response(omega), np.array(self.delays_) * self.ts_, band

    def _set_transfer_function(self, tf: transfer.TransferFunctionMatrix, ts: float) -> None:
        self.tf_ = tf
        self.continuous_ = realise(tf.numerators, tf.denominators)
        self.system_ = with_input_delays(self.continuous_.to_discrete(ts), self.delays_)

    def _export(self) -> tuple[dict, dict[str, np.ndarray]]:
        state, arrays = super()._export()
        for role in ("numerators", "denominators"):
            for i, row in enumerate(getattr(self.tf_, role)):
                for j, coefficients in enumerate(row):
                    arrays[f"tf/{role}/{i}/{j}"] = coefficients
        for i, covariance in enumerate(self.covariance_ or ()):
            arrays[f"tf/covariance/{i}"] = covariance
        state["report"] = self.report_.to_dict()
        state["covariance_lags"] = None if self.covariance_ is None else list(self.covariance_lags_)
        state["covariance_prewhitened"] = None if self.covariance_ is None else list(self.covariance_prewhitened_)
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
        self.covariance_ = None
        if "tf/covariance/0" in arrays:
            self.covariance_ = [arrays[f"tf/covariance/{i}"] for i in range(ny)]
            self.covariance_lags_ = list(state.get("covariance_lags") or [None] * ny)
            # a file written before prewhitening has none
            self.covariance_prewhitened_ = [bool(done) for done in state.get("covariance_prewhitened") or [False] * ny]
            intervals(self.tf_, self.covariance_)  # checks their shapes

    @property
    def n_parameters(self) -> int:
        """Coefficients of every entry: n_poles (monic denominator) + n_zeros + 1."""
        return int(np.sum(self.tf_.n_poles + self.tf_.n_zeros + 1))

    def summary(self, confidence: float = 0.95) -> dict:
        """What was identified, with ``confidence`` intervals where the covariance was estimated."""
        return self._summary("transfer function") | {
            "n_poles": self.tf_.n_poles.tolist(), "n_zeros": self.tf_.n_zeros.tolist(),
            "continuous_stable": self.tf_.is_stable(),
            "numerators": [[b.tolist() for b in row] for row in self.tf_.numerators],
            "denominators": [[a.tolist() for a in row] for row in self.tf_.denominators],
            **self._uncertainty_summary(confidence),
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
                validation: Recording | None = None, scored_from: str = "zero", **params) -> list[dict]:
    """One fit per order (``kind`` "tf": poles per entry, default 2-8; "ss": states, default 2-12),
    each row with the order, the parameter count, the fit % per output and its mean (on ``validation``
    when given, else on the estimation data; simulated from the zero or the estimated initial state,
    ``scored_from``, as the row says), AIC and BIC (one-step prediction errors on the estimation data; the simulation errors
    of a transfer function, which has no noise model), whether it is stable, and the seconds the fit took."""
    if kind not in KINDS:
        raise IdentificationError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    if scored_from not in INITIAL_STATES:
        raise IdentificationError(f"scored_from: expected one of {', '.join(INITIAL_STATES)}, got {scored_from!r}")
    orders = list(DEFAULT_ORDERS[kind] if orders is None else orders)
    if not orders:
        raise IdentificationError("orders: none given")
    if len(set(orders)) < len(orders):
        raise IdentificationError(f"orders: {', '.join(map(str, orders))} repeats an order")
    # the largest order's data check before any fit: a refusal at once, not after fitting every order below it
    # no row reads a parameter covariance: none is computed
    settings = params | {"estimate_covariance": False}
    KINDS[kind](max(orders), **settings)._prepared(recording)  # the first parameter is the order of either kind
    rows = []
    for order in orders:
        model = KINDS[kind](order, **settings)
        started = time.perf_counter()
        simulated = model._identify(recording)
        seconds = time.perf_counter() - started
        # the fit's simulation of the estimation data scores it there, and is the one-step prediction of a
        # model without a noise model
        if validation is None and scored_from == "zero":
            scores = model.evaluate_predictions(recording, simulated)
        else:
            scores = model.evaluate(recording if validation is None else validation, initial_state=scored_from)
        one_step = simulated if model.system_.K is None else model.predict(recording, 1)
        aic, bic = information_criteria(_errors(recording, one_step), model.n_parameters)
        fits = scores.values["fit_percent"]
        rows.append({"order": order, "parameters": model.n_parameters, "fit_percent": float(np.mean(fits)),
                     "fit_percent_per_output": {name: float(v) for name, v in zip(model.outputs_, fits, strict=True)},
                     "initial_state": scores.initial_state, "aic": aic, "bic": bic,
                     "stable": model.is_stable(), "seconds": seconds})
    return rows


# a validation fit within this many points of the best is a tie, which the smaller model wins
_ORDER_TIE = 0.5


def validated_order(recording: Recording, validation: Recording, kind: str, orders: Iterable[int] | None = None,
                    **params) -> tuple[int, list[dict]]:
    """The order chosen by validation: every order of :func:`order_table` fitted on ``recording`` and
    scored on ``validation`` from each trial's estimated initial state; the stable one of the best mean
    fit, a smaller one within ``_ORDER_TIE`` points of it preferred. Returns it and the table's rows."""
    rows = order_table(recording, kind, orders, validation, "estimate", **params)
    stable = [row for row in rows if row["stable"]]
    if not stable:
        raise IdentificationError(f"{validation.source}: no order of {', '.join(str(row['order']) for row in rows)} "
                                  "gives a stable model to validate")
    best = max(row["fit_percent"] for row in stable)
    return min(row["order"] for row in stable if row["fit_percent"] >= best - _ORDER_TIE), rows

