"""Softmax classifier network trained by scaled conjugate gradient (the toolbox's
``patternnet`` + ``trainscg``; Møller 1993, Neural Networks 6, 525–533).

Inputs are mapminmax-scaled to [-1, 1]; hidden layers are tanh (Nguyen–Widrow
initialisation); the output layer is a softmax over the classes, trained on the mean
cross-entropy −(1/n) Σ_n Σ_k t_nk log p_nk. The data division and validation early stopping
are those of :class:`~softtip.calibration.network.LMNetwork` (``division``, ``groups``,
``validation_data``, ``max_fail``). Training stops at the first of: cross-entropy <= ``goal``,
``max_epochs`` iterations, gradient norm <= ``min_grad``, ``max_fail`` validation failures
(as for the regression network); the weights of the lowest validation cross-entropy are
returned.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import column_or_1d, validate_data

from softtip._core.config import PositiveNumber, schema
from softtip._core.network import forward_one
from softtip._core.threads import single_threaded_blas
from softtip.calibration import checks
from softtip.calibration.feedforward import (
    EarlyStopping,
    backprop_gradient,
    cross_entropy,
    forward,
    initial_layers,
    pack,
    softmax,
    stop_reason,
    to_unit_range,
    unpack,
)
from softtip.calibration.network import TanhNetworkBase, TanhNetworkSettings, TrainingResult


def cross_entropy_and_gradient(layers: list[np.ndarray], inputs: np.ndarray,
                               one_hot: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean cross-entropy of the softmax network and its gradient with respect to θ."""
    activations = forward(layers, inputs)
    probabilities = softmax(activations[-1])
    # ∂(mean cross-entropy)/∂(softmax input) = (p − t)/n
    gradient = backprop_gradient(layers, activations, (probabilities - one_hot) / len(inputs))
    return cross_entropy(probabilities, one_hot), gradient


def _cross_entropy_only(layers, inputs, one_hot) -> float:
    if not len(inputs):
        return float("nan")
    return cross_entropy(softmax(forward(layers, inputs)[-1]), one_hot)


def scaled_conjugate_gradient(layers: list[np.ndarray], train: tuple[np.ndarray, np.ndarray],
                              validation: tuple[np.ndarray, np.ndarray], test: tuple[np.ndarray, np.ndarray], *,
                              max_epochs: int, max_fail: int, sigma: float, lambda_init: float, min_grad: float,
                              goal: float) -> TrainingResult:
    """Møller's SCG on the mean cross-entropy, with the toolbox's stopping rules.

    The curvature along the search direction p comes from a gradient difference over a
    step σ/‖p‖; λ regularises it like the trust-region parameter of Levenberg–Marquardt and is
    adapted from the ratio Δ of actual to predicted decrease. The direction restarts on the
    steepest descent every len(θ) iterations.
    """
    shapes = [w.shape for w in layers]
    inputs, one_hot = train
    theta = pack(layers)
    perf, gradient = cross_entropy_and_gradient(layers, inputs, one_hot)
    residual = -gradient
    direction = residual.copy()
    lambda_k, lambda_bar, success, delta = lambda_init, 0.0, True, 0.0
    vperf = _cross_entropy_only(layers, *validation)
    stopping = EarlyStopping(theta, vperf)
    history = {key: [] for key in ("train", "validation", "test", "lambda", "gradient")}
    for epoch in range(max_epochs + 1):
        gradient_norm = float(np.linalg.norm(residual))
        for key, value in zip(history, (perf, vperf, _cross_entropy_only(unpack(theta, shapes), *test),
                                        lambda_k, gradient_norm), strict=True):
            history[key].append(value)
        reason = stop_reason(epoch, perf, gradient_norm, stopping, max_epochs=max_epochs, goal=goal,
                             min_grad=min_grad, max_fail=max_fail)
        if reason:
            break

        direction_sq = float(direction @ direction)
        if success:  # second-order information along the direction, by a gradient difference
            sigma_k = sigma / np.sqrt(direction_sq)
            _, probe_gradient = cross_entropy_and_gradient(unpack(theta + sigma_k * direction, shapes),
                                                           inputs, one_hot)
            delta = float(direction @ (probe_gradient + residual)) / sigma_k
        delta += (lambda_k - lambda_bar) * direction_sq
        if delta <= 0:  # make the local Hessian positive definite
            lambda_bar = 2.0 * (lambda_k - delta / direction_sq)
            delta = -delta + lambda_k * direction_sq
            lambda_k = lambda_bar
        mu = float(direction @ residual)
        alpha = mu / delta
        trial = theta + alpha * direction
        trial_perf, trial_gradient = cross_entropy_and_gradient(unpack(trial, shapes), inputs, one_hot)
        with np.errstate(divide="ignore", invalid="ignore"):
            comparison = 2.0 * delta * (perf - trial_perf) / mu**2
        if not np.isfinite(comparison):  # an overflowing trial: a failed step, so λ grows
            comparison = -1.0
        if comparison >= 0:
            theta, perf = trial, trial_perf
            previous_residual, residual = residual, -trial_gradient
            lambda_bar, success = 0.0, True
            if (epoch + 1) % len(theta) == 0:
                direction = residual.copy()
            else:
                beta = float(residual @ residual - residual @ previous_residual) / mu
                direction = residual + beta * direction
            if comparison >= 0.75:
                lambda_k *= 0.25
        else:
            lambda_bar, success = lambda_k, False
        if comparison < 0.25:
            lambda_k += delta * (1.0 - comparison) / direction_sq
        vperf = _cross_entropy_only(unpack(theta, shapes), *validation)
        stopping.update(epoch + 1, theta, vperf)
    return TrainingResult(unpack(stopping.best_theta, shapes), {k: np.array(v) for k, v in history.items()},
                          reason, stopping.best_epoch)


