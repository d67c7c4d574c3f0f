"""Recordings for system identification: evenly sampled inputs and outputs, trial by trial.

A :class:`Recording` holds the sample time, the input and output channel names and units, and
its trials (:class:`Trial`: u (N, nu) and y (N, ny), the trial id in the source, where in that
trial it starts, and optionally which samples are scored). It comes from a softtip
:class:`~softtip.data.Dataset` (any channels and numeric labels), from a CSV file or from a plain
Parquet file (:func:`read_recording`), or from arrays (:meth:`Recording.from_arrays`).

The sample time comes from the time column (``time_s`` by default) or is given; steps that
differ from it by more than ``time_tolerance`` (a fraction of the sample time) are refused, as
are a given sample time that disagrees with the time column, non-finite values, unknown columns
and text where numbers are expected; every refusal is one :class:`~softtip.data.DatasetError`
line naming the file and the column.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from softtip._core.archive import hash_arrays
from softtip._core.config import OpenFraction, PositiveNumber, checked
from softtip._core.files import not_a_file
from softtip.data.csvload import parse_numbers, read_csv_table
from softtip.data.dataset import (
    TIME,
    TRIAL,
    Dataset,
    DatasetError,
    column_to_numpy,
    first_line,
    is_dataset_file,
    require_columns,
    trial_runs,
)
from softtip.sysid.textfile import SUFFIXES as WHITESPACE
from softtip.sysid.textfile import text_columns

DETRENDS = ("none", "mean", "linear")
READABLE = (".csv", ".parquet", *WHITESPACE)
# the magnitudes whose squares and sums of squares stay normal doubles; the smallest relative
# variation that is more than rounding
MAGNITUDE_RANGE, ROUNDING = (1e-150, 1e150), 1e-12


@dataclass(frozen=True, eq=False)
class Trial:
    """One evenly sampled run: inputs ``u`` (N, nu), outputs ``y`` (N, ny).

    ``id`` is the trial's id in the source, ``start`` the index of its first sample there (a trial
    cut by a time split starts later); ``scored`` marks the samples that count in metrics (None:
    all of them).
    """

    u: np.ndarray
    y: np.ndarray
    id: int = 0
    start: int = 0
    scored: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.u)


@dataclass(frozen=True)
class Resampling:
    """What resampling onto an even grid did to a recording: ``before`` samples at a median step of
    ``median_step`` (the longest ``longest_step``; ``gaps`` steps longer than 1.5 sample times, bridged by
    straight lines) became ``after`` samples every ``ts`` s, linearly interpolated within each trial."""

    ts: float
    before: int
    after: int
    median_step: float
    longest_step: float
    gaps: int

    def to_dict(self) -> dict:
        return {"ts": self.ts, "samples_before": self.before, "samples_after": self.after,
                "median_step": self.median_step, "longest_step": self.longest_step, "gaps_bridged": self.gaps,
                "method": "linear interpolation within each trial", "note": self.describe()}

    def describe(self) -> str:
        return (f"resampled every {self.ts:g} s by linear interpolation within each trial: {self.before} samples "
                f"at a median step of {self.median_step:g} s (longest {self.longest_step:g} s; {self.gaps} "
                f"steps longer than {1.5 * self.ts:g} s bridged by straight lines) became {self.after}")


def resample(source: str, column: str, trial: np.ndarray, time: np.ndarray, columns: Mapping[str, np.ndarray],
             ts: float) -> tuple[np.ndarray, dict[str, np.ndarray], Resampling]:
    """Every column of ``columns`` linearly interpolated, trial by trial, at ``ts`` from each trial's first
    time stamp to its last: the new trial ids, the new columns and what was done. Times must increase
    within a trial (a repeated or earlier stamp is refused, naming its row)."""
    ts = checked(PositiveNumber, f"{source}: resample", ts, DatasetError)
    starts, lengths = trial_runs(trial)
    ids, grids, steps = [], [], []
    for a, n in zip(starts, lengths, strict=True):
        times = time[a:a + n]
        step = np.diff(times)
        if np.any(step <= 0):
            row = a + 1 + int(np.argmax(step <= 0))
            raise DatasetError(f"{source}: column {column!r}: time does not increase at row {row} "
                               f"(trial {trial[a]}): cannot resample")
        grid = times[0] + ts * np.arange(int(np.floor((times[-1] - times[0]) / ts * (1 + 1e-12))) + 1)
        grids.append((a, n, grid))
        ids.append(np.full(len(grid), trial[a]))
        steps.append(step)
    values = {name: np.concatenate([np.interp(grid, time[a:a + n], np.asarray(data[a:a + n], dtype=np.float64))
                                    for a, n, grid in grids]) for name, data in columns.items()}
    every = np.concatenate(steps)
    if every.size == 0:
        raise DatasetError(f"{source}: no trial has two samples: nothing to resample")
    done = Resampling(float(ts), len(trial), sum(len(grid) for *_, grid in grids), float(np.median(every)),
                      float(every.max()), int(np.sum(every > 1.5 * ts)))
    return np.concatenate(ids), values, done


def _names(value: Any, count: int, default: str, what: str, source: str) -> tuple[str, ...]:
    if value is None:
        return tuple(f"{default}{k}" for k in range(count))
    if isinstance(value, str):
        value = [value]
    names = tuple(value)
    if len(names) != count or not all(isinstance(name, str) for name in names):
        raise DatasetError(f"{source}: {what}: expected {count} names, got {value!r}")
    return names


def _units(value: Any, count: int, what: str, source: str) -> tuple[str, ...]:
    if value is None or value == ():
        return ("",) * count
    if isinstance(value, str):
        return (value,) * count
    units = tuple(value)
    if len(units) != count or not all(isinstance(unit, str) for unit in units):
        raise DatasetError(f"{source}: {what}: expected a unit or {count} units, got {value!r}")
    return units


def _columns(values: Any) -> np.ndarray:
    """Samples of one channel (1-D) as a column; anything else as given, for the recording to check."""
    values = np.asarray(values, dtype=np.float64)
    return values[:, None] if values.ndim == 1 else values


@dataclass(frozen=True, eq=False)
class Recording:
    """Trials of one system's inputs and outputs at one sample time ``ts`` (s); validated, read-only.

    A recording without outputs (``outputs`` empty) can be simulated, not identified or scored.
    """

    ts: float
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    trials: tuple[Trial, ...]
    input_units: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()
    source: str = "arrays"
    detrended: str = "none"
    resampled: Resampling | None = None

    def __post_init__(self):
        source = self.source
        object.__setattr__(self, "ts", float(checked(PositiveNumber, f"{source}: ts", self.ts, DatasetError)))
        inputs, outputs = tuple(self.inputs), tuple(self.outputs)
        if not inputs:
            raise DatasetError(f"{source}: inputs: expected at least one name")
        for role, names in (("inputs", inputs), ("outputs", outputs)):
            if not all(isinstance(name, str) and name for name in names):
                raise DatasetError(f"{source}: {role}: expected non-empty names, got {names!r}")
        everything = inputs + outputs
        repeated = sorted({name for name in everything if everything.count(name) > 1})
        if repeated:
            raise DatasetError(f"{source}: column {repeated[0]!r} is named more than once among inputs and outputs")
        if self.detrended not in DETRENDS:
            raise DatasetError(f"{source}: detrended: expected one of {', '.join(DETRENDS)}, got {self.detrended!r}")
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "outputs", outputs)
        object.__setattr__(self, "input_units", _units(self.input_units, len(inputs), "input_units", source))
        object.__setattr__(self, "output_units", _units(self.output_units, len(outputs), "output_units", source))
        trials = tuple(self.trials)
        if not trials:
            raise DatasetError(f"{source}: no trials")
        object.__setattr__(self, "trials", tuple(self._checked(trial) for trial in trials))

    def _checked(self, trial: Trial) -> Trial:
        where = f"{self.source}: trial {trial.id}"
        u, y = np.array(trial.u, dtype=np.float64), np.array(trial.y, dtype=np.float64)
        for role, values, names in (("u", u, self.inputs), ("y", y, self.outputs)):
            if values.ndim != 2 or values.shape[1] != len(names):
                raise DatasetError(f"{where}: {role}: expected shape (samples, {len(names)}), got {values.shape}")
            bad = ~np.isfinite(values)
            if bad.any():
                row, column = np.argwhere(bad)[0]
                raise DatasetError(f"{where}: column {names[column]!r}, sample {trial.start + row}: "
                                   f"{values[row, column]} is not a finite number")
        if len(u) != len(y):
            raise DatasetError(f"{where}: {len(u)} input samples but {len(y)} output samples")
        if len(u) < 2:
            raise DatasetError(f"{where}: {len(u)} sample(s); a trial needs at least 2")
        scored = None
        if trial.scored is not None:
            scored = np.array(trial.scored, dtype=bool)
            if scored.shape != (len(u),):
                raise DatasetError(f"{where}: scored: expected {len(u)} flags, got shape {scored.shape}")
            scored.setflags(write=False)
        for values in (u, y):
            values.setflags(write=False)
        return Trial(u, y, int(trial.id), int(trial.start), scored)

    # -- construction ------------------------------------------------------

    @classmethod
    def from_arrays(cls, u: Any, y: Any, ts: float, *, inputs: Sequence[str] | None = None,
                    outputs: Sequence[str] | None = None, input_units: Any = None, output_units: Any = None,
                    source: str = "arrays") -> Recording:
        """A recording of one trial (u (N, nu), y (N, ny); 1-D for one channel) or of several (lists of
        such arrays, one per trial). Channels are named u0, u1 ... and y0, y1 ... unless named."""
        several = isinstance(u, (list, tuple))
        if several != isinstance(y, (list, tuple)) or (several and len(u) != len(y)):
            raise DatasetError(f"{source}: u and y: expected two arrays, or two lists of as many arrays")
        pairs = list(zip(u, y, strict=True)) if several else [(u, y)]
        trials = [Trial(_columns(a), _columns(b), k) for k, (a, b) in enumerate(pairs)]
        nu, ny = (np.shape(trials[0].u)[1:] or (1,))[0], (np.shape(trials[0].y)[1:] or (1,))[0]
        return cls(ts, _names(inputs, nu, "u", "inputs", source), _names(outputs, ny, "y", "outputs", source),
                   tuple(trials), input_units, output_units, source)

    @classmethod
    def from_dataset(cls, dataset: Dataset, inputs: Sequence[str], outputs: Sequence[str], *,
                     ts: float | None = None, time_tolerance: float = 0.02, source: str = "dataset") -> Recording:
        """The dataset's channels or numeric labels ``inputs`` and ``outputs``, trial by trial; the sample
        time from its ``time_s`` column (checked against ``ts`` when given)."""
        units = {**dataset.channel_units, **dataset.labels}
        for name in (*inputs, *outputs):
            if name in dataset.conditions:
                raise DatasetError(f"{source}: {name!r} is a condition (constant over each trial), not a signal")
            if name not in units:
                raise DatasetError(f"{source}: no channel or label {name!r} "
                                   f"(channels and labels: {', '.join(units)})")
            if dataset.columns[name].dtype.kind not in "biuf":
                raise DatasetError(f"{source}: label {name!r} holds text, expected numbers")
        return _assemble(source, dataset.groups, dataset.columns[TIME], dataset.columns, list(inputs), list(outputs),
                         [units[name] for name in inputs], [units[name] for name in outputs], ts, time_tolerance)

    # -- structure ---------------------------------------------------------

    @property
    def n_inputs(self) -> int:
        return len(self.inputs)

    @property
    def n_outputs(self) -> int:
        return len(self.outputs)

    @property
    def n_samples(self) -> int:
        return sum(len(trial) for trial in self.trials)

    @property
    def segments(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(u, y) of every trial."""
        return [(trial.u, trial.y) for trial in self.trials]

    def time(self, index: int) -> np.ndarray:
        """The time stamps (s) of trial ``index``, from the start of its source trial."""
        trial = self.trials[index]
        return (trial.start + np.arange(len(trial))) * self.ts

    @cached_property
    def sha256(self) -> str:
        """Hex digest of the sample time and every trial's arrays (see :func:`softtip._core.archive.hash_arrays`)."""
        digest = hashlib.sha256(np.float64(self.ts).tobytes())
        hash_arrays(digest, {f"{k:06d}/{role}": getattr(trial, role)
                             for k, trial in enumerate(self.trials) for role in ("u", "y")})
        return digest.hexdigest()

    def describe(self) -> dict:
        """What a model file keeps of the data it was identified on."""
        return {"source": self.source, "ts": self.ts, "inputs": list(self.inputs), "outputs": list(self.outputs),
                "input_units": list(self.input_units), "output_units": list(self.output_units),
                "trials": len(self.trials), "samples": self.n_samples, "detrended": self.detrended,
                "resampled": None if self.resampled is None else self.resampled.to_dict(), "sha256": self.sha256}

    # -- derived recordings ---------------------------------------------------

    def with_trials(self, trials: Sequence[Trial], source: str | None = None) -> Recording:
        return replace(self, trials=tuple(trials), source=self.source if source is None else source)

    def select(self, indices: Sequence[int]) -> Recording:
        """The trials at ``indices`` (positions in :attr:`trials`)."""
        return self.with_trials([self.trials[k] for k in indices])

    def detrend(self, kind: str) -> Recording:
        """Every trial's inputs and outputs less their mean (``"mean"``) or least-squares line (``"linear"``).

        A model identified on detrended data runs on data detrended the same way.
        """
        if kind not in ("mean", "linear"):
            raise DatasetError(f"detrend: expected 'mean' or 'linear', got {kind!r}")
        import scipy.signal  # only here: it takes a third of a second to import

        how = "constant" if kind == "mean" else "linear"
        trials = [replace(trial, u=scipy.signal.detrend(trial.u, axis=0, type=how),
                          y=scipy.signal.detrend(trial.y, axis=0, type=how)) for trial in self.trials]
        detrended = "linear" if "linear" in (kind, self.detrended) else "mean"
        return replace(self, trials=tuple(trials), detrended=detrended)

    # -- checks before identification ---------------------------------------

    def require_excitation(self) -> None:
        """Refuses, in one line naming the channel, a recording without outputs, or with a channel that
        cannot be identified in double precision: constant, varying only at the level of its rounding
        (less than 1e-12 of its magnitude), or of magnitude beyond [1e-150, 1e150] (its squares, which
        every estimator sums, would underflow or overflow: rescale it, i.e. change its unit)."""
        if not self.outputs:
            raise DatasetError(f"{self.source}: no outputs: nothing to identify")
        u = np.concatenate([trial.u for trial in self.trials])
        y = np.concatenate([trial.y for trial in self.trials])
        for role, values, names in (("input", u, self.inputs), ("output", y, self.outputs)):
            magnitudes, spreads = np.max(np.abs(values), axis=0), np.ptp(values, axis=0)
            for name, magnitude, spread, first in zip(names, magnitudes, spreads, values[0], strict=True):
                where = f"{self.source}: {role} {name!r}"
                if spread == 0:
                    raise DatasetError(f"{where} is constant ({first:g}) over the whole recording: "
                                       f"{'its effect' if role == 'input' else 'it'} cannot be identified")
                if magnitude > MAGNITUDE_RANGE[1] or magnitude < MAGNITUDE_RANGE[0]:
                    raise DatasetError(f"{where} reaches {magnitude:.3g}: outside [{MAGNITUDE_RANGE[0]:g}, "
                                       f"{MAGNITUDE_RANGE[1]:g}], where sums of squares stay finite and non-zero "
                                       "in double precision; rescale it (change its unit)")
                if spread <= ROUNDING * magnitude:
                    raise DatasetError(f"{where} varies by {spread:.3g} about {magnitude:.3g}: at the level of "
                                       "its rounding, not a signal that excites or responds")

    def require_samples(self, minimum: int, purpose: str) -> None:
        """Refuses a recording of fewer than ``minimum`` samples in all, naming ``purpose``."""
        if self.n_samples < minimum:
            raise DatasetError(f"{self.source}: {self.n_samples} samples, too few for {purpose} "
                               f"(needs at least {minimum})")


