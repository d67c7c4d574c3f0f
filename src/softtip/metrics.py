"""Metrics of calibrated sensors and identified systems, as reported in the papers' tables.

Error metrics take reference values ``y`` and estimates ``yhat`` of the same shape, 1-D
(one output: a float) or 2-D (n_samples, n_outputs: one value per output, an array).
Sensor readings are in µT, forces in N; :func:`sensitivity` reports mT/N.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from softtip._core import signals


def _pair(y: ArrayLike, yhat: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    y, yhat = np.asarray(y, dtype=np.float64), np.asarray(yhat, dtype=np.float64)
    if y.shape != yhat.shape or y.ndim not in (1, 2) or len(y) == 0:
        raise ValueError(f"y and yhat must have the same non-empty 1-D or 2-D shape, got {y.shape} and {yhat.shape}")
    return y, yhat


def _reduced(values: np.ndarray):
    return float(values) if values.ndim == 0 else values


def mean_abs_error(y: ArrayLike, yhat: ArrayLike):
    y, yhat = _pair(y, yhat)
    return _reduced(np.mean(np.abs(yhat - y), axis=0))


def max_abs_error(y: ArrayLike, yhat: ArrayLike):
    y, yhat = _pair(y, yhat)
    return _reduced(np.max(np.abs(yhat - y), axis=0))


def rmse(y: ArrayLike, yhat: ArrayLike):
    y, yhat = _pair(y, yhat)
    return _reduced(np.sqrt(np.mean((yhat - y) ** 2, axis=0)))


def _full_scale(full_scale: ArrayLike) -> np.ndarray:
    scale = np.asarray(full_scale, dtype=np.float64)
    if not np.all(np.isfinite(scale)) or np.any(scale <= 0):
        raise ValueError(f"full_scale must be positive (one value or one per output), got {full_scale!r}")
    return scale


def rmse_percent_fs(y: ArrayLike, yhat: ArrayLike, full_scale: ArrayLike):
    """Root-mean-square error in % of ``full_scale`` (a value, or one per output)."""
    return _reduced(100.0 * np.asarray(rmse(y, yhat)) / _full_scale(full_scale))


def mae_percent_fs(y: ArrayLike, yhat: ArrayLike, full_scale: ArrayLike):
    """Mean absolute error in % of ``full_scale`` (a value, or one per output)."""
    return _reduced(100.0 * np.asarray(mean_abs_error(y, yhat)) / _full_scale(full_scale))


def r2(y: ArrayLike, yhat: ArrayLike):
    """Coefficient of determination 1 − SS_res/SS_tot per output; NaN for a constant reference."""
    y, yhat = _pair(y, yhat)
    total = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
    residual = np.sum((y - yhat) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _reduced(np.where(total > 0, 1.0 - residual / total, np.nan))


def pearson_r(y: ArrayLike, yhat: ArrayLike):
    """Pearson correlation of reference and estimate per output; NaN if either is constant."""
    y, yhat = _pair(y, yhat)
    dy, dyhat = y - y.mean(axis=0), yhat - yhat.mean(axis=0)
    norms = np.sqrt(np.sum(dy**2, axis=0) * np.sum(dyhat**2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return _reduced(np.where(norms > 0, np.sum(dy * dyhat, axis=0) / norms, np.nan))


def _label_indices(labels: np.ndarray, values: np.ndarray, what: str) -> np.ndarray:
    """Index of each of ``values`` in the distinct ``labels``; a value outside ``labels`` is an error."""
    order = np.argsort(labels)
    position = np.minimum(np.searchsorted(labels, values, sorter=order), len(labels) - 1)
    index = order[position]
    unknown = labels[index] != values
    if unknown.any():
        raise ValueError(f"{what} holds labels not in the given classes/labels: {np.unique(values[unknown])[:5]}")
    return index


def _labels(labels: ArrayLike, name: str) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.ndim != 1 or len(labels) == 0 or len(np.unique(labels)) != len(labels):
        raise ValueError(f"{name} must be a non-empty 1-D sequence of distinct labels, got {labels!r}")
    return labels


def mean_probability_of_true_class(proba: ArrayLike, y: ArrayLike, classes: ArrayLike) -> float:
    """Mean over samples of the probability given to the true class; ``proba`` columns follow ``classes``."""
    proba, y, classes = np.asarray(proba, dtype=np.float64), np.asarray(y), _labels(classes, "classes")
    if proba.ndim != 2 or proba.shape != (len(y), len(classes)) or len(y) == 0:
        raise ValueError(f"proba must be (n_samples={len(y)}, n_classes={len(classes)}), got {proba.shape}")
    index = _label_indices(classes, y, "y")
    return float(np.mean(proba[np.arange(len(y)), index]))


def confusion(y_true: ArrayLike, y_pred: ArrayLike, labels: ArrayLike) -> np.ndarray:
    """Counts (len(labels), len(labels)): row = true label, column = predicted, in ``labels`` order."""
    y_true, y_pred, labels = np.asarray(y_true), np.asarray(y_pred), _labels(labels, "labels")
    if y_true.shape != y_pred.shape or y_true.ndim != 1:
        raise ValueError(f"y_true and y_pred must be 1-D of the same length, got {y_true.shape} and {y_pred.shape}")
    rows = _label_indices(labels, y_true, "y_true")
    columns = _label_indices(labels, y_pred, "y_pred")
    counts = np.zeros((len(labels), len(labels)), dtype=np.int64)
    np.add.at(counts, (rows, columns), 1)
    return counts


def per_condition(metric: Callable, y: ArrayLike, yhat: ArrayLike, conditions: ArrayLike) -> dict:
    """``metric(y, yhat)`` within each condition (in order of first appearance) and ``"overall"``.

    Conditions are one label per sample (e.g. the board orientation or contact position of
    the trial); numpy scalars become Python values so the dict serialises to JSON.
    """
    y, yhat, conditions = np.asarray(y), np.asarray(yhat), np.asarray(conditions)
    if conditions.ndim != 1 or len(conditions) != len(y) or len(yhat) != len(y):
        raise ValueError(f"conditions must be one label per sample ({len(y)}), got shape {conditions.shape}")
    _, first = np.unique(conditions, return_index=True)
    result = {}
    for condition in conditions[np.sort(first)]:
        key = condition.item() if isinstance(condition, np.generic) else condition
        if key == "overall":
            raise ValueError('conditions must not use the label "overall", which names the all-sample value')
        mask = conditions == condition
        result[key] = metric(y[mask], yhat[mask])
    result["overall"] = metric(y, yhat)
    return result


def _series(force: ArrayLike, signal: ArrayLike, name: str) -> tuple[np.ndarray, np.ndarray]:
    force, signal = np.asarray(force, dtype=np.float64), np.asarray(signal, dtype=np.float64)
    if force.ndim != 1 or len(force) < 2 or len(signal) != len(force) or signal.ndim not in (1, 2):
        raise ValueError(f"force must be 1-D with >= 2 samples and {name} have one row per force sample, "
                         f"got shapes {force.shape} and {signal.shape}")
    if not (np.all(np.isfinite(force)) and np.all(np.isfinite(signal))):
        raise ValueError(f"force and {name} must be finite")
    return force, signal


def hysteresis_percent(force: ArrayLike, z: ArrayLike) -> float:
    """Hysteresis (%) of one load–unload cycle (S1 §2): |Z_up − Z_down| / (Z_max − Z_min) · 100,
    with Z_up, Z_down the z-axis MFD on the loading and unloading branches at the force midway
    between the cycle's minimum and maximum; see
    :func:`softtip._core.signals.hysteresis_percent`, which computes it."""
    return signals.hysteresis_percent(z, force)


def sensitivity(force: ArrayLike, mfd: ArrayLike):
    """Sensitivity in mT/N: least-squares slope of the MFD change (µT) against the normal
    force (N) on the ascending branch (the samples up to the first maximum of force).

    ``mfd`` 1-D gives a float, (n_samples, n_axes) one slope per axis.
    """
    force, mfd = _series(force, mfd, "mfd")
    rising = slice(0, int(np.argmax(force)) + 1)
    f = force[rising] - force[rising].mean()
    if not np.any(f):
        raise ValueError("force does not rise on the ascending branch: sensitivity undefined")
    # f sums to zero, so the MFD needs no centring: Σ f·(m − m̄) = Σ f·m
    slope_ut_per_n = np.tensordot(f, mfd[rising], axes=(0, 0)) / np.dot(f, f)
    return _reduced(np.asarray(slope_ut_per_n) / 1000.0)


def first_detection(force: ArrayLike, predicted_state: ArrayLike, true_state, persistence: int = 1) -> float:
    """The force at which the true state is first detected, NaN if never.

    Detection is the ``persistence``-th of consecutive samples whose predicted state equals
    the true state (default 1: the first matching sample); the force reported is that of
    this sample, i.e. when a detector requiring that persistence would fire. ``true_state``
    is one state for the trial or one per sample.
    """
    force = np.asarray(force, dtype=np.float64)
    predicted = np.asarray(predicted_state)
    if force.ndim != 1 or predicted.shape != force.shape:
        raise ValueError(f"force and predicted_state must be 1-D of the same length, "
                         f"got {force.shape} and {predicted.shape}")
    true = np.asarray(true_state)
    if true.ndim not in (0, 1) or (true.ndim == 1 and true.shape != force.shape):
        raise ValueError(f"true_state must be one state or one per sample ({len(force)}), got shape {true.shape}")
    if isinstance(persistence, bool) or not isinstance(persistence, (int, np.integer)) or persistence < 1:
        raise ValueError(f"persistence must be an integer >= 1, got {persistence!r}")
    matches = (predicted == true).astype(np.int64)
    if len(matches) < persistence:
        return float("nan")
    run_totals = np.convolve(matches, np.ones(persistence, dtype=np.int64), mode="valid")
    detected = np.flatnonzero(run_totals == persistence)
    return float(force[detected[0] + persistence - 1]) if len(detected) else float("nan")

