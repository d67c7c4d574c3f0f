"""A rig's delimited text logs into a softtip dataset (``softtip import``).

A mapping, written once as a small TOML file, says how a rig's logs become trials::

    [sensor]                      # the sensor log
    file = "sensor.csv"           # its name in each trial's folder
    header = false                # no header row: columns are numbered from 1
    time = 1                      # the time column, in time_unit (or rate_hz: evenly spaced)
    unit = "uT"                   # uT, mT, G, T, or counts (the chip's output words; need its settings)
                                  # chip: a registered sensor (default: the one that reads in unit), or
                                  # "other": any 3-axis sensor, named and in its own unit
    settings = { gain_sel = 1, res_xyz = [2, 2, 2] }  # the chips' settings, in the registered sensor's
                                  # schema (keys left out take its defaults): range checks follow them;
                                  # the old gain_sel, res_xyz, hallconf keys here read with a warning
    chips = [[2, 3, 4], [5, 6, 7]]  # each chip's columns, one per axis of its reading (x, y, z)

    [labels]                      # per-sample targets: in the sensor log, or a log of their own
    file = "states.csv"           # joined to the sensor log by nearest time, within tolerance_s
    header = false
    time = 1
    missing = -1                  # a value meaning "no reading in this row"
    tolerance_s = 0.02
    columns = { fz_N = { column = 5, unit = "g" } }   # grams on a scale, stored in newtons

    [trials]
    split = "file"                # one source per trial; or "column" (a trial id column), "gap" (gap_s)
    validation = { last = 1 }     # or { trials = [0, 3] }, or { fraction = 0.2 } (the last trials)
    baseline = { samples = 20 }   # each trial's first samples are its zero; or { seconds = 1.0 }, or
                                  # { label = "fz_N", below = 0.05 }: its samples at rest; per = "source":
                                  # one zero for all the trials of a source

A source is a file (the sensor log, labels in it) or a folder holding the mapping's files. A ``file``
may be a pattern (``file = "sensor-*.csv"``): a rig that rotates its logs writes one log in several
files, read as one in the order of their first times (each needs the time column; files that overlap
in time are refused). Labels are
converted to the unit their name ends in (``fz_N``: N) from the unit they were logged in; a label whose
name states no unit is kept in its logged unit. The dataset's conditions are ``role`` (calibration or
validation, what ``softtip calibrate`` splits by) and ``source`` (where each trial came from).

Its reader of delimited text is :func:`softtip.data.csvload.read_columns`, for any command that takes such files.
"""

from __future__ import annotations

import glob
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field, Strict

from softtip._core.channels import AXES, MAGNETIC
from softtip._core.systems import NotRegistered
from softtip._core.config import (Flag, OpenFraction, PositiveInteger, PositiveNumber, Refusal, Text, choice, expect,
                                  integer, parse, read_toml, schema)
from softtip._core.files import not_a_file
from softtip._core.units import FORCE_UNITS, MM, UM
from softtip.data.csvload import TIME_UNITS_IN_S, WHITESPACE, read_columns
from softtip.data.dataset import DIMENSIONLESS, TIME, TRIAL, Dataset, DatasetError, DatasetMetadata, trial_runs
from softtip.data.splits import CALIBRATION, VALIDATION
from softtip.sensors.registry import SensorKind, sensor_kind, sensor_kinds

STANDARD_GRAVITY = 9.80665  # m/s², the conventional value (3rd CGPM, 1901): a scale's grams as force
OTHER = "other"  # a sensor no system registered: named, in its own unit, its full scale given
WRITTEN = ("role", "source", "saturated")  # the columns an import writes besides channels and the mapping's labels
# Label units softtip converts between, by quantity: how many of the quantity's first unit one of each is.
LABEL_UNITS = (
    {**FORCE_UNITS, "kN": 1e3, "g": STANDARD_GRAVITY * 1e-3, "kg": STANDARD_GRAVITY, "lbf": 4.4482216152605},
    {"m": 1.0, "mm": MM, "um": UM},
    {"rad": 1.0, "deg": np.pi / 180},
)

ColumnRef = Annotated[Annotated[int, Strict()] | Annotated[str, Strict(), Field(min_length=1)],
                      expect("a column number from 1 (no header) or a header name")]
Delimiter = Annotated[str, Strict(), Field(min_length=1), expect(f"one character or {WHITESPACE!r}")]