# ------------------------------------------------------------------------------------------- assembling


def sample_time(source: str, column: str, trial: np.ndarray, time: np.ndarray, ts: float | None,
                tolerance: float) -> float:
    """The sample time of the time column ``time`` (the median step within trials), refusing steps that
    differ from it, and a given ``ts`` that differs from it, by more than ``tolerance`` of it."""
    tolerance = checked(OpenFraction, "time_tolerance", tolerance, DatasetError)
    same = trial[1:] == trial[:-1]
    steps = np.diff(time)[same]
    if steps.size == 0:
        if ts is None:
            raise DatasetError(f"{source}: no trial has two samples: give the sample time")
        return ts
    step = float(np.median(steps))
    if not step > 0:
        raise DatasetError(f"{source}: column {column!r}: time does not increase (median step {step:g} s)")
    off = np.abs(steps - step) > tolerance * step
    if off.any():
        row = int(np.flatnonzero(same)[np.argmax(off)]) + 1
        raise DatasetError(f"{source}: column {column!r}: irregular sample times in trial {trial[row]}: a step of "
                           f"{steps[np.argmax(off)]:g} s at row {row}, the sample time is {step:g} s "
                           f"(tolerance {100 * tolerance:g} %): resample it onto an even grid (--resample SECONDS "
                           "on the command line, resample= in read_recording), which interpolates linearly")
    if ts is not None and abs(ts - step) > tolerance * step:
        raise DatasetError(f"{source}: the sample time given, {ts:g} s, does not match the {step:g} s of "
                           f"column {column!r}")
    return step if ts is None else ts


