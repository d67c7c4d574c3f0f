"""Calibration / validation splits by trial.

Samples of one trial are strongly correlated (one motion, one contact), so a model
validated on samples of trials it was calibrated on looks better than it is. Every
split here keeps each trial whole on one side, except :func:`split_by_sample`, which
exists for comparison and warns.
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from softtip.data.dataset import TRIAL, Dataset, DatasetError


class LeakageWarning(UserWarning):
    """A split puts samples of one trial on both sides."""


def _fraction(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < value < 1:
        raise DatasetError(f"{name}: expected a fraction in (0, 1), got {value!r}")
    return float(value)


def _round_half_up(x: float) -> int:
    return math.floor(x + 0.5)


def _hashable(value: np.generic) -> Any:
    item = value.item()
    return None if isinstance(item, float) and math.isnan(item) else item


def _calibration_count(per_condition: Any, n_trials: int, where: str) -> int:
    if isinstance(per_condition, numbers.Integral) and not isinstance(per_condition, bool):
        if per_condition < 1:
            raise DatasetError(f"calibration_per_condition: expected a trial count >= 1, got {per_condition}")
        if per_condition > n_trials:
            raise DatasetError(f"{where} has {n_trials} trials, fewer than the {per_condition} asked for calibration")
        return int(per_condition)
    fraction = _fraction(per_condition, "calibration_per_condition")
    return _round_half_up(fraction * n_trials)


def split_by_trial(dataset: Dataset, calibration_per_condition: int | float,
                   condition_columns: Sequence[str] = (), *, seed: int | None = None) -> tuple[Dataset, Dataset]:
    """(calibration, validation): per condition, k trials for calibration and the rest for validation.

    Trials are grouped by their values of ``condition_columns`` (all trials form one group
    when none are given). ``calibration_per_condition`` is a trial count k (10 for the papers'
    10 + 5 split) or a fraction of each group, rounded half up (0.7 gives 7 + 3 of 10 and
    5 + 3 of 8 is 0.625). Without a seed the first k trials of each group, in recording
    order, calibrate; with a seed, k trials drawn at random.
    """
    for name in condition_columns:
        if name not in dataset.conditions:
            raise DatasetError(f"condition_columns: {name!r} is not a condition "
                               f"(conditions: {', '.join(dataset.conditions) or 'none'})")
    table = dataset.trial_conditions
    members: dict[tuple, list[int]] = {}
    for row, trial in enumerate(table[TRIAL]):
        key = tuple(_hashable(table[name][row]) for name in condition_columns)
        members.setdefault(key, []).append(int(trial))
    rng = None if seed is None else np.random.default_rng(seed)
    calibration: list[int] = []
    for key, trials in members.items():
        where = ("condition " + ", ".join(f"{name}={value}" for name, value in zip(condition_columns, key, strict=True))
                 if condition_columns else "the dataset")
        k = _calibration_count(calibration_per_condition, len(trials), where)
        chosen = np.arange(k) if rng is None else np.sort(rng.permutation(len(trials))[:k])
        calibration.extend(np.asarray(trials)[chosen].tolist())
    in_calibration = np.isin(dataset.groups, calibration)
    return dataset.select(in_calibration), dataset.select(~in_calibration)


def _check_n_splits(trial: np.ndarray, n_splits: Any) -> None:
    n_trials = len(np.unique(trial))
    if isinstance(n_splits, bool) or not isinstance(n_splits, numbers.Integral) or not 2 <= n_splits <= n_trials:
        raise DatasetError(f"n_splits: expected an integer from 2 to the number of trials ({n_trials}), "
                           f"got {n_splits!r}")


def _trial_folds(trial: np.ndarray, n_splits: int, seed: int | None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(train, test) row indices of k folds that keep every trial whole."""
    if seed is None:
        # imported here: scikit-learn is heavy, and only cross-validation needs it
        from sklearn.model_selection import GroupKFold

        yield from GroupKFold(n_splits=n_splits).split(trial.reshape(-1, 1), groups=trial)
        return
    ids = np.unique(trial)
    fold_of_id = np.empty(len(ids), dtype=np.intp)
    fold_of_id[np.random.default_rng(seed).permutation(len(ids))] = np.arange(len(ids)) % n_splits
    fold = fold_of_id[np.searchsorted(ids, trial)]
    for k in range(n_splits):
        yield np.flatnonzero(fold != k), np.flatnonzero(fold == k)