@dataclass(frozen=True)
class _Log:
    """Where a log is and how its text is laid out."""

    file: Text | None = None
    header: Flag = True
    delimiter: Delimiter = ","
    time: ColumnRef | None = None
    time_unit: choice(*TIME_UNITS_IN_S) = "s"
    rate_hz: PositiveNumber | None = None

    def __post_init__(self) -> None:
        if self.delimiter != WHITESPACE and (len(self.delimiter) != 1 or self.delimiter in "0123456789.-+eE\"\n"):
            raise Refusal("delimiter", f"expected one character that is not part of a number, or {WHITESPACE!r}")
        for key, ref in self.columns_named():
            if isinstance(ref, int) and ref < 1:
                raise Refusal(key, f"column {ref}: columns are numbered from 1")
            if isinstance(ref, str) and not self.header:
                raise Refusal(key, f"column {ref!r} is named, but the file has no header: number it from 1")

    def columns_named(self) -> list[tuple[tuple, int | str]]:
        """Every column the log's settings name, each with the key that names it."""
        return [] if self.time is None else [(("time",), self.time)]

    def columns_used(self) -> list[int | str]:
        return [ref for _, ref in self.columns_named()]


@schema
class SensorLog(_Log):
    """The sensor log: each chip's columns (one per axis its reading has: x, y, z for a 3-axis chip),
    what chip it is and in what unit."""

    chips: Annotated[list[list[ColumnRef]], Field(min_length=1),
                     expect("a list of each chip's axis columns")] = field(default_factory=list)
    chip: Text | None = None
    unit: Text = "uT"
    name: Annotated[str, Strict(), Field(pattern=r"^[a-z][a-z0-9]*$"),
                    expect("a lower-case name (letters, then digits)")] | None = None
    full_scale: PositiveNumber | None = None
    settings: dict[str, Any] | None = None  # the chips' settings, read by the registered sensor's schema

    def __post_init__(self) -> None:
        if not self.chips:
            raise Refusal("chips", "expected a list of each chip's axis columns")
        super().__post_init__()
        if (self.time is None) == (self.rate_hz is None):
            raise Refusal("time", "give the time column or rate_hz (evenly spaced samples), one of them")
        if any(len(chip) != len(self.axes) for chip in self.chips):
            raise Refusal("chips", f"expected a list of [{', '.join(self.axes)}] columns, one per chip")
        if self.chip == OTHER:
            if self.name is None or self.settings is not None:
                raise Refusal("name", "chip = \"other\" needs a name for its channels, and takes no chip settings")
            return
        kind = self.kind
        if self.unit not in (*kind.reading.units, kind.raw_unit):
            raise Refusal("unit", f"the {kind.name} reads in {', '.join(kind.reading.units)} or {kind.raw_unit}; "
                                  "another sensor is chip = \"other\"")
        if self.unit == kind.raw_unit and self.settings is None:
            raise Refusal("settings", f"raw {kind.raw_unit} need the chips' settings to be read as "
                                      f"{kind.reading.quantity}")
        if self.name is not None or self.full_scale is not None:
            raise Refusal("name" if self.name is not None else "full_scale",
                          f"the {kind.name}'s channels and range follow from the chip: give it for chip = \"other\"")
        if self.settings is not None:
            try:
                kind.settings_from(self.settings)
            except ValueError as refusal:
                raise Refusal("settings", f"not the {kind.title or kind.name}'s settings ({refusal})") from None

    def columns_named(self) -> list[tuple[tuple, int | str]]:
        return [*super().columns_named(), *((("chips", k, a), ref) for k, chip in enumerate(self.chips)
                                             for a, ref in enumerate(chip))]

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes each chip's columns hold: its registered reading's (x, y, z for another chip)."""
        return AXES if self.chip == OTHER else self.kind.reading.axes

    @property
    def kind(self) -> SensorKind:
        """The registered sensor: the one named, or the one that reads in the log's unit."""
        if self.chip is not None:
            try:
                return sensor_kind(self.chip)
            except NotRegistered as problem:
                raise Refusal("chip", f"{problem} or \"other\"") from None
        reading_in = [kind for kind in sensor_kinds().values() if self.unit in (*kind.reading.units, kind.raw_unit)]
        if len(reading_in) != 1:
            raise Refusal("unit", f"{'several registered sensors read' if reading_in else 'no registered sensor reads'} "
                                  f"in {self.unit}: name it as chip (or chip = \"other\")")
        return reading_in[0]

    @property
    def chip_settings(self) -> Any:
        """The chips' declared settings, in the registered sensor's schema, if any."""
        return None if self.chip == OTHER or self.settings is None else self.kind.settings_from(self.settings)

    def channel(self, chip: int, axis: str) -> str:
        if self.chip != OTHER:
            return self.kind.reading.channel_name(chip, axis)
        return f"{self.name}{chip}_{axis}_{self.unit}"