def _assemble(source: str, trial: np.ndarray, time: np.ndarray | None, columns: Mapping[str, np.ndarray],
              inputs: list[str], outputs: list[str], input_units: Any, output_units: Any, ts: float | None,
              tolerance: float, time_column: str = TIME, resample_ts: float | None = None) -> Recording:
    """A recording from per-row columns: trial ids (rows of a trial contiguous), times or None, signals;
    resampled at ``resample_ts`` when given."""
    if ts is not None:
        ts = checked(PositiveNumber, f"{source}: ts", ts, DatasetError)
    starts, lengths = trial_runs(trial)
    ids, counts = np.unique(trial[starts], return_counts=True)
    if np.any(counts > 1):
        raise DatasetError(f"{source}: the rows of trial {ids[counts > 1][0]} are not contiguous")
    resampled = None
    if resample_ts is not None:
        if time is None:
            raise DatasetError(f"{source}: resample: needs a time column (the rows' time stamps)")
        if ts is not None:
            raise DatasetError(f"{source}: resample: give the new sample time or ts, not both")
        trial, columns, resampled = resample(source, time_column, trial, time,
                                             {name: columns[name] for name in (*inputs, *outputs)}, resample_ts)
        starts, lengths = trial_runs(trial)
        time, ts = None, resampled.ts
    if time is None:
        if ts is None:
            raise DatasetError(f"{source}: no time column: give the sample time")
    else:
        ts = sample_time(source, time_column, trial, time, ts, tolerance)
    u = np.column_stack([np.asarray(columns[name], dtype=np.float64) for name in inputs])
    y = np.column_stack([np.asarray(columns[name], dtype=np.float64) for name in outputs]) if outputs \
        else np.zeros((len(trial), 0))
    trials = [Trial(u[a:a + n], y[a:a + n], int(trial[a])) for a, n in zip(starts, lengths, strict=True)]
    return Recording(ts, tuple(inputs), tuple(outputs), tuple(trials), input_units, output_units, source,
                     resampled=resampled)


