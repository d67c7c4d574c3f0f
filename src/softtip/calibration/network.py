"""Feedforward tanh network regression trained by Levenberg–Marquardt (the toolbox's
``feedforwardnet`` + ``trainlm``), and what it shares with the softmax classifier.

Semantics followed:

* inputs and targets are mapped to [-1, 1] per column by mapminmax settings taken from all
  the data passed to ``fit`` (the network is trained on scaled targets, so every output
  weighs the same in the error whatever its unit);
* hidden layers are tanh, initialised by Nguyen–Widrow; the output layer is linear,
  initialised uniformly in [-1, 1];
* the data are divided at random into train/validation/test (``division``, default
  0.70/0.15/0.15); ``fit(..., groups=trial_ids)`` divides whole groups instead (trials, or the
  time blocks of :func:`softtip.calibration.validation.stopping_groups` when trials are few), and
  ``fit(..., validation_data=(X_val, y_val))`` trains on all of X and validates on the given
  set (no test share). The test share is never used for training; its error is recorded;
* each epoch solves (JᵀJ + μI) δ = Jᵀe by Cholesky, J the Jacobian of the outputs, e the
  residuals, and tries μ, 10μ, 100μ, ... until the training error falls (then μ ← μ/10);
* training stops at the first of: mean squared error <= ``goal``, ``max_epochs`` epochs,
  gradient norm ‖Jᵀe‖ <= ``min_grad``, μ >= ``mu_max``, ``max_fail`` validation failures
  (epochs whose validation error is above the lowest so far, counted since that lowest);
  the weights of the lowest validation error are returned. With ``min_progress`` (not the
  toolbox's; None is its rule) validation failures stop training only once it has stopped
  learning too: its training error fell by less than that fraction over the last ``max_fail``
  epochs, so a plateau that the validation error sits out while the training error still falls
  does not end it (:mod:`softtip.calibration.validation` says when this is needed).
* with ``anchored`` (not the toolbox's) the linear output layer is refitted once trained, by least
  squares on the training share, so that a zero input gives exactly a zero output: for inputs and
  targets that are both changes from a baseline (a sensor's readings and the force on it), where an
  untouched sensor must read no force whatever the network learnt about the rest of its range.

Errors in ``history_`` are mean squared errors of the scaled targets.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import scipy.linalg
from pydantic import AfterValidator, BeforeValidator, Field
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils.validation import check_array, check_is_fitted, validate_data

from softtip._core.config import (
    Flag,
    NonNegativeNumber,
    Number,
    OpenFraction,
    PositiveNumber,
    Real,
    Refusal,
    Whole,
    expect,
    integer,
    number,
    parse,
    schema,
)
from softtip._core.network import PREDICT_CHUNK, forward_one, predict_batch
from softtip._core.threads import single_threaded_blas
from softtip.calibration import checks
from softtip.calibration.feedforward import (
    EarlyStopping,
    backprop_gradient,
    divide,
    forward,
    gauss_newton_matrix,
    initial_layers,
    layer_shapes,
    minmax_gain,
    pack,
    runtime_layers,
    stop_reason,
    to_unit_range,
    unpack,
)

HISTORY_KEYS = ("train", "validation", "test")
MU_FLOOR = 1e-20  # the toolbox never lets μ underflow below this


@dataclass(frozen=True)
class TrainingResult:
    layers: list[np.ndarray]
    history: dict[str, np.ndarray]
    stop_reason: str
    best_epoch: int


def _mse(layers, inputs, targets) -> float:
    if not len(inputs):
        return float("nan")
    return float(np.mean((targets - forward(layers, inputs)[-1]) ** 2))


def levenberg_marquardt(layers: list[np.ndarray], train: tuple[np.ndarray, np.ndarray],
                        validation: tuple[np.ndarray, np.ndarray], test: tuple[np.ndarray, np.ndarray], *,
                        max_epochs: int, max_fail: int, mu: float, mu_dec: float, mu_inc: float,
                        mu_max: float, min_grad: float, goal: float,
                        min_progress: float | None = None) -> TrainingResult:
    """Train a tanh network with linear outputs on (inputs, targets) pairs; see the module notes."""
    shapes = [w.shape for w in layers]
    theta = pack(layers)
    inputs, targets = train
    activations = forward(unpack(theta, shapes), inputs)
    errors = targets - activations[-1]
    perf = float(np.mean(errors**2))
    vperf = _mse(layers, *validation)
    stopping = EarlyStopping(theta, vperf)
    history = {key: [] for key in (*HISTORY_KEYS, "mu", "gradient")}
    identity = np.eye(len(theta))
    for epoch in range(max_epochs + 1):
        current = unpack(theta, shapes)
        gradient = backprop_gradient(current, activations, errors)  # Jᵀe
        gradient_norm = float(np.linalg.norm(gradient))
        for key, value in zip(history, (perf, vperf, _mse(current, *test), mu, gradient_norm), strict=True):
            history[key].append(value)
        learning = (min_progress is not None and epoch >= max_fail
                    and history["train"][epoch - max_fail] - perf >= min_progress * perf)
        reason = stop_reason(epoch, perf, gradient_norm, stopping, max_epochs=max_epochs, goal=goal,
                             min_grad=min_grad, max_fail=math.inf if learning else max_fail,
                             limit_reached="mu_max" if mu >= mu_max else "")
        if reason:
            break
        curvature = gauss_newton_matrix(current, activations)
        while mu <= mu_max:
            try:
                factor = scipy.linalg.cho_factor(curvature + mu * identity, check_finite=False)
            except np.linalg.LinAlgError:
                mu *= mu_inc
                continue
            trial = theta + scipy.linalg.cho_solve(factor, gradient, check_finite=False)
            trial_activations = forward(unpack(trial, shapes), inputs)
            trial_errors = targets - trial_activations[-1]
            trial_perf = float(np.mean(trial_errors**2))
            if trial_perf < perf:
                theta, activations, errors, perf = trial, trial_activations, trial_errors, trial_perf
                mu = max(mu * mu_dec, MU_FLOOR)
                break
            mu *= mu_inc
        vperf = _mse(unpack(theta, shapes), *validation)
        stopping.update(epoch + 1, theta, vperf)
    return TrainingResult(unpack(stopping.best_theta, shapes), {k: np.array(v) for k, v in history.items()},
                          reason, stopping.best_epoch)


def anchored_output_layer(layers: list[np.ndarray], inputs: np.ndarray, targets: np.ndarray,
                          anchor_input: np.ndarray, anchor_target: np.ndarray) -> np.ndarray:
    """The linear output layer (augmented, bias last) refitted by least squares on (inputs, targets), the
    hidden layers kept, under the constraint that ``anchor_input`` gives exactly ``anchor_target``: a
    fit of the targets' departures from the anchor's on the hidden activations' departures, without
    an intercept."""
    hidden = forward(layers, inputs)[-2]
    anchor = forward(layers, anchor_input[None])[-2][0]
    weights, *_ = np.linalg.lstsq(hidden - anchor, targets - anchor_target, rcond=None)
    return np.column_stack([weights.T, anchor_target - anchor @ weights])


def _one_or_more(sizes):
    return (sizes,) if isinstance(sizes, numbers.Integral) and not isinstance(sizes, bool) else sizes


def _fractions(fractions: tuple[float, float, float]) -> tuple[float, float, float]:
    if min(fractions) < 0 or fractions[0] <= 0 or abs(sum(fractions) - 1.0) > 1e-9:
        raise ValueError("not a division")
    return fractions


LayerSizes = Annotated[tuple[integer(1), ...], BeforeValidator(_one_or_more), Field(min_length=1),
                       expect("one or more positive integers")]
Division = Annotated[tuple[Real, Real, Real], AfterValidator(_fractions),
                     expect("(train, validation, test) fractions >= 0 summing to 1 with train > 0")]
Growth = number("a number > 1", gt=1)
RandomState = Annotated[None | Whole | np.random.Generator, expect("None, an int or a numpy Generator")]


@schema
class TanhNetworkSettings:
    """The hyper-parameters the tanh networks share, checked at fit time (scikit-learn stores them as given)."""

    hidden_layer_sizes: LayerSizes
    max_epochs: integer(0)
    max_fail: integer(1)
    min_grad: NonNegativeNumber
    goal: NonNegativeNumber
    division: Division
    random_state: RandomState


@schema
class LMSettings(TanhNetworkSettings):
    mu: PositiveNumber
    mu_dec: OpenFraction
    mu_inc: Growth
    mu_max: Number
    min_progress: NonNegativeNumber | None
    anchored: Flag

    def __post_init__(self):
        if not self.mu_max > self.mu:
            raise Refusal("mu_max", f"expected a number > mu = {self.mu}")


class TanhNetworkBase(BaseEstimator):
    """What the tanh networks share: hyper-parameter checks, data division, run-time weights."""

    _SETTINGS: type[TanhNetworkSettings]  # the schema of the estimator's hyper-parameters

    def _settings(self) -> TanhNetworkSettings:
        return parse(self._SETTINGS, self.get_params(), type(self).__name__)

    def _validation_pair(self, validation_data, n_features: int) -> tuple[np.ndarray, object]:
        """Checked inputs and the raw targets of ``validation_data``."""
        try:
            val_inputs, val_targets = validation_data
        except (TypeError, ValueError):
            raise ValueError("validation_data must be a pair (X_val, y_val)") from None
        val_inputs = check_array(val_inputs, dtype=np.float64, input_name="validation_data X")
        if val_inputs.shape[1] != n_features:
            raise ValueError(f"validation_data X has {val_inputs.shape[1]} features, the training data {n_features}")
        if np.shape(val_targets)[:1] != (len(val_inputs),):
            raise ValueError(f"validation_data has {len(val_inputs)} inputs but targets of shape "
                             f"{np.shape(val_targets)}")
        return val_inputs, val_targets

    @staticmethod
    def _divide(inputs: np.ndarray, targets: np.ndarray, groups, validation, fractions,
                rng) -> list[tuple[np.ndarray, np.ndarray]]:
        """(train, validation, test) pairs of (inputs, targets); ``validation`` a pair or None."""
        if validation is not None:
            return [(inputs, targets), validation, (inputs[:0], targets[:0])]
        if groups is not None:
            groups = np.asarray(groups)
            if groups.shape != (len(inputs),):
                raise ValueError(f"groups must be one label per sample ({len(inputs)}), got shape {groups.shape}")
        return [(inputs[i], targets[i]) for i in divide(len(inputs), fractions, rng, groups)]

    def _export(self) -> tuple[dict[str, np.ndarray], dict]:
        """Fitted arrays and JSON-able fitted state, for saving without pickle."""
        check_is_fitted(self, "weights_")
        arrays = {f"weights/{i}": w for i, w in enumerate(self.weights_)}
        arrays |= {"input_min": self.input_min_, "input_max": self.input_max_}
        arrays |= {f"history/{key}": values for key, values in self.history_.items()}
        state = {"n_features_in": int(self.n_features_in_), "stop_reason": self.stop_reason_,
                 "best_epoch": int(self.best_epoch_)}
        return arrays, state

    def _keep_training(self, result: TrainingResult) -> None:
        """Set the fitted attributes shared by the networks from a training run."""
        self.weights_ = [np.array(w) for w in result.layers]
        self.history_ = result.history
        self.stop_reason_ = result.stop_reason
        self.best_epoch_ = result.best_epoch

    def _restore_network(self, arrays: dict[str, np.ndarray], state: dict, n_outputs: int) -> None:
        """Set the fitted attributes shared by the networks from saved arrays, checking shapes."""
        n_inputs = checks.stored_int(state, "n_features_in", 1)
        shapes = layer_shapes([n_inputs, *self._settings().hidden_layer_sizes, n_outputs])
        self.weights_ = [checks.stored_array(arrays, f"weights/{i}", shape) for i, shape in enumerate(shapes)]
        if f"weights/{len(shapes)}" in arrays:
            raise ValueError(f"more weight arrays than the {len(shapes)} layers of hidden_layer_sizes")
        self.input_min_ = checks.stored_array(arrays, "input_min", (n_inputs,))
        self.input_max_ = checks.stored_array(arrays, "input_max", (n_inputs,))
        history = {name.removeprefix("history/"): values for name, values in arrays.items()
                   if name.startswith("history/")}
        lengths = {values.shape for values in history.values()}
        if len(lengths) > 1 or any(len(shape) != 1 for shape in lengths):
            raise ValueError("the history arrays must be 1-D and of one length")
        if not isinstance(state.get("stop_reason"), str):
            raise ValueError("state 'stop_reason' must be a string")
        self.history_ = history
        self.stop_reason_ = state["stop_reason"]
        self.best_epoch_ = checks.stored_int(state, "best_epoch", 0)
        self.n_features_in_ = n_inputs

    def _set_runtime(self, output_gain: np.ndarray | None = None, output_offset: np.ndarray | None = None) -> None:
        self._runtime = runtime_layers(self.weights_, self.input_min_, self.input_max_, output_gain, output_offset)

    def _raw_outputs(self, X) -> np.ndarray:
        """Linear outputs of the last layer (in target units for the regression network)."""
        check_is_fitted(self, "weights_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        if len(X) <= PREDICT_CHUNK:  # small products run on one thread anyway; skip the switch's cost
            return predict_batch(self._runtime, X)
        with single_threaded_blas():
            return predict_batch(self._runtime, X)


class LMNetwork(RegressorMixin, TanhNetworkBase):
    """Feedforward regression network (tanh hidden layers, linear outputs) trained by
    Levenberg–Marquardt with validation early stopping; see the module notes.

    Fitted attributes: ``weights_`` (augmented matrices ``(n_out, n_in + 1)`` per layer, the
    bias last, acting on mapminmax-scaled values), ``input_min_``/``input_max_`` and
    ``target_min_``/``target_max_`` (the scaling), ``n_outputs_``, ``history_`` (per epoch:
    ``train``/``validation``/``test`` MSE of the scaled targets, ``mu``, ``gradient``),
    ``stop_reason_`` (``goal``, ``max_epochs``, ``min_grad``, ``mu_max`` or ``validation``)
    and ``best_epoch_``.
    """

    _SETTINGS = LMSettings

    def __init__(self, hidden_layer_sizes=(10,), *, max_epochs=1000, max_fail=6, mu=1e-3, mu_dec=0.1,
                 mu_inc=10.0, mu_max=1e10, min_grad=1e-7, goal=0.0, division=(0.70, 0.15, 0.15),
                 min_progress=None, anchored=False, random_state=None):
        self.hidden_layer_sizes = hidden_layer_sizes
        self.max_epochs = max_epochs
        self.max_fail = max_fail
        self.mu = mu
        self.mu_dec = mu_dec
        self.mu_inc = mu_inc
        self.mu_max = mu_max
        self.min_grad = min_grad
        self.goal = goal
        self.division = division
        self.min_progress = min_progress
        self.anchored = anchored
        self.random_state = random_state

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    def fit(self, X, y, groups=None, validation_data=None):
        """Train on X (n_samples, n_features) and y (n_samples,) or (n_samples, n_outputs).

        ``groups``: one label per sample (e.g. the trial); the division then keeps groups whole.
        ``validation_data``: (X_val, y_val) to validate on instead of a share of X.
        """
        settings = self._settings()
        rng = np.random.default_rng(settings.random_state)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        targets = y.reshape(len(y), -1).astype(np.float64)
        self.input_min_, self.input_max_ = X.min(axis=0), X.max(axis=0)
        self.target_min_, self.target_max_ = targets.min(axis=0), targets.max(axis=0)
        self.n_outputs_ = targets.shape[1]
        validation = None
        if validation_data is not None:
            val_inputs, val_targets = self._validation_pair(validation_data, X.shape[1])
            val_targets = check_array(np.asarray(val_targets, dtype=np.float64).reshape(len(val_inputs), -1),
                                      input_name="validation_data y")
            if val_targets.shape[1] != self.n_outputs_:
                raise ValueError(f"validation_data y has {val_targets.shape[1]} outputs, "
                                 f"the training data {self.n_outputs_}")
            validation = (val_inputs, val_targets)
        parts = self._divide(X, targets, groups, validation, settings.division, rng)
        scaled = [(to_unit_range(inputs, self.input_min_, self.input_max_),
                   to_unit_range(outputs, self.target_min_, self.target_max_)) for inputs, outputs in parts]
        sizes = [X.shape[1], *settings.hidden_layer_sizes, self.n_outputs_]
        with single_threaded_blas():
            result = levenberg_marquardt(
                initial_layers(sizes, rng), *scaled, max_epochs=settings.max_epochs, max_fail=settings.max_fail,
                mu=settings.mu, mu_dec=settings.mu_dec, mu_inc=settings.mu_inc, mu_max=settings.mu_max,
                min_grad=settings.min_grad, goal=settings.goal,
                min_progress=settings.min_progress)
        self._keep_training(result)
        if settings.anchored:
            zero_input = to_unit_range(np.zeros((1, X.shape[1])), self.input_min_, self.input_max_)[0]
            zero_target = to_unit_range(np.zeros((1, self.n_outputs_)), self.target_min_, self.target_max_)[0]
            self.weights_[-1] = anchored_output_layer(self.weights_, *scaled[0], zero_input, zero_target)
        self._set_runtime_from_scaling()
        return self

    def _export(self) -> tuple[dict[str, np.ndarray], dict]:
        arrays, state = super()._export()
        arrays |= {"target_min": self.target_min_, "target_max": self.target_max_}
        return arrays, state | {"n_outputs": int(self.n_outputs_)}

    @classmethod
    def _restore(cls, params: dict, arrays: dict[str, np.ndarray], state: dict) -> LMNetwork:
        """A fitted network from :meth:`_export` output; ValueError if the parts do not fit together."""
        network = cls(**params)
        network.n_outputs_ = checks.stored_int(state, "n_outputs", 1)
        network._restore_network(arrays, state, network.n_outputs_)
        network.target_min_ = checks.stored_array(arrays, "target_min", (network.n_outputs_,))
        network.target_max_ = checks.stored_array(arrays, "target_max", (network.n_outputs_,))
        network._set_runtime_from_scaling()
        return network

    def _set_runtime_from_scaling(self) -> None:
        output_gain = 1.0 / minmax_gain(self.target_min_, self.target_max_)
        self._set_runtime(output_gain, output_gain + self.target_min_)

    def predict(self, X) -> np.ndarray:
        """Outputs for X; 1-D when the network has one output."""
        outputs = self._raw_outputs(X)
        return outputs.ravel() if self.n_outputs_ == 1 else outputs

    def predict_one(self, x: np.ndarray) -> np.ndarray:
        """Outputs (1-D) for one sample (1-D, float64), without input checks: the real-time path."""
        return forward_one(self._runtime, x)
