"""Validating a calibration made of few trials, each unlike the others (a real rig's recordings).

**Early stopping.** The network stops when its error on a held-out share of the calibration data
stops falling (:mod:`softtip.calibration.network`). Which share is held out decides whether that
works:

* ``trials`` — whole trials (the toolbox's rule with trial groups). Right when there are many
  trials of every kind. With a few trials that differ (one taxel, one session, one load path per
  trial) the held-out trial is unlike every training trial: its error rises from the first epochs
  and training stops before the network has learnt, or with two or three trials nothing is held out
  at all and training runs to its epoch cap;
* ``blocks`` — every trial cut into consecutive blocks of ``block_s`` seconds
  (:func:`softtip.data.splits.time_blocks`), whole blocks held out. Every kind of trial is in
  training and in validation; a block is long against the time over which neighbouring samples are
  alike, so the validation error is not that of samples the network was trained on (a random share
  of samples would follow the training error and never stop training). Because it is not, it does
  not fall at every epoch the training error falls: Levenberg–Marquardt crosses plateaus (μ raised,
  small steps) on which the held-out blocks' error sits a few per cent above its lowest for ten or
  twenty epochs before both fall again. The toolbox's 6 failures, set for a random share, stop
  there. So with blocks, failures stop training only once the network has stopped learning too:
  its training error fell by less than :data:`BLOCKS_MIN_PROGRESS` over the last 6 epochs
  (``min_progress`` of :class:`~softtip.calibration.network.LMNetwork`). A plateau, where the
  training error still falls, is crossed; overfitting, where the validation error rises while the
  training error barely moves, still stops it. The weights kept are those of the lowest
  validation error;
* ``auto`` (the default) — ``trials`` when the calibration set has at least
  :data:`MIN_TRIALS_HELD_OUT` trials (the default 15 % validation share is then two trials or
  more), ``blocks`` otherwise.

**Model selection** across trials is :func:`cross_validate_by_trial`: every calibration trial in
turn (or a fold of them) is held out, each candidate fitted on the rest with the same early-stopping
rule, and the held-out errors averaged; :func:`selected` takes the candidate of the lowest error.
It tells which model carries over to a trial it has not seen, which a validation share inside the
calibration trials cannot.

**Covariate shift** (:class:`CalibrationRange`): a validation set is scored as the model will be used only
if it lies where the model was calibrated. The statistic is the *out-of-range share*: the share of
validation samples with at least one input channel (or target) beyond the calibration set's range
widened by :data:`RANGE_MARGIN` of its span on each side. Above :data:`SHIFT_WARNING_SHARE` the
validation error measures extrapolation, and a warning says so.

**Baselines** (:func:`baselines`): scikit-learn's ridge regression, gradient boosting and MLP,
fitted on the same calibration samples and scored on the same validation samples, as a reference
for whether softtip's model is competitive on the data. Each is a plain, documented configuration
(inputs standardised; no early stopping on a random share of samples, which would leak), not a
tuned one.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.compose import TransformedTargetRegressor
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import RidgeCV
from sklearn.multioutput import MultiOutputRegressor
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from softtip import metrics
from softtip._core.threads import single_threaded
from softtip.data.splits import TrialKFold, time_blocks

StoppingRule = Literal["auto", "trials", "blocks"]
STOPPING_RULES: tuple[str, ...] = get_args(StoppingRule)
MIN_TRIALS_HELD_OUT = 10  # round(0.15 * 10) = 2 validation trials: fewer, and one trial decides when to stop
DEFAULT_BLOCK_S = 5.0  # several seconds: longer than a press's rise, short against a recording
BLOCKS_MIN_PROGRESS = 0.01  # a training error falling by 1 % in 6 epochs is still learning (see the notes)
RANGE_MARGIN = 0.05  # of the calibration span, each side: quantisation steps and noise are not a shift
SHIFT_WARNING_SHARE = 0.01  # of the validation samples beyond the widened range
BASELINES: tuple[str, ...] = ("ridge", "boosting", "mlp")
RIDGE_ALPHAS = np.logspace(-6, 6, 13)
MLP_HIDDEN = (100,)  # scikit-learn's default size
MLP_MAX_ITER = 1000


def stopping_groups(trial: np.ndarray, time_s: np.ndarray, rule: StoppingRule,
                    block_s: float = DEFAULT_BLOCK_S) -> tuple[np.ndarray, str]:
    """(the group of every sample for a network's held-out shares, the rule applied: ``trials`` or
    ``blocks``); ``auto`` resolved as in the module notes."""
    if rule not in STOPPING_RULES:
        raise ValueError(f"early stopping rule: expected one of {', '.join(STOPPING_RULES)}, got {rule!r}")
    trial = np.asarray(trial)
    if rule == "auto":
        rule = "trials" if np.unique(trial).size >= MIN_TRIALS_HELD_OUT else "blocks"
    if rule == "trials":
        return trial, rule
    return time_blocks(trial, time_s, block_s), rule


def min_progress(rule: str) -> float | None:
    """The network's ``min_progress`` under an applied rule (``trials`` or ``blocks``): the toolbox's
    failures alone with whole trials; with blocks, failures while the training error falls do not
    count (see the module notes)."""
    return BLOCKS_MIN_PROGRESS if rule == "blocks" else None


# --------------------------------------------------------------------------
# Covariate shift
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class RangeShift:
    """How far a validation set lies outside its calibration set (see the module notes).

    ``input_share``: share of validation samples with any input beyond the widened calibration range;
    ``target_share``: the same for the targets; ``channel_shares``: per input channel, its share.
    """

    input_share: float
    target_share: float
    channel_shares: tuple[float, ...]

    @property
    def shifted(self) -> bool:
        return max(self.input_share, self.target_share) > SHIFT_WARNING_SHARE

    def warning(self, channels: tuple[str, ...], targets: tuple[str, ...]) -> str:
        """One line saying where the validation set leaves the calibration range ("" when it does not)."""
        if not self.shifted:
            return ""
        worst = np.argsort(self.channel_shares)[::-1][:3]
        named = ", ".join(f"{channels[k]} {100 * self.channel_shares[k]:.0f} %" for k in worst
                          if self.channel_shares[k] > 0)
        return (f"validation set unlike the calibration set: {100 * self.input_share:.1f} % of its samples have an "
                f"input beyond the calibration range (± {100 * RANGE_MARGIN:.0f} % of its span; {named or 'none'}) "
                f"and {100 * self.target_share:.1f} % a target ({', '.join(targets)}) beyond it; its errors measure "
                "extrapolation")

    def to_json(self, channels: tuple[str, ...]) -> dict:
        return {"input_share": self.input_share, "target_share": self.target_share,
                "channel_shares": dict(zip(channels, self.channel_shares, strict=True)),
                "margin_of_span": RANGE_MARGIN, "warning_above": SHIFT_WARNING_SHARE}


@dataclass(frozen=True)
class CalibrationRange:
    """Per input channel and per target, the lowest and highest value of a calibration set: what a model
    file keeps so that any later dataset can be checked against it (:meth:`shift`)."""

    input_low: tuple[float, ...]
    input_high: tuple[float, ...]
    target_low: tuple[float, ...]
    target_high: tuple[float, ...]

    @classmethod
    def of(cls, X: np.ndarray, y: np.ndarray) -> CalibrationRange:
        """The range of calibration inputs X (n, channels) and targets y ((n,) or (n, targets))."""
        if not len(X):
            raise ValueError("calibration range: the calibration set holds no samples")
        y = y.reshape(len(y), -1)
        return cls(*(tuple(map(float, values)) for values in (X.min(axis=0), X.max(axis=0), y.min(axis=0),
                                                               y.max(axis=0))))

    @classmethod
    def from_json(cls, stored: object, n_inputs: int, n_targets: int) -> CalibrationRange:
        """The range a model file stored, checked: one finite value per input and per target, low <= high."""
        if not isinstance(stored, dict) or set(stored) != {"input_low", "input_high", "target_low", "target_high"}:
            raise ValueError("the model's calibration range must hold input_low, input_high, target_low, target_high")
        parts = {}
        for name, size in (("input_low", n_inputs), ("input_high", n_inputs), ("target_low", n_targets),
                           ("target_high", n_targets)):
            values = stored[name]
            if (not isinstance(values, list) or len(values) != size
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in values)):
                raise ValueError(f"the model's calibration range {name}: expected {size} finite numbers")
            parts[name] = tuple(map(float, values))
        made = cls(**parts)
        if any(np.greater(made.input_low, made.input_high)) or any(np.greater(made.target_low, made.target_high)):
            raise ValueError("the model's calibration range has a low end above its high end")
        return made

    def to_json(self) -> dict:
        return {"input_low": list(self.input_low), "input_high": list(self.input_high),
                "target_low": list(self.target_low), "target_high": list(self.target_high)}

    def shift(self, X: np.ndarray, y: np.ndarray) -> RangeShift:
        """The out-of-range shares of a dataset of inputs X and targets y (see the module notes)."""
        if not len(X):
            raise ValueError("range shift: the dataset holds no samples")
        inputs = _beyond(np.array(self.input_low), np.array(self.input_high), X)
        targets = _beyond(np.array(self.target_low), np.array(self.target_high), y.reshape(len(y), -1))
        return RangeShift(float(inputs.any(axis=1).mean()), float(targets.any(axis=1).mean()),
                          tuple(float(share) for share in inputs.mean(axis=0)))


def _beyond(low: np.ndarray, high: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per sample and column of ``values``: beyond [low, high] widened by the margin of the span."""
    margin = RANGE_MARGIN * (high - low)
    return (values < low - margin) | (values > high + margin)