@schema
class LabelColumn:
    column: ColumnRef
    unit: Text


@schema
class LabelLog(_Log):
    """Per-sample targets: in the sensor log (no file) or a log of their own, joined by nearest time."""

    columns: Annotated[dict[str, LabelColumn], Field(min_length=1),
                       expect("a table of label = { column, unit }")] = field(default_factory=dict)
    missing: Annotated[float, Strict(), expect("a number")] | None = None
    tolerance_s: PositiveNumber | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.columns:
            raise Refusal("columns", "expected a table of label = { column, unit }")
        if (self.file is None) != (self.tolerance_s is None):
            raise Refusal("tolerance_s", "a label log of its own is joined by nearest time within tolerance_s "
                                         "(and only then)")
        if self.file is not None and (self.time is None or self.rate_hz is not None):
            raise Refusal("time", "a label log of its own is joined by time: give its time column (not rate_hz)")
        if self.file is None and (self.time is not None or self.rate_hz is not None):
            raise Refusal("time", "labels in the sensor log share its time: give time only with a label file")
        for name, label in self.columns.items():
            if not name.isidentifier() or name in (TRIAL, TIME, *WRITTEN) or MAGNETIC.is_channel(name):
                raise Refusal("columns", f"{name!r}: expected a label name (letters, digits, underscores) "
                                         "that is not a channel or a column softtip writes")
            stored_unit(name, label.unit)

    def columns_named(self) -> list[tuple[tuple, int | str]]:
        return [*super().columns_named(), *((("columns", name, "column"), label.column)
                                             for name, label in self.columns.items())]


@schema
class Validation:
    """Which trials validate: the last few, these ids, or the last fraction of them."""

    last: PositiveInteger | None = None
    trials: Annotated[list[integer(0)], Field(min_length=1), expect("a list of trial numbers")] | None = None
    fraction: OpenFraction | None = None

    def __post_init__(self) -> None:
        if sum(value is not None for value in (self.last, self.trials, self.fraction)) != 1:
            raise Refusal("last", "give one of last, trials and fraction")

    def chosen(self, n_trials: int) -> np.ndarray:
        """Whether each of ``n_trials`` trials validates; at least one trial is left to calibrate on."""
        if self.trials is not None:
            beyond = [trial for trial in self.trials if trial >= n_trials]
            if beyond:
                raise DatasetError(f"validation.trials: there is no trial {beyond[0]} "
                                   f"(the {n_trials} trials are numbered from 0)")
            chosen = np.isin(np.arange(n_trials), self.trials)
        else:
            count = self.last if self.last is not None else int(np.floor(self.fraction * n_trials + 0.5))
            if count < 1:
                raise DatasetError(f"validation.fraction = {self.fraction}: none of the {n_trials} trials validates")
            chosen = np.arange(n_trials) >= n_trials - count
        if chosen.all():
            given = next(f"{key} = {value}" for key, value in (("last", self.last), ("trials", self.trials),
                                                                ("fraction", self.fraction)) if value is not None)
            raise DatasetError(f"validation.{given}: all {n_trials} trials would validate, none would calibrate")
        return chosen


@schema
class Baseline:
    """Each trial's zero: the mean of its first samples, of its first seconds, or of its samples at rest
    (those whose ``label``, in the unit it is stored in, is below ``below``: the reference says nothing
    presses); ``per = "source"`` takes one zero per source for all its trials (trials split from one
    recording at gaps or by a column, which need not start at rest)."""

    samples: PositiveInteger | None = None
    seconds: PositiveNumber | None = None
    label: Annotated[str, Strict(), Field(min_length=1), expect("a label's name")] | None = None
    below: Annotated[float, Strict(), Field(allow_inf_nan=False), expect("a number")] | None = None
    per: choice("trial", "source") = "trial"

    def __post_init__(self) -> None:
        if (self.label is None) != (self.below is None):
            raise Refusal("label", "the rest rule takes a label and the value it is below at rest, both")
        if sum(value is not None for value in (self.samples, self.seconds, self.label)) != 1:
            raise Refusal("samples", "give samples, seconds, or label and below: one rule")