class TrialKFold:
    """A scikit-learn cross-validation splitter (``cv=``) whose folds never split a trial.

    It holds the trial id of every row, so it cannot be used without groups by mistake.
    Without a seed the folds are scikit-learn's ``GroupKFold`` (folds of balanced sample
    counts, deterministic); with a seed the trials are shuffled and dealt into folds of
    equal trial counts (±1).
    """

    def __init__(self, trials: Any, n_splits: int = 5, seed: int | None = None):
        self.trials = np.asarray(trials)
        if self.trials.ndim != 1 or self.trials.dtype.kind not in "iu":
            raise DatasetError(f"trials: expected a 1-D array of integer trial ids, got {self.trials.dtype} "
                               f"of shape {self.trials.shape}")
        _check_n_splits(self.trials, n_splits)
        self.n_splits = int(n_splits)
        self.seed = seed

    @classmethod
    def for_dataset(cls, dataset: Dataset, n_splits: int = 5, seed: int | None = None) -> TrialKFold:
        return cls(dataset.groups, n_splits, seed)

    def get_n_splits(self, X: Any = None, y: Any = None, groups: Any = None) -> int:
        return self.n_splits

    def split(self, X: Any, y: Any = None, groups: Any = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        if len(X) != len(self.trials):
            raise DatasetError(f"TrialKFold: X has {len(X)} rows, the splitter holds {len(self.trials)} trial ids")
        if groups is not None and not np.array_equal(np.asarray(groups), self.trials):
            raise DatasetError("TrialKFold: the groups passed differ from the trial ids the splitter holds")
        return _trial_folds(self.trials, self.n_splits, self.seed)

    def __repr__(self) -> str:
        return f"TrialKFold(n_splits={self.n_splits}, seed={self.seed}, {len(np.unique(self.trials))} trials)"


def kfold_by_trial(dataset: Dataset, n_splits: int = 5, *, seed: int | None = None
                   ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(train, test) row indices of ``n_splits`` folds, each trial in exactly one test fold."""
    return TrialKFold.for_dataset(dataset, n_splits, seed).split(dataset.groups)


def leave_condition_out(dataset: Dataset, column: str, values: Iterable[Any]) -> tuple[Dataset, Dataset]:
    """(trained, untrained): the untrained side holds every trial whose condition ``column`` is in ``values``."""
    if column not in dataset.conditions:
        raise DatasetError(f"leave_condition_out: {column!r} is not a condition "
                           f"(conditions: {', '.join(dataset.conditions) or 'none'})")
    present = dataset.trial_conditions[column]
    wanted = list(values) if isinstance(values, Iterable) and not isinstance(values, str) else [values]
    if not wanted:
        raise DatasetError("leave_condition_out: no values given")
    left_out = np.zeros(len(present), dtype=bool)
    for value in wanted:
        if (present.dtype.kind == "U") != isinstance(value, str):
            raise DatasetError(f"leave_condition_out: {value!r} cannot equal a value of {column} ({present.dtype})")
        matches = present == value
        if not matches.any():
            raise DatasetError(f"leave_condition_out: no trial has {column} = {value!r} "
                               f"(values present: {', '.join(map(str, np.unique(present)))})")
        left_out |= matches
    untrained = np.isin(dataset.groups, dataset.trials[left_out])
    return dataset.select(~untrained), dataset.select(untrained)


def split_by_sample(dataset: Dataset, fraction: float, *, seed: int | None = None) -> tuple[Dataset, Dataset]:
    """(first, second): a random ``fraction`` of the samples, and the rest, regardless of trials.

    Warns with :class:`LeakageWarning`: samples of one trial end up on both sides, so an error
    measured on the second part is optimistic. Use :func:`split_by_trial` for validation.
    """
    fraction = _fraction(fraction, "fraction")
    first = np.zeros(len(dataset), dtype=bool)
    first[np.random.default_rng(seed).permutation(len(dataset))[:_round_half_up(fraction * len(dataset))]] = True
    shared = np.intersect1d(dataset.groups[first], dataset.groups[~first]).size
    warnings.warn(f"split_by_sample: {shared} of {len(dataset.trials)} trials have samples on both sides; "
                  "errors measured on this split are optimistic (use split_by_trial)", LeakageWarning, stacklevel=2)
    return dataset.select(first), dataset.select(~first)