# --------------------------------------------------------------------------
# Scores, baselines, cross-validation
# --------------------------------------------------------------------------


def regression_scores(truth: np.ndarray, estimate: np.ndarray, targets: tuple[str, ...]) -> dict[str, dict]:
    """Per target: mean absolute error, RMSE and R² of ``estimate`` against ``truth``."""
    truth, estimate = truth.reshape(len(truth), -1), estimate.reshape(len(truth), -1)
    return {name: {"mean_abs_error": float(metrics.mean_abs_error(truth[:, k], estimate[:, k])),
                   "rmse": float(metrics.rmse(truth[:, k], estimate[:, k])),
                   "r2": float(metrics.r2(truth[:, k], estimate[:, k]))} for k, name in enumerate(targets)}


def baseline(name: str, seed: int) -> BaseEstimator:
    """A scikit-learn reference regressor by name (one of :data:`BASELINES`), multi-output."""
    if name == "ridge":
        return make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS))
    if name == "boosting":
        return MultiOutputRegressor(HistGradientBoostingRegressor(early_stopping=False, random_state=seed))
    if name == "mlp":
        network = make_pipeline(StandardScaler(), MLPRegressor(hidden_layer_sizes=MLP_HIDDEN, max_iter=MLP_MAX_ITER,
                                                               random_state=seed))
        return TransformedTargetRegressor(network, transformer=StandardScaler())
    raise ValueError(f"baseline: expected one of {', '.join(BASELINES)}, got {name!r}")


