"""Estimation / validation splits of a recording, and which of them are honest for time series.

A model of a dynamic system is judged on what it was not fitted to. Neighbouring samples of a
10 Hz force recording are nearly equal, so a split that scatters samples at random between the two
sides (:func:`split_by_sample`, the published 80/20 split) scores the model on samples whose
neighbours it was fitted to: it warns with :class:`~softtip.data.LeakageWarning`. The honest splits
keep time together: whole trials (:func:`split_by_trial`), or a contiguous block of time
(:func:`split_by_time`: the first 80 % of each trial, or a 40 s estimation segment followed by a
10 s validation segment).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from softtip._core.config import NonNegativeNumber, PositiveNumber, checked
from softtip.data.dataset import DatasetError
from softtip.data.splits import check_fraction, chosen_trials, round_half_up, sample_mask, trial_count
from softtip.sysid.recording import Recording, Trial


def split_by_trial(recording: Recording, estimation: int | float = 0.8, *,
                   seed: int | None = None) -> tuple[Recording, Recording]:
    """(estimation, validation): ``estimation`` trials (a count, or a fraction rounded half up) and the
    rest; the first ones in recording order without a seed, drawn at random with one."""
    n = len(recording.trials)
    k = trial_count(estimation, n, "estimation", f"{recording.source}", "estimation")
    if k >= n:
        raise DatasetError(f"{recording.source}: estimation = {estimation!r} takes all {n} trials: none is left "
                           "for validation")
    chosen = chosen_trials(n, k, seed)
    rest = np.setdiff1d(np.arange(n), chosen)
    return recording.select(chosen), recording.select(rest)


def _cut(trial: Trial, first: int, last: int) -> Trial:
    """Samples ``first`` to ``last`` (exclusive) of ``trial``."""
    scored = None if trial.scored is None else trial.scored[first:last]
    return Trial(trial.u[first:last], trial.y[first:last], trial.id, trial.start + first, scored)


def split_by_time(recording: Recording, fraction: float | None = None, *, estimation_s: float | None = None,
                  validation_s: float | None = None) -> tuple[Recording, Recording]:
    """(estimation, validation) by contiguous blocks of time.

    With ``fraction``: the first ``fraction`` of every trial (rounded half up) for estimation, the
    rest of it for validation. With ``estimation_s`` (and optionally ``validation_s``): the trials
    laid end to end in order, the first ``estimation_s`` seconds for estimation and the following
    ``validation_s`` seconds (default: all the rest) for validation; a trial crossing a boundary is
    cut there, and pieces of fewer than 2 samples are left out.
    """
    source = recording.source
    if (fraction is None) == (estimation_s is None):
        raise DatasetError(f"{source}: split_by_time: give either fraction or estimation_s")
    if fraction is not None:
        if validation_s is not None:
            raise DatasetError(f"{source}: split_by_time: validation_s goes with estimation_s, not with fraction")
        fraction = check_fraction(fraction, "fraction")
        estimation, validation = [], []
        for trial in recording.trials:
            cut = round_half_up(fraction * len(trial))
            if min(cut, len(trial) - cut) < 2:
                raise DatasetError(f"{source}: trial {trial.id} has {len(trial)} samples: a {fraction:g} split "
                                   "leaves fewer than 2 on one side")
            estimation.append(_cut(trial, 0, cut))
            validation.append(_cut(trial, cut, len(trial)))
        return recording.with_trials(estimation), recording.with_trials(validation)
    first = round(checked(PositiveNumber, "estimation_s", estimation_s, DatasetError) / recording.ts)
    total = recording.n_samples
    if validation_s is None:
        last = total
    else:
        last = first + round(checked(NonNegativeNumber, "validation_s", validation_s, DatasetError) / recording.ts)
    if last > total or first >= last:
        raise DatasetError(f"{source}: split_by_time: {first} + {last - first} samples asked for, the recording "
                           f"has {total} ({total * recording.ts:g} s)")
    sides: tuple[list[Trial], list[Trial]] = ([], [])
    offset = 0
    for trial in recording.trials:
        for side, (a, b) in enumerate(((0, first), (first, last))):
            a, b = max(a - offset, 0), min(b - offset, len(trial))
            if b - a >= 2:
                sides[side].append(_cut(trial, a, b))
        offset += len(trial)
    if not sides[0] or not sides[1]:
        raise DatasetError(f"{source}: split_by_time: one side has no piece of 2 samples or more")
    return recording.with_trials(sides[0]), recording.with_trials(sides[1])


def split_by_sample(recording: Recording, fraction: float = 0.8, *,
                    seed: int | None = None) -> tuple[Recording, Recording]:
    """(estimation, validation): the published split, a random ``fraction`` of the samples to estimation.

    A dynamic model needs evenly sampled series, so both sides keep every trial whole: on the
    estimation side the outputs of the held-out samples are filled by linear interpolation of
    the kept samples around them (which is exactly how the neighbours leak); on the validation
    side only the held-out samples are scored. Warns with :class:`~softtip.data.LeakageWarning`.
    """
    groups = np.concatenate([np.full(len(trial), k) for k, trial in enumerate(recording.trials)])
    kept = sample_mask(groups, fraction, seed, "split_by_sample", "use split_by_trial or split_by_time")
    estimation, validation = [], []
    for k, trial in enumerate(recording.trials):
        mask = kept[groups == k]
        index = np.arange(len(trial))
        if mask.any():
            filled = trial.y.copy()
            for column in range(filled.shape[1]):
                filled[:, column] = np.interp(index, index[mask], trial.y[mask, column])
            estimation.append(replace(trial, y=filled, scored=None))
        if not mask.all():
            validation.append(replace(trial, scored=~mask if trial.scored is None else trial.scored & ~mask))
    return recording.with_trials(estimation), recording.with_trials(validation)