@schema
class Trials:
    split: choice("file", "column", "gap") = "file"
    column: ColumnRef | None = None
    gap_s: PositiveNumber | None = None
    validation: Validation | None = None
    baseline: Baseline | None = None

    def __post_init__(self) -> None:
        if (self.split == "column") != (self.column is not None):
            raise Refusal("column", "the trial column is given with split = \"column\" (and only then)")
        if (self.split == "gap") != (self.gap_s is not None):
            raise Refusal("gap_s", "the gap is given with split = \"gap\" (and only then)")


@schema
class ImportMapping:
    """How a rig's logs become a softtip dataset (see the module notes)."""

    sensor: SensorLog
    labels: LabelLog | None = None
    trials: Trials = field(default_factory=Trials)
    description: Annotated[str, Strict(), expect("a string")] = ""

    def __post_init__(self) -> None:
        if isinstance(self.trials.column, str) and not self.sensor.header:
            raise Refusal("trials", f"column {self.trials.column!r} is named, but the sensor log has no header")
        rest = self.trials.baseline.label if self.trials.baseline is not None else None
        if rest is not None and (self.labels is None or rest not in self.labels.columns):
            raise Refusal("trials", f"baseline.label = {rest!r} is not one of the mapping's labels")
        if self.trials.split == "gap" and self.sensor.time is None:
            raise Refusal("trials", "split = \"gap\" needs the sensor log's time column")


def load_mapping(path: str | os.PathLike) -> ImportMapping:
    """A mapping file, validated: a mistake is one line naming the file and the key."""
    return mapping_from(read_toml(path, "import mapping", DatasetError), str(path))


def mapping_from(document: Any, source: str) -> ImportMapping:
    """A mapping from its tables (a parsed file, edited by options), validated; ``source`` names it in errors."""
    return parse(ImportMapping, _settings_moved(document, source), source, error=DatasetError)


class DeprecatedMappingKey(FutureWarning):
    """A key of an import mapping that softtip still reads, written another way now."""


# the Hall chip's settings as a mapping's [sensor] table stated them before they became a table in the
# registered sensor's schema (sensor.settings): a lab's existing files keep working, with a warning
_OLD_SETTINGS = ("gain_sel", "res_xyz", "hallconf")


def _settings_moved(document: Any, source: str) -> Any:
    """``document`` with the old top-level chip settings of its [sensor] table moved into its settings table,
    and one warning naming them; settings given both ways are refused."""
    sensor = document.get("sensor") if isinstance(document, dict) else None
    old = [key for key in _OLD_SETTINGS if isinstance(sensor, dict) and key in sensor]
    if not old:
        return document
    settings = sensor.get("settings", {})
    if not isinstance(settings, dict) or set(old) & set(settings):
        twice = old[0] if not isinstance(settings, dict) else sorted(set(old) & set(settings))[0]
        raise DatasetError(f"{source}: sensor.{twice}: given beside sensor.settings; expected it in sensor.settings "
                           "only")
    moved = {key: sensor[key] for key in old}
    written = ", ".join(f"{key} = {_toml(value)}" for key, value in moved.items())
    warnings.warn(f"{source}: sensor.{', sensor.'.join(old)}: deprecated; write sensor.settings = {{ {written} }}",
                  DeprecatedMappingKey, stacklevel=3)
    rest = {key: value for key, value in sensor.items() if key not in old}
    return {**document, "sensor": {**rest, "settings": {**settings, **moved}}}


def _toml(value: Any) -> str:
    """A setting's value as TOML writes it (integers and lists of them, booleans)."""
    if isinstance(value, bool):
        return str(value).lower()
    return f"[{', '.join(map(_toml, value))}]" if isinstance(value, list) else repr(value)


def stored_unit(name: str, unit: str) -> str:
    """The unit label ``name`` is stored in: the unit its name ends in, if softtip converts ``unit`` into it."""
    named = name.rsplit("_", 1)[-1] if "_" in name else None
    for family in LABEL_UNITS:
        if named in family:
            if unit not in family:
                raise DatasetError(f"label {name}: its name says {named}, and {unit!r} is not a unit of that "
                                   f"quantity softtip converts ({', '.join(family)})")
            return named
    return unit