@dataclass(frozen=True)
class BaselineScore:
    name: str
    scores: dict[str, dict]  # per target, as regression_scores
    fit_s: float
    converged: bool  # False when scikit-learn warned that the fit stopped at its iteration cap

    def to_json(self) -> dict:
        return {"validation": self.scores, "fit_s": round(self.fit_s, 3), "converged": self.converged}


def fit_quietly(estimator: BaseEstimator, X: np.ndarray, y: np.ndarray) -> bool:
    """Fit on one thread; whether it converged (scikit-learn's ConvergenceWarning caught and reported, not
    printed)."""
    with warnings.catch_warnings(record=True) as caught, single_threaded():
        warnings.simplefilter("always", ConvergenceWarning)
        estimator.fit(X, y)
    return not any(issubclass(w.category, ConvergenceWarning) for w in caught)


def baselines(calibration: tuple[np.ndarray, np.ndarray], validation: tuple[np.ndarray, np.ndarray],
              targets: tuple[str, ...], seed: int, names: tuple[str, ...] = BASELINES) -> list[BaselineScore]:
    """Each baseline fitted on the calibration (X, y) and scored on the validation (X, y)."""
    (X, y), (X_val, y_val) = calibration, validation
    results = []
    for name in names:
        model = baseline(name, seed)
        start = time.perf_counter()
        converged = fit_quietly(model, X, y.reshape(len(y), -1))
        seconds = time.perf_counter() - start
        results.append(BaselineScore(name, regression_scores(y_val, model.predict(X_val), targets), seconds, converged))
    return results