def _csv_columns(path: Path, wanted: list[str]) -> dict[str, np.ndarray]:
    table = read_csv_table(path, wanted, only=wanted)
    return {name: parse_numbers(path, name, table.column(name)) for name in wanted}


def _parquet_columns(path: Path, wanted: list[str]) -> dict[str, np.ndarray]:
    try:
        with pq.ParquetFile(path) as parquet:  # not read_table: it loads pyarrow.dataset, and with it pandas
            table = parquet.read(columns=wanted)
    except (pa.ArrowException, OSError) as problem:
        raise DatasetError(f"{path}: unreadable Parquet data ({first_line(problem)})") from None
    values = {}
    for name in wanted:
        column = table.column(name)
        if not (pa.types.is_integer(column.type) or pa.types.is_floating(column.type)
                or pa.types.is_boolean(column.type)):
            raise DatasetError(f"{path}: column {name!r} holds {column.type} values, expected numbers")
        values[name] = column_to_numpy(repr(name), column)
    return values


def _suffix(path: Path) -> str:
    problem = not_a_file(path)
    if problem:
        raise DatasetError(f"recording {path} {problem}")
    suffix = path.suffix.lower()
    if suffix not in READABLE:
        raise DatasetError(f"recording {path}: expected a .csv, .parquet, or whitespace-separated "
                           f"{' or '.join(WHITESPACE)} file")
    return suffix