def _label_factor(name: str, unit: str) -> float:
    stored = stored_unit(name, unit)
    family = next((family for family in LABEL_UNITS if stored in family), None)
    return 1.0 if family is None else family[unit] / family[stored]


def _times(log: _Log, values: np.ndarray) -> np.ndarray:
    """A log's times in seconds from its rows ``values`` (the time column first, if it has one), or
    evenly spaced at rate_hz."""
    if log.time is None:
        return np.arange(len(values)) / log.rate_hz
    return values[:, 0] * TIME_UNITS_IN_S[log.time_unit]


# ---------------------------------------------------------------------------------------------- the import


@dataclass(frozen=True)
class ImportReport:
    """What an import did, for the command's summary."""

    trials: int
    samples: int
    validation_trials: list[int]
    unlabelled_dropped: int  # sensor rows with no label reading within the tolerance
    saturated: dict[str, int]  # channel -> samples at the declared sensor's limit
    join_offset_s: float | None  # the largest |sensor time - label time| of the rows kept


def log_files(source: Path, mapping: ImportMapping) -> tuple[list[Path], list[Path] | None]:
    """The pieces of the sensor log and of the label log (None: labels in the sensor log) of one source:
    one file each, or every file of the source's folder a pattern in ``file`` matches (a rig that
    rotates its logs), in no particular order (:func:`_read_log` puts them in time order)."""
    labels = mapping.labels
    separate = labels is not None and labels.file is not None
    if source.is_dir():
        if mapping.sensor.file is None:
            raise DatasetError(f"{source}: a folder, but the mapping names no sensor.file to read in it")
        return (_pieces(source, mapping.sensor, "sensor"),
                _pieces(source, labels, "labels") if separate else None)
    if separate:
        raise DatasetError(f"{source}: a file, but the labels are in a log of their own ({labels.file}): "
                           "give the folder holding both")
    return [source], None


def _pieces(folder: Path, log: _Log, table: str) -> list[Path]:
    """The files of ``folder`` that a log's ``file`` names: itself, or every match of its pattern."""
    if not glob.has_magic(log.file):
        return [folder / log.file]
    found = sorted(path for path in folder.glob(log.file) if path.is_file())
    if not found:
        raise DatasetError(f"{folder}: {table}.file = {log.file!r} matches no file")
    if len(found) > 1 and log.time is None:
        raise DatasetError(f"{folder}: {table}.file = {log.file!r} matches {len(found)} files: a log in several "
                           "files needs its time column to put them in order")
    return found


def _read_log(paths: list[Path], log: _Log, refs: list[int | str], *,
              strictly: bool) -> list[tuple[Path, np.ndarray]]:
    """Each piece of a log with its ``refs`` columns (the time column first, if the log has one), the
    pieces in time order; a piece that starts before the one ahead of it ends (or, ``strictly``, as it
    ends) is refused naming both."""
    pieces = [(path, read_columns(path, refs, header=log.header, delimiter=log.delimiter)) for path in paths]
    if len(pieces) == 1:
        return pieces
    for path, values in pieces:
        if not len(values):
            raise DatasetError(f"{path}: no rows")
    pieces.sort(key=lambda piece: piece[1][0, 0])
    for (before, earlier), (path, later) in zip(pieces[:-1], pieces[1:]):
        if later[0, 0] < earlier[-1, 0] or (strictly and later[0, 0] == earlier[-1, 0]):
            raise DatasetError(f"{path}: starts at time {float(later[0, 0])}, before {before} ends "
                               f"({float(earlier[-1, 0])}): the files of one log must follow each other in time")
    return pieces