@schema
class SCGSettings(TanhNetworkSettings):
    sigma: PositiveNumber
    lambda_init: PositiveNumber


class SoftmaxClassifier(ClassifierMixin, TanhNetworkBase):
    """Classifier network (tanh hidden layers, softmax output) trained by scaled conjugate
    gradient with validation early stopping; see the module notes.

    ``classes_`` may be any sortable labels (ints, strings). Fitted attributes: ``weights_``
    (augmented matrices ``(n_out, n_in + 1)`` per layer, acting on mapminmax-scaled inputs),
    ``input_min_``/``input_max_``, ``classes_``, ``history_`` (per iteration: ``train``/
    ``validation``/``test`` mean cross-entropy, ``lambda``, ``gradient``), ``stop_reason_``
    (``goal``, ``max_epochs``, ``min_grad`` or ``validation``) and ``best_epoch_``.
    """

    _SETTINGS = SCGSettings

    def __init__(self, hidden_layer_sizes=(10,), *, max_epochs=1000, max_fail=6, sigma=5e-5, lambda_init=5e-7,
                 min_grad=1e-6, goal=0.0, division=(0.70, 0.15, 0.15), random_state=None):
        self.hidden_layer_sizes = hidden_layer_sizes
        self.max_epochs = max_epochs
        self.max_fail = max_fail
        self.sigma = sigma
        self.lambda_init = lambda_init
        self.min_grad = min_grad
        self.goal = goal
        self.division = division
        self.random_state = random_state

    def fit(self, X, y, groups=None, validation_data=None):
        """Train on X (n_samples, n_features) and labels y (n_samples,).

        ``groups``: one label per sample (e.g. the trial); the division then keeps groups whole.
        ``validation_data``: (X_val, y_val) to validate on instead of a share of X.
        """
        settings = self._settings()
        rng = np.random.default_rng(settings.random_state)
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        self.classes_, labels = np.unique(y, return_inverse=True)
        if len(self.classes_) < 2:
            raise ValueError(f"SoftmaxClassifier needs samples of at least 2 classes, "
                             f"got 1 class ({self.classes_[0]!r})")
        one_hot = np.eye(len(self.classes_))[labels]
        self.input_min_, self.input_max_ = X.min(axis=0), X.max(axis=0)
        validation = None
        if validation_data is not None:
            val_inputs, val_labels = self._validation_pair(validation_data, X.shape[1])
            validation = (val_inputs, self._one_hot(column_or_1d(val_labels), "validation_data y"))
        parts = self._divide(X, one_hot, groups, validation, settings.division, rng)
        scaled = [(to_unit_range(inputs, self.input_min_, self.input_max_), targets) for inputs, targets in parts]
        sizes = [X.shape[1], *settings.hidden_layer_sizes, len(self.classes_)]
        with single_threaded_blas():
            result = scaled_conjugate_gradient(
                initial_layers(sizes, rng), *scaled, max_epochs=settings.max_epochs, max_fail=settings.max_fail,
                sigma=settings.sigma, lambda_init=settings.lambda_init, min_grad=settings.min_grad,
                goal=settings.goal)
        self._keep_training(result)
        self._set_runtime()
        return self

    def _export(self) -> tuple[dict[str, np.ndarray], dict]:
        arrays, state = super()._export()
        classes = self.classes_
        if classes.dtype.kind not in "iubU":
            classes = np.asarray(classes.tolist())
            if classes.dtype.kind not in "iubU":
                raise ValueError("classes_ must be integers, booleans or strings to be saved")
        return arrays | {"classes": classes}, state

    @classmethod
    def _restore(cls, params: dict, arrays: dict[str, np.ndarray], state: dict) -> SoftmaxClassifier:
        """A fitted classifier from :meth:`_export` output; ValueError if the parts do not fit together."""
        classifier = cls(**params)
        classes = arrays.get("classes")
        if classes is None or classes.ndim != 1 or len(classes) < 2 or len(np.unique(classes)) != len(classes):
            raise ValueError("array 'classes' must list at least 2 distinct labels")
        classifier.classes_ = checks.stored_array(arrays, "classes", classes.shape, kinds="iubU")
        classifier._restore_network(arrays, state, len(classes))
        classifier._set_runtime()
        return classifier

    def _one_hot(self, labels: np.ndarray, what: str) -> np.ndarray:
        index = np.searchsorted(self.classes_, labels)
        index = np.minimum(index, len(self.classes_) - 1)
        unknown = self.classes_[index] != labels
        if unknown.any():
            raise ValueError(f"{what} holds labels not in the training data: {np.unique(labels[unknown])[:5]}")
        return np.eye(len(self.classes_))[index]

    def predict_proba(self, X) -> np.ndarray:
        """Class probabilities (n_samples, n_classes), columns in the order of ``classes_``."""
        return softmax(self._raw_outputs(X))

    def predict(self, X) -> np.ndarray:
        logits = self._raw_outputs(X)
        return self.classes_[np.argmax(logits, axis=1)]

    def predict_proba_one(self, x: np.ndarray) -> np.ndarray:
        """Class probabilities for one sample (1-D, float64), without input checks: the real-time path."""
        logits = forward_one(self._runtime, x)
        exponentials = np.exp(logits - logits.max())
        return exponentials / exponentials.sum()

    def predict_one(self, x: np.ndarray):
        """The class of one sample (1-D, float64), without input checks: the real-time path."""
        return self.classes_[np.argmax(forward_one(self._runtime, x))]
