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

Gains rather than an affine correction of the inputs by default: the re-zero has taken out the
offsets, and an offset fitted from a few presses is poorly determined (tried on the eFlesh
recordings, it did worse). Where the readings change shape, not only scale (a steel plate near the
chips adds its images' field, which depends on where the magnets are), :class:`SessionAffine` maps
each chip's readings by a matrix and an offset, regularised toward the identity: on the twin with
every cause of drift at once it leaves 0.39 N on Fz after five presses where gains leave 0.60 N
(``softtip fingertip drift``), and from one press it is worse than no correction.
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


def _session_rows(estimator, X, y) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A session correction's checked inputs, its inputs' groups (0 for all without ``groups``), its
    targets as (rows, outputs) and each output's weight: one over the square root of rows times its
    mean square, so that newtons and newton-metres weigh alike."""
    X, y = validate_data(estimator, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
    groups = np.zeros(X.shape[1], int) if estimator.groups is None else np.asarray(estimator.groups, dtype=int)
    if groups.shape != (X.shape[1],) or groups.min() < 0:
        raise ValueError(f"groups: expected one non-negative group per input ({X.shape[1]}), got {groups}")
    targets = y.reshape(len(y), -1)
    weight = 1.0 / np.sqrt(len(targets) * np.maximum(np.mean(targets**2, axis=0), np.finfo(float).tiny))
    return X, groups, targets, weight


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
        X, groups, targets, weight = _session_rows(self, X, y)
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
    ``zero_rmse``: predicting zero on them; ``gains``: the per-input gains (an affine map's
    diagonal) after each count of presses (ones for none); ``press_ends``: the row after each press
    found; ``scored_rows``: how many.
    """

    rmse: np.ndarray
    zero_rmse: np.ndarray
    gains: np.ndarray
    press_ends: np.ndarray
    scored_rows: int
    at_bound: tuple[tuple[int, ...], ...]


def session_curve(model, X: np.ndarray, y: np.ndarray, trials: np.ndarray, *, presses: int, above: float,
                  groups: np.ndarray, affine: bool = False) -> SessionCurve:
    """``model`` on a new session (``X`` changes from its rest, ``y`` its loads, rows in time order):
    re-calibrated by :class:`SessionGains` (``affine``: :class:`SessionAffine`, whose matrices'
    diagonals are then the curve's gains) on the rows up to the end of its first k presses, for k in
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
        correction = SessionAffine(model, groups) if affine else SessionGains(model, groups)
        fitted = correction.fit(X[: ends[k - 1]], y2[: ends[k - 1]])
        errors.append(rmse(fitted.predict(X[scored])))
        gains.append(np.diag(fitted.map_) if affine else fitted.gains_)
        at_bound.append(() if affine else tuple(int(g) for g in fitted.at_bound_))
    return SessionCurve(rmse=np.array(errors), zero_rmse=rmse(np.zeros_like(y2[scored])), gains=np.array(gains),
                        press_ends=ends, scored_rows=len(X) - start, at_bound=tuple(at_bound))


class SessionAffine(RegressorMixin, BaseEstimator):
    """A fitted ``model`` with each group's inputs (a chip's, by :func:`gain_groups`) mapped by a matrix
    and an offset fitted on a new session: ``x_g -> A_g x_g + s_g b_g``, ``s_g`` the RMS of the group's
    inputs on the rows fitted, so that ``b_g`` is in units of the readings' size. The fit minimises the
    outputs' squared error (each output over its mean square, as :class:`SessionGains`) plus ``alpha``
    times Σ‖A_g − I‖² + ‖b_g‖²: with few presses the map stays near the identity where they do not
    determine it.

    Fitted attributes: ``matrices_`` (one per group), ``offsets_`` (in the inputs' units),
    ``cost_`` (as :class:`SessionGains`), ``n_features_in_``.
    """

    def __init__(self, model=None, groups=None, alpha=1e-3):
        self.model = model
        self.groups = groups
        self.alpha = alpha

    def fit(self, X, y):
        if not (isinstance(self.alpha, (int, float)) and 0 < self.alpha < np.inf):
            raise ValueError(f"alpha = {self.alpha!r}: expected a number > 0")
        X, groups, targets, weight = _session_rows(self, X, y)
        members = [np.flatnonzero(groups == g) for g in np.unique(groups)]
        sizes = np.sqrt([np.mean(X[:, m] ** 2) for m in members])
        sizes = np.where(sizes > 0, sizes, 1.0)
        identity = np.concatenate([np.r_[np.eye(len(m)).ravel(), np.zeros(len(m))] for m in members])

        def residuals(parameters: np.ndarray) -> np.ndarray:
            self._set_map(parameters, members, sizes, X.shape[1])
            predicted = np.asarray(self.model.predict(self._mapped(X))).reshape(targets.shape)
            return np.r_[((predicted - targets) * weight).ravel(), np.sqrt(self.alpha) * (parameters - identity)]

        result = least_squares(residuals, identity, xtol=1e-10, ftol=1e-10, gtol=1e-10)
        if result.status <= 0:
            raise NotConverged(f"session affine map: least squares stopped without converging ({result.message})")
        self._set_map(result.x, members, sizes, X.shape[1])
        self.matrices_ = [self.map_[np.ix_(m, m)] for m in members]
        self.offsets_ = self.shift_.copy()
        self.cost_ = float(np.sum(result.fun[:targets.size] ** 2) / targets.shape[1])
        return self

    def _set_map(self, parameters: np.ndarray, members: list[np.ndarray], sizes: np.ndarray, n: int) -> None:
        """The block-diagonal matrix ``map_`` and the offset ``shift_`` of packed parameters."""
        self.map_, self.shift_ = np.zeros((n, n)), np.zeros(n)
        start = 0
        for m, size in zip(members, sizes, strict=True):
            k = len(m)
            self.map_[np.ix_(m, m)] = parameters[start:start + k * k].reshape(k, k)
            self.shift_[m] = size * parameters[start + k * k:start + k * k + k]
            start += k * k + k

    def _mapped(self, X: np.ndarray) -> np.ndarray:
        return X @ self.map_.T + self.shift_

    def predict(self, X):
        check_is_fitted(self, "matrices_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.model.predict(self._mapped(X))