def _sensor_values(path: Path, sensor: SensorLog, values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The chips' readings (rows, chips, axes) in the stored unit, and which samples are saturated
    (None: the sensor's limits are unknown)."""
    readings = values.reshape(len(values), len(sensor.chips), len(sensor.axes))
    settings = sensor.chip_settings
    if sensor.chip == OTHER:
        if sensor.full_scale is None:
            return readings, None
        beyond = np.abs(readings) > sensor.full_scale
        if beyond.any():
            _refuse_beyond(path, sensor, beyond, f"its full scale {sensor.full_scale:g} {sensor.unit}")
        return readings, np.abs(readings) >= sensor.full_scale
    kind = sensor.kind
    if sensor.unit == kind.raw_unit:
        words = 1 << kind.raw_bits
        whole = np.isfinite(readings) & (readings == np.round(readings)) & (readings >= 0) & (readings < words)
        if not whole.all():
            _refuse_beyond(path, sensor, ~whole, f"a {kind.raw_bits}-bit output word (an integer 0..{words - 1})")
        return kind.decode(settings, readings.astype(np.int64))
    readings = readings * kind.reading.units[sensor.unit]
    if settings is None:
        return readings, None
    beyond = kind.beyond(readings, settings)  # a step's rounding in the host's conversion is allowed
    if beyond.any():
        _refuse_beyond(path, sensor, beyond, f"the {kind.name}'s range at the declared settings")
    return readings, kind.saturated(readings, settings)


def _refuse_beyond(path: Path, sensor: SensorLog, where: np.ndarray, what: str) -> None:
    row, chip, axis = (int(k) for k in np.argwhere(where)[0])
    raise DatasetError(f"{path}: line {row + (2 if sensor.header else 1)}, column {sensor.chips[chip][axis]} "
                       f"(chip {chip} {sensor.axes[axis]}): beyond {what}")


def _check_time_order(path: Path, log: _Log, time: np.ndarray, ids: np.ndarray, *, strictly: bool) -> None:
    """Refuses, naming the line, a time that is not a number or that goes back (or, ``strictly``, stays)
    within a trial."""
    first = 2 if log.header else 1
    if not np.all(np.isfinite(time)):
        raise DatasetError(f"{path}: line {np.flatnonzero(~np.isfinite(time))[0] + first}, column {log.time}: "
                           "the time is not a finite number")
    step = np.diff(time)
    wrong = (step <= 0 if strictly else step < 0) & (ids[1:] == ids[:-1])
    if wrong.any():
        raise DatasetError(f"{path}: line {np.flatnonzero(wrong)[0] + 1 + first}, column {log.time}: the time "
                           f"{'does not increase' if strictly else 'goes back'}; expected a log in time order")


def _join(path: Path, labels: LabelLog, sensor_time: np.ndarray, label_time: np.ndarray,
          label_values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sensor rows kept, their labels, |time offset|): each sensor row takes the label row nearest in
    time whose every label is a reading, if it lies within the tolerance; ``label_time`` in order."""
    valid = np.all(np.isfinite(label_values), axis=1)
    if labels.missing is not None:
        valid &= ~np.any(label_values == labels.missing, axis=1)
    label_time, label_values = label_time[valid], label_values[valid]
    if label_time.size == 0:
        raise DatasetError(f"{path}: no row holds a reading of every label")
    after = np.clip(np.searchsorted(label_time, sensor_time), 1, max(len(label_time) - 1, 1))
    before = after - 1
    after = np.minimum(after, len(label_time) - 1)
    nearest = np.where(np.abs(label_time[before] - sensor_time) <= np.abs(label_time[after] - sensor_time),
                       before, after)
    offset = np.abs(label_time[nearest] - sensor_time)
    kept = offset <= labels.tolerance_s
    return kept, label_values[nearest[kept]], offset[kept]


@dataclass
class _Trial:
    source: str
    time: np.ndarray
    readings: np.ndarray  # (rows, chips, axes)
    labels: np.ndarray  # (rows, labels)
    saturated: np.ndarray | None


def _read_source(source: Path, mapping: ImportMapping) -> tuple[list[_Trial], int, float | None]:
    """One source's trials, the sensor rows it dropped for want of a label, the largest join offset."""
    sensor, labels = mapping.sensor, mapping.labels
    sensor_files, label_files = log_files(source, mapping)
    sensor_file = sensor_files[0] if len(sensor_files) == 1 else source / sensor.file  # what errors name
    own_labels = ([] if labels is None or label_files is not None
                  else [label.column for label in labels.columns.values()])
    split_column = [mapping.trials.column] if mapping.trials.split == "column" else []
    refs = [*sensor.columns_used(), *own_labels, *split_column]
    pieces = _read_log(sensor_files, sensor, refs, strictly=True)
    values = np.concatenate([piece for _, piece in pieces])
    if len(values) == 0:
        raise DatasetError(f"{sensor_file}: no rows")
    n_time = 0 if sensor.time is None else 1
    time = _times(sensor, values)
    chip_columns = slice(n_time, n_time + len(sensor.axes) * len(sensor.chips))
    read = [_sensor_values(path, sensor, piece[:, chip_columns]) for path, piece in pieces]
    readings = np.concatenate([piece_readings for piece_readings, _ in read])
    saturated = None if read[0][1] is None else np.concatenate([piece_saturated for _, piece_saturated in read])
    rest = values[:, chip_columns.stop:]
    own = rest[:, :len(own_labels)]
    ids = _trial_ids(sensor_file, mapping.trials, time, rest[:, len(own_labels):])
    first = 0
    for path, piece in pieces:  # each file's own lines named
        _check_time_order(path, sensor, time[first:first + len(piece)], ids[first:first + len(piece)], strictly=True)
        first += len(piece)
    starts, lengths = trial_runs(ids)
    clock, time = time, time - np.repeat(time[starts], lengths)  # from each trial's first sample, kept or not
    baseline = mapping.trials.baseline
    zero_ids = ids if baseline is None or baseline.per == "trial" else np.zeros_like(ids)  # whose zero each row takes
    if baseline is not None and baseline.label is None:
        if baseline.samples:
            zero_starts, zero_lengths = trial_runs(zero_ids)
            at_zero = np.arange(len(ids)) - np.repeat(zero_starts, zero_lengths) < baseline.samples
        else:
            at_zero = (time if baseline.per == "trial" else clock - clock[0]) < baseline.seconds
        readings = _subtract_zero(sensor_file, baseline, readings, zero_ids, at_zero)
    dropped, largest = 0, None
    if labels is None:
        label_values = np.zeros((len(time), 0))
    elif label_files is None:
        label_values = own
        missing = ~np.all(np.isfinite(own), axis=1)
        if labels.missing is not None:
            missing |= np.any(own == labels.missing, axis=1)
        keep = ~missing
        dropped = int(missing.sum())
        time, readings, label_values, ids, zero_ids = time[keep], readings[keep], own[keep], ids[keep], zero_ids[keep]
        saturated = None if saturated is None else saturated[keep]
    else:
        label_refs = [labels.time, *(label.column for label in labels.columns.values())]
        label_pieces = _read_log(label_files, labels, label_refs, strictly=False)
        for path, piece in label_pieces:
            _check_time_order(path, labels, _times(labels, piece), np.zeros(len(piece), dtype=np.int64),
                              strictly=False)
        logged = np.concatenate([piece for _, piece in label_pieces])
        label_file = label_files[0] if len(label_files) == 1 else source / labels.file
        keep, label_values, offset = _join(label_file, labels, clock, _times(labels, logged), logged[:, 1:])
        dropped = int((~keep).sum())
        largest = float(offset.max()) if offset.size else None
        time, readings, ids, zero_ids = time[keep], readings[keep], ids[keep], zero_ids[keep]
        saturated = None if saturated is None else saturated[keep]
    if labels is not None:
        factors = [_label_factor(name, label.unit) for name, label in labels.columns.items()]
        label_values = label_values * np.asarray(factors)
    if not len(ids):
        raise DatasetError(f"{source}: no sensor row has a label reading within the tolerance")
    if baseline is not None and baseline.label is not None:
        at_rest = label_values[:, list(labels.columns).index(baseline.label)] < baseline.below
        readings = _subtract_zero(sensor_file, baseline, readings, zero_ids, at_rest)
    trials = []
    for start, length in zip(*trial_runs(ids), strict=True):
        rows = slice(start, start + length)
        trials.append(_Trial(source.name, time[rows], readings[rows], label_values[rows],
                             None if saturated is None else saturated[rows]))
    return trials, dropped, largest


def _trial_ids(path: Path, trials: Trials, time: np.ndarray, column: np.ndarray) -> np.ndarray:
    """Each row's trial within its source, numbered from 0 in order."""
    if trials.split == "file":
        return np.zeros(len(time), dtype=np.int64)
    if trials.split == "gap":
        return np.concatenate([[0], np.cumsum(np.diff(time) > trials.gap_s)]).astype(np.int64)
    ids = column[:, 0]
    if not np.all(np.isfinite(ids)):
        raise DatasetError(f"{path}: trial column {trials.column}: a value is not a number")
    return np.concatenate([[0], np.cumsum(ids[1:] != ids[:-1])]).astype(np.int64)


def _subtract_zero(path: Path, baseline: Baseline, readings: np.ndarray, ids: np.ndarray,
                   at_zero: np.ndarray) -> np.ndarray:
    """``readings`` minus, per trial, the mean of its samples ``at_zero`` (the baseline rule's samples)."""
    starts, lengths = trial_runs(ids)
    counts = np.add.reduceat(at_zero, starts)
    rule = next(f"{key} = {value}" for key, value in (("samples", baseline.samples), ("seconds", baseline.seconds),
                                                       ("label", baseline.label)) if value is not None)
    if np.any(counts == 0):
        raise DatasetError(f"{path}: baseline.{rule}: a {baseline.per} has no sample that is at its zero by "
                           "this rule")
    if np.any(counts == lengths):
        raise DatasetError(f"{path}: baseline.{rule} covers every sample of a {baseline.per} of "
                           f"{lengths[counts == lengths][0]}: a zero must leave samples to measure")
    zero = np.add.reduceat(readings * at_zero[:, None, None], starts) / counts[:, None, None]
    return readings - np.repeat(zero, lengths, axis=0)


def import_logs(sources: Sequence[str | os.PathLike], mapping: ImportMapping) -> tuple[Dataset, ImportReport]:
    """The dataset of a rig's logs, one or more trials per source (see the module notes), and a report."""
    if not sources:
        raise DatasetError("no sources given: expected log files or folders")
    trials: list[_Trial] = []
    dropped, offsets = 0, []
    for source in map(Path, sources):
        problem = None if source.is_dir() else not_a_file(source)
        if problem:
            raise DatasetError(f"{source}: {problem}")
        found, lost, largest = _read_source(source, mapping)
        trials += found
        dropped += lost
        offsets += [] if largest is None else [largest]
    sensor, labels = mapping.sensor, mapping.labels
    n = len(trials)
    validation = mapping.trials.validation
    validates = np.zeros(n, dtype=bool) if validation is None else validation.chosen(n)
    columns: dict[str, Any] = {
        TRIAL: np.repeat(np.arange(n), [len(trial.time) for trial in trials]),
        TIME: np.concatenate([trial.time for trial in trials])}
    readings = np.concatenate([trial.readings for trial in trials])
    for chip in range(len(sensor.chips)):
        for a, axis in enumerate(sensor.axes):
            columns[sensor.channel(chip, axis)] = readings[:, chip, a]
    label_units = {} if labels is None else {name: stored_unit(name, label.unit)
                                             for name, label in labels.columns.items()}
    values = np.concatenate([trial.labels for trial in trials])
    for k, name in enumerate(label_units):
        columns[name] = values[:, k]
    saturation = None if trials[0].saturated is None else np.concatenate([trial.saturated for trial in trials])
    if saturation is not None:
        columns["saturated"] = saturation.any(axis=(1, 2))
        label_units["saturated"] = DIMENSIONLESS
    columns["role"] = np.repeat(np.where(validates, VALIDATION, CALIBRATION), [len(t.time) for t in trials])
    columns["source"] = np.repeat([trial.source for trial in trials], [len(t.time) for t in trials])
    channel_units = {} if sensor.chip != OTHER else {sensor.channel(chip, axis): sensor.unit
                                                     for chip in range(len(sensor.chips)) for axis in sensor.axes}
    settings = sensor.chip_settings
    metadata = DatasetMetadata(
        description=mapping.description or f"imported from {', '.join(trial.source for trial in trials[:3])}"
                                           + (" ..." if n > 3 else ""),
        sensor_settings=None if settings is None else settings.to_dict())
    dataset = Dataset(columns, label_units, {"role": DIMENSIONLESS, "source": DIMENSIONLESS}, metadata,
                      channel_units)
    saturated = {} if saturation is None else {
        sensor.channel(chip, axis): int(saturation[:, chip, a].sum())
        for chip in range(len(sensor.chips)) for a, axis in enumerate(sensor.axes)}
    report = ImportReport(trials=n, samples=len(dataset), validation_trials=[int(k) for k in np.flatnonzero(validates)],
                          unlabelled_dropped=dropped, saturated=saturated,
                          join_offset_s=max(offsets) if offsets else None)
    return dataset, report
