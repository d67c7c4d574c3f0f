"""Calibration / validation splits by trial.

Samples of one trial are strongly correlated (one motion, one contact), so a model
validated on samples of trials it was calibrated on looks better than it is. Every
split here keeps each trial whole on one side, except :func:`split_by_sample`, which
exists for comparison and warns, and :func:`time_blocks`, which cuts trials into
consecutive blocks for a network's early stopping when there are too few trials to hold
whole ones out.
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from softtip.data.dataset import TRIAL, Dataset, DatasetError, trial_runs

# the roles a protocol gives its trials, in the condition ``role``
CALIBRATION, VALIDATION = "calibration", "validation"


def by_role(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """(calibration rows, validation rows) as the protocol split the trials (the condition ``role``);
    a dataset without roles is all calibration."""
    if "role" not in dataset.conditions:
        rows = len(dataset.groups)
        return np.ones(rows, dtype=bool), np.zeros(rows, dtype=bool)
    role = dataset.column("role")
    return role == CALIBRATION, role == VALIDATION


class LeakageWarning(UserWarning):
    """A split puts samples of one trial on both sides."""


def check_fraction(value: Any, name: str) -> float:
    """``value`` as a float if it is a fraction in (0, 1), else an error naming the parameter ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < value < 1:
        raise DatasetError(f"{name}: expected a fraction in (0, 1), got {value!r}")
    return float(value)


def round_half_up(x: float) -> int:
    return math.floor(x + 0.5)


def _hashable(value: np.generic) -> Any:
    item = value.item()
    return None if isinstance(item, float) and math.isnan(item) else item


def trial_count(value: Any, n_trials: int, name: str, where: str, purpose: str) -> int:
    """How many of ``n_trials`` trials the parameter ``name`` asks for ``purpose`` ("calibration"): a
    count k >= 1, or a fraction of them rounded half up; ``where`` names the trials in messages ("the
    dataset", "condition a=1")."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        if value < 1:
            raise DatasetError(f"{name}: expected a trial count >= 1, got {value}")
        if value > n_trials:
            raise DatasetError(f"{where} has {n_trials} trials, fewer than the {value} asked for {purpose}")
        return int(value)
    return round_half_up(check_fraction(value, name) * n_trials)


def chosen_trials(n_trials: int, k: int, seed: int | np.random.Generator | None) -> np.ndarray:
    """The positions, in order, of the k trials chosen of ``n_trials``: the first k without a seed, k
    drawn at random with one."""
    return np.arange(k) if seed is None else np.sort(np.random.default_rng(seed).permutation(n_trials)[:k])


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
    rng = None if seed is None else np.random.default_rng(seed)  # one stream for every group
    calibration: list[int] = []
    for key, trials in members.items():
        where = ("condition " + ", ".join(f"{name}={value}" for name, value in zip(condition_columns, key, strict=True))
                 if condition_columns else "the dataset")
        k = trial_count(calibration_per_condition, len(trials), "calibration_per_condition", where,
                        "calibration")
        calibration.extend(np.asarray(trials)[chosen_trials(len(trials), k, rng)].tolist())
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


def time_blocks(trial: np.ndarray, time: np.ndarray, block_s: float) -> np.ndarray:
    """A block id per row: each trial (a run of rows of one id) cut every ``block_s`` seconds of its time,
    counted from its first row; ids 0, 1, ... in row order, so no block spans two trials."""
    if isinstance(block_s, bool) or not isinstance(block_s, numbers.Real) or not 0 < block_s < math.inf:
        raise DatasetError(f"block_s: expected a finite number of seconds > 0, got {block_s!r}")
    trial, time = np.asarray(trial), np.asarray(time, dtype=np.float64)
    if trial.shape != time.shape or trial.ndim != 1:
        raise DatasetError(f"time_blocks: trial and time must be 1-D of one length, got {trial.shape} and {time.shape}")
    if not trial.size:
        return np.zeros(0, dtype=np.intp)
    starts, lengths = trial_runs(trial)
    index = np.floor((time - np.repeat(time[starts], lengths)) / block_s)
    new_block = np.r_[False, (trial[1:] != trial[:-1]) | (index[1:] != index[:-1])]
    return np.cumsum(new_block)


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


def sample_mask(groups: np.ndarray, fraction: float, seed: int | None, caller: str, advice: str) -> np.ndarray:
    """A random ``fraction`` of the rows (``groups``: the trial id of each), regardless of trials, as a mask.

    Warns with :class:`LeakageWarning` in the name of ``caller``, counting the trials with rows on
    both sides and giving ``advice`` (the honest split to use instead).
    """
    fraction = check_fraction(fraction, "fraction")
    first = np.zeros(len(groups), dtype=bool)
    first[np.random.default_rng(seed).permutation(len(groups))[:round_half_up(fraction * len(groups))]] = True
    shared = np.intersect1d(groups[first], groups[~first]).size
    warnings.warn(f"{caller}: {shared} of {np.unique(groups).size} trials have samples on both sides; "
                  f"errors measured on this split are optimistic ({advice})", LeakageWarning, stacklevel=3)
    return first


def split_by_sample(dataset: Dataset, fraction: float, *, seed: int | None = None) -> tuple[Dataset, Dataset]:
    """(first, second): a random ``fraction`` of the samples, and the rest, regardless of trials.

    Warns with :class:`LeakageWarning`: samples of one trial end up on both sides, so an error
    measured on the second part is optimistic. Use :func:`split_by_trial` for validation.
    """
    first = sample_mask(dataset.groups, fraction, seed, "split_by_sample", "use split_by_trial")
    return dataset.select(first), dataset.select(~first)