@dataclass(frozen=True)
class Candidate:
    """A model to cross-validate: a factory of unfitted estimators given the early-stopping rule applied
    (``trials`` or ``blocks``, for :func:`min_progress`), and whether its fit takes early-stopping groups."""

    name: str
    make: Callable[[str], BaseEstimator]
    takes_groups: bool


@dataclass(frozen=True)
class CrossValidation:
    """Errors on held-out trials: per candidate, the RMSE of every target; per fold, its held-out trials
    and how far they lie outside the range of the trials fitted on (a fold far outside measures
    extrapolation, and so does the RMSE it adds to)."""

    rmse: dict[str, np.ndarray]
    held_out_trials: tuple[tuple[int, ...], ...]
    held_out_shifts: tuple[RangeShift, ...]


def cross_validate_by_trial(candidates: list[Candidate], X: np.ndarray, y: np.ndarray, trial: np.ndarray,
                            time_s: np.ndarray, n_splits: int, rule: StoppingRule = "auto",
                            block_s: float = DEFAULT_BLOCK_S) -> CrossValidation:
    """``n_splits`` folds of whole trials (:class:`~softtip.data.splits.TrialKFold`), every sample predicted
    once by each candidate fitted without its trial; the early-stopping groups of each fold's fit are made
    from its own trials."""
    folds = list(TrialKFold(trial, n_splits).split(X))
    targets = y.reshape(len(y), -1)
    predicted = {candidate.name: np.empty_like(targets) for candidate in candidates}
    for train, test in folds:
        groups, applied = stopping_groups(trial[train], time_s[train], rule, block_s)
        for candidate in candidates:
            model = candidate.make(applied)
            if candidate.takes_groups:
                model.fit(X[train], y[train], groups=groups)
            else:
                fit_quietly(model, X[train], targets[train])
            predicted[candidate.name][test] = model.predict(X[test]).reshape(len(test), -1)
    return CrossValidation(
        {name: np.atleast_1d(metrics.rmse(targets, estimate)) for name, estimate in predicted.items()},
        tuple(tuple(int(t) for t in np.unique(trial[test])) for _, test in folds),
        tuple(CalibrationRange.of(X[train], targets[train]).shift(X[test], targets[test]) for train, test in folds))


def selected(rmse: dict[str, np.ndarray], y: np.ndarray) -> str:
    """The name whose cross-validated RMSE, each target's divided by its spread (standard deviation) over the
    calibration samples ``y`` so that targets in different units weigh alike, is lowest on average."""
    spread = np.std(y.reshape(len(y), -1), axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    return min(rmse, key=lambda name: float(np.mean(rmse[name] / spread)))
