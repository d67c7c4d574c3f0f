"""A saved model carried over to a new session: re-zeroed at rest, re-calibrated from a few presses.

Between sessions a magnetic skin's readings change scale: the magnets' remanence falls with
temperature (NdFeB about -0.12 %/K), a chip's sensitivity drifts, the elastomer creeps and ages, and
iron nearby bends the field. On a real 2x2 array of 3-axis Hall chips the sensitivity changed
2-3.5x between an afternoon and an evening, and every model trained on one session did worse on the
other than predicting zero. A new session is therefore

1. **re-zeroed at rest**: its readings are changes from its own rest (the dataset's baseline, or the
   live baseline taken at rest), which takes out every offset;
2. **re-calibrated** from at most a few presses of a known or measured load, keeping the model:
   :class:`SessionGains` multiplies each input by a gain, shared by the inputs of one chip by default
   (``grouping="chip"``): a magnet's remanence and a chip's sensitivity scale the three axes of a
   chip alike, so five chips need five gains, which one or two presses determine. The gains are
   fitted by least squares through the model (``scipy.optimize.least_squares``, gains kept within
   1/20..20: a gain at a bound is reported). ``"channel"`` gives every input its own gain (more
   presses needed), ``"common"`` one gain for all.

Gains rather than an affine correction of the inputs: the re-zero has taken out the offsets, and an
offset fitted from a few presses is poorly determined (tried on the eFlesh recordings, it did worse).
Gains rather than a correction of the output: the chips drift apart (the 2-3.5x above differed from
chip to chip), which one output scale cannot follow. The corrected model is the original with a
scaling step in front (:meth:`SessionGains.corrected_model`), saved and run live as any model.

:func:`session_curve` scores a model on a new session after 0, 1, ... presses, always on the same
samples (those after the last press it may use): the error against the number of presses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import least_squares
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted, validate_data

from softtip._core.systems import reading_of
from softtip._core.errors import NotConverged

GROUPINGS = ("chip", "channel", "common")
Grouping = Literal["chip", "channel", "common"]
GAIN_BOUNDS = (1 / 20, 20.0)


def gain_groups(channels: list[str] | tuple[str, ...], grouping: Grouping = "chip") -> np.ndarray:
    """The gain each input channel shares (0, 1, ...): by chip, one per channel, or one for all."""
    if grouping not in GROUPINGS:
        raise ValueError(f"grouping = {grouping!r}: expected one of {', '.join(GROUPINGS)}")
    if grouping == "common":
        return np.zeros(len(channels), dtype=int)
    if grouping == "channel":
        return np.arange(len(channels))
    reading = reading_of(channels)
    chips = [reading.channel_order(name)[0] for name in channels]
    return np.unique(chips, return_inverse=True)[1]


def press_ends(load: np.ndarray, trials: np.ndarray, above: float) -> np.ndarray:
    """The row after each press: a press is a run of rows of one trial whose ``load`` exceeds
    ``above``; it ends at the first row back at or below it (or at its trial's end)."""
    pressed = np.asarray(load, dtype=np.float64) > above
    trials = np.asarray(trials)
    same_trial = np.r_[False, trials[1:] == trials[:-1]]
    starts = pressed & ~(same_trial & np.r_[False, pressed[:-1]])
    runs = np.cumsum(starts) * pressed  # run number of every pressed row, 0 elsewhere
    return np.array([np.flatnonzero(runs == run)[-1] + 1 for run in range(1, runs.max() + 1)], dtype=int)


class SessionGains(RegressorMixin, BaseEstimator):
    """A fitted ``model`` (anything with ``predict``) with its inputs multiplied by gains fitted on a new
    session: the gain of ``groups[j]`` multiplies input j (see the module notes).

    Fitted attributes: ``gains_`` (one per input), ``group_gains_``, ``at_bound_`` (groups whose gain
    reached 1/20 or 20: the presses did not determine them), ``cost_`` (the final mean squared
    residual over the outputs' mean squares), ``n_features_in_``.
    """

    def __init__(self, model=None, groups=None):
        self.model = model
        self.groups = groups

    def fit(self, X, y):
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        groups = np.zeros(X.shape[1], int) if self.groups is None else np.asarray(self.groups, dtype=int)
        if groups.shape != (X.shape[1],) or groups.min() < 0:
            raise ValueError(f"groups: expected one non-negative group per input ({X.shape[1]}), got {groups}")
        targets = y.reshape(len(y), -1)
        # Each output's residual in units of its own size, so newtons and newton-metres weigh alike.
        weight = 1.0 / np.sqrt(len(targets) * np.maximum(np.mean(targets**2, axis=0), np.finfo(float).tiny))
        count = groups.max() + 1

        def residuals(group_gains: np.ndarray) -> np.ndarray:
            predicted = np.asarray(self.model.predict(X * group_gains[groups])).reshape(targets.shape)
            return ((predicted - targets) * weight).ravel()

        low, high = GAIN_BOUNDS
        result = least_squares(residuals, np.ones(count), bounds=(low, high), xtol=1e-10, ftol=1e-10, gtol=1e-10)
        if result.status <= 0:
            raise NotConverged(f"session gains: least squares stopped without converging ({result.message})")
        self.group_gains_ = result.x
        self.gains_ = result.x[groups]
        self.at_bound_ = np.flatnonzero(result.active_mask != 0)
        self.cost_ = float(2 * result.cost / targets.shape[1])
        return self

    def predict(self, X):
        check_is_fitted(self, "gains_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.model.predict(X * self.gains_)

    def corrected_model(self) -> Pipeline:
        """The model with a scaling step in front that multiplies its inputs by the gains: a
        scikit-learn Pipeline that :func:`~softtip.calibration.save_model` saves as any model."""
        check_is_fitted(self, "gains_")
        scaling = StandardScaler()
        scaling.mean_ = np.zeros(self.n_features_in_)
        scaling.scale_ = 1.0 / self.gains_  # StandardScaler divides by its scale
        scaling.var_ = scaling.scale_**2
        scaling.n_features_in_ = self.n_features_in_
        scaling.n_samples_seen_ = 1
        steps = list(self.model.steps) if isinstance(self.model, Pipeline) else [("model", self.model)]
        return Pipeline([("session", scaling), *steps])


@dataclass(frozen=True)
class SessionCurve:
    """Errors of a model on a new session after 0..``len(rmse) - 1`` presses.

    ``rmse`` (presses + 1, outputs): on the scored rows, those after the last press used;
    ``zero_rmse``: predicting zero on them; ``gains``: the per-input gains after each count of presses
    (ones for none); ``press_ends``: the row after each press found; ``scored_rows``: how many.
    """

    rmse: np.ndarray
    zero_rmse: np.ndarray
    gains: np.ndarray
    press_ends: np.ndarray
    scored_rows: int
    at_bound: tuple[tuple[int, ...], ...]


def session_curve(model, X: np.ndarray, y: np.ndarray, trials: np.ndarray, *, presses: int, above: float,
                  groups: np.ndarray) -> SessionCurve:
    """``model`` on a new session (``X`` changes from its rest, ``y`` its loads, rows in time order):
    re-calibrated by :class:`SessionGains` on the rows up to the end of its first k presses, for k in
    0..``presses``, and scored on the rows after the ``presses``-th (a press: rows whose largest
    absolute output exceeds ``above``). ValueError if the session has too few presses or nothing after
    them."""
    y2 = np.asarray(y, dtype=np.float64).reshape(len(y), -1)
    load = np.abs(y2).max(axis=1)
    ends = press_ends(load, trials, above)
    if len(ends) < presses:
        raise ValueError(f"the new session has {len(ends)} presses above {above:g}; {presses} asked for")
    start = int(ends[presses - 1]) if presses else 0
    if start >= len(X) or not (load[start:] > above).any():
        raise ValueError(f"the new session has no press after its first {presses} to score on")
    scored = slice(start, None)

    def rmse(predicted: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean((np.asarray(predicted).reshape(-1, y2.shape[1]) - y2[scored]) ** 2, axis=0))

    errors, gains, at_bound = [rmse(model.predict(X[scored]))], [np.ones(X.shape[1])], [()]
    for k in range(1, presses + 1):
        fitted = SessionGains(model, groups).fit(X[: ends[k - 1]], y2[: ends[k - 1]])
        errors.append(rmse(fitted.predict(X[scored])))
        gains.append(fitted.gains_)
        at_bound.append(tuple(int(g) for g in fitted.at_bound_))
    return SessionCurve(rmse=np.array(errors), zero_rmse=rmse(np.zeros_like(y2[scored])), gains=np.array(gains),
                        press_ends=ends, scored_rows=len(X) - start, at_bound=tuple(at_bound))