def file_columns(path: str | os.PathLike, names: Sequence[str] | None = None) -> list[str]:
    """The column names of a CSV (``.csv``), Parquet (``.parquet``) or whitespace-separated (``.dat``,
    ``.txt``) file; ``names`` those of a text file without a header."""
    path = Path(path)
    suffix = _suffix(path)
    if suffix in WHITESPACE or (suffix == ".csv" and names is not None):
        return list(text_columns(path, names, None if suffix in WHITESPACE else ","))
    if names is not None:
        raise DatasetError(f"{path}: column names are for a text file without a header (.csv, .dat, .txt)")
    try:
        return pacsv.open_csv(path).schema.names if suffix == ".csv" else pq.read_schema(path).names
    except (pa.ArrowException, OSError) as problem:
        kind = "CSV" if suffix == ".csv" else "Parquet"
        raise DatasetError(f"{path}: cannot be read as {kind} ({first_line(problem)})") from None


def read_recording(path: str | os.PathLike, inputs: Sequence[str], outputs: Sequence[str], *,
                   ts: float | None = None, time_column: str | None = None, trial_column: str | None = None,
                   units: Mapping[str, str] | None = None, time_tolerance: float = 0.02,
                   names: Sequence[str] | None = None, resample: float | None = None,
                   missing: float | None = None) -> Recording:
    """The columns ``inputs`` and ``outputs`` of a CSV file (``.csv``), a Parquet file (``.parquet``) or a
    whitespace-separated text file (``.dat``, ``.txt``: DaISy's files; ``names`` the columns of one
    without a header row, else they are named 1, 2 ... by position; a CSV file without a header row is
    read with ``names`` too).

    A softtip dataset file is read as a :class:`~softtip.data.Dataset` (its channels and labels, with
    their units). Any other file is read as plain columns: ``time_column`` (seconds; default ``time_s``
    when present, else ``ts`` must be given) and ``trial_column`` (integer ids, the rows of a trial
    contiguous; default ``trial`` when present, else one trial), ``units`` a mapping of column to unit.
    ``resample`` (s): irregular time stamps interpolated linearly onto that even grid, trial by trial
    (what was done is kept as the recording's ``resampled``). ``missing``: the value a logger writes for
    "no reading" (such as -1): a row holding it in a signal is dropped (then resample).
    """
    path = Path(path)
    suffix = _suffix(path)
    whitespace = text_columns(path, names, None if suffix in WHITESPACE else ",") \
        if suffix in WHITESPACE or (suffix == ".csv" and names is not None) else None
    present = list(whitespace) if whitespace is not None else file_columns(path, names)
    if suffix == ".parquet" and is_dataset_file(path):
        if time_column is not None or trial_column is not None or units is not None or resample is not None \
                or missing is not None:
            raise DatasetError(f"{path}: a softtip dataset names its own time, trial and units, and is evenly sampled")
        return Recording.from_dataset(Dataset.read(path), inputs, outputs, ts=ts, time_tolerance=time_tolerance,
                                      source=str(path))
    time_name = time_column if time_column is not None else (TIME if TIME in present else None)
    trial_name = trial_column if trial_column is not None else (TRIAL if TRIAL in present else None)
    own = [name for name in (time_name, trial_name) if name is not None]
    for name in (*inputs, *outputs):
        if name in own:
            raise DatasetError(f"{path}: column {name!r} is the time or trial column, not a signal")
    wanted = list(dict.fromkeys([*own, *inputs, *outputs]))
    require_columns(path, wanted, present)
    if whitespace is not None:
        columns = whitespace
    else:
        columns = (_csv_columns if suffix == ".csv" else _parquet_columns)(path, wanted)
    if trial_name is None:
        trial = np.zeros(len(columns[wanted[0]]), dtype=np.int64)
    else:
        ids = columns[trial_name]
        if not np.all(np.isfinite(ids) & (ids == np.round(ids))):
            raise DatasetError(f"{path}: trial column {trial_name!r} holds values that are not integers")
        trial = ids.astype(np.int64)
    units = dict(units or {})
    unknown = [name for name in units if name not in (*inputs, *outputs)]
    if unknown:
        raise DatasetError(f"{path}: units: {unknown[0]!r} is not an input or output")
    if missing is not None:
        kept = ~np.any([columns[name] == missing for name in (*inputs, *outputs)], axis=0)
        if not kept.any():
            raise DatasetError(f"{path}: every row holds the missing value {missing:g} in a signal")
        columns = {name: columns[name][kept] for name in wanted}
        trial = trial[kept]
    return _assemble(str(path), trial, None if time_name is None else columns[time_name], columns, list(inputs),
                     list(outputs), [units.get(name, "") for name in inputs], [units.get(name, "") for name in outputs],
                     ts, time_tolerance, time_name or TIME, resample)
