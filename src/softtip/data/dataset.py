"""Trial datasets: one Parquet file per dataset, one row per sample, metadata as JSON.

Columns, in this order:

- ``trial`` (int64): the trial id; the rows of a trial are contiguous;
- ``time_s`` (float64): time from the start of the trial, strictly increasing within it;
- channels (float64, finite): the magnetic ones, ``s{k}_b{x|y|z}_uT``, the change of flux density
  of Hall sensor k from its baseline in µT, in the order sensor, then axis, recognised by their
  names; then the channels of other sensors (a tactile chip's forces, say), declared with their
  units, in the order declared;
- labels: per-sample targets (forces, angles, contact states...), numeric or string;
- conditions: per-trial constants (board angle, contact position, trained or not...),
  numeric, boolean or string.

Labels and conditions are declared with their units; ``"1"`` for dimensionless numbers and
for categories (string columns). The Parquet schema metadata holds one JSON document under the key
``softtip``: format name, schema version, the channel, label and condition lists with units,
the provenance (description, design, sensor settings, protocol, seed, softtip version,
creation time) and ``sha256``: the SHA-256 of the whole file as written with these 64 hex digits
as zeros (the document is written with zeros, hashed, then the digits put in place: they are of one
length, so nothing moves). Every data page also carries its CRC (Parquet's page checksum). Both are
verified on reading, so a byte changed anywhere in the file, data, document or Parquet's own
structure, is refused in one line naming the file. Statistics and the serialised Arrow schema,
which readers take on trust, are not written: the columns' types are Parquet's logical types. A
file written before datasets carried a checksum still reads, with a :class:`UnverifiedDatasetWarning`:
its content cannot be verified, and writing it again adds the checksum. Nothing is pickled.

Channels of other sensors need no new schema version: the document has always listed every
channel with its unit; a version-1 file of magnetic channels reads as before.
"""

from __future__ import annotations

import hashlib
import io
import json
import numbers
import os
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from pydantic import Strict

from softtip import __version__
from softtip._core.channels import CHANNEL_UNIT, channel_names, channel_order, is_channel
from softtip._core.config import ConfigError, Text, Whole, checked, expect
from softtip._core.files import atomic_write, not_a_file

FORMAT = "softtip-dataset"
SCHEMA_VERSION = 1
METADATA_KEY = b"softtip"
TRIAL = "trial"
TIME = "time_s"
DIMENSIONLESS = "1"  # the unit of counts, ratios and categories
_NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_DOCUMENT_KEYS = ("format", "schema_version", "description", "channels", "labels", "conditions", "design",
                  "sensor_settings", "protocol", "seed", "softtip_version", "created_utc")
CHECKSUM_KEY = "sha256"  # absent from files written before datasets carried a checksum
_UNSEALED = "0" * 64  # the checksum's place while the file is hashed
PARQUET_OPTIONS = {"write_page_checksum": True, "write_statistics": False, "store_schema": False}


class DatasetError(ConfigError):
    """A dataset, dataset file or recording (or the mapping that reads it) that does not hold valid
    softtip trials."""


class UnverifiedDatasetWarning(UserWarning):
    """A dataset file without a checksum (written before datasets carried one): read unverified."""


# --------------------------------------------------------------------------
# Trial structure
# --------------------------------------------------------------------------


def trial_runs(trial: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First row and length of every run of equal consecutive trial ids."""
    trial = np.asarray(trial)
    if trial.size == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    starts = np.flatnonzero(np.r_[True, trial[1:] != trial[:-1]])
    return starts, np.diff(np.r_[starts, trial.size])


def subtract_trial_baseline(values: np.ndarray, trial: np.ndarray, n_samples: int) -> np.ndarray:
    """``values`` (n_rows, ...) minus, per trial, the mean of that trial's first ``n_samples`` rows."""
    if isinstance(n_samples, bool) or not isinstance(n_samples, numbers.Integral) or n_samples < 1:
        raise DatasetError(f"baseline: expected a number of samples >= 1, got {n_samples!r}")
    starts, lengths = trial_runs(trial)
    if lengths.size and lengths.min() < n_samples:
        raise DatasetError(f"trial {trial[starts[np.argmin(lengths)]]} has {lengths.min()} samples, "
                           f"fewer than the {n_samples} of its baseline")
    baseline = values[starts[:, None] + np.arange(n_samples)].mean(axis=1)
    return values - np.repeat(baseline, lengths, axis=0)


def _differs(values: np.ndarray) -> np.ndarray:
    """values[i + 1] != values[i], with NaN equal to NaN."""
    later, earlier = values[1:], values[:-1]
    changed = later != earlier
    if values.dtype.kind == "f":
        changed &= ~(np.isnan(later) & np.isnan(earlier))
    return changed


def _check_trial_structure(trial: np.ndarray, time: np.ndarray, conditions: Mapping[str, np.ndarray]) -> None:
    starts, _ = trial_runs(trial)
    ids, counts = np.unique(trial[starts], return_counts=True)
    if np.any(counts > 1):
        raise DatasetError(f"the rows of trial {ids[counts > 1][0]} are not contiguous")
    if not np.all(np.isfinite(time)):
        raise DatasetError(f"column {TIME}: row {np.flatnonzero(~np.isfinite(time))[0]} is not finite")
    same_trial = trial[1:] == trial[:-1]
    backwards = np.flatnonzero(same_trial & (np.diff(time) <= 0))
    if backwards.size:
        row = backwards[0] + 1
        raise DatasetError(f"column {TIME}: time does not increase within trial {trial[row]} at row {row}")
    for name, values in conditions.items():
        changes = np.flatnonzero(same_trial & _differs(values))
        if changes.size:
            raise DatasetError(f"condition {name} changes within trial {trial[changes[0] + 1]}: "
                               "conditions are constant over a trial")


# --------------------------------------------------------------------------
# Column values
# --------------------------------------------------------------------------


def _one_dimensional(name: str, values: Any) -> np.ndarray:
    array = np.array(values)  # a copy: the dataset's columns are read-only and owned
    if array.ndim != 1:
        raise DatasetError(f"column {name}: expected a 1-D array, got shape {array.shape}")
    return array


def _trial_column(values: Any) -> np.ndarray:
    array = _one_dimensional(TRIAL, values)
    if array.size == 0:
        return array.astype(np.int64)
    if array.dtype.kind not in "iu":
        raise DatasetError(f"column {TRIAL}: expected integer trial ids, got {array.dtype}")
    return array.astype(np.int64)


def _float_column(name: str, values: Any) -> np.ndarray:
    array = _one_dimensional(name, values)
    if array.size and array.dtype.kind not in "iuf":
        raise DatasetError(f"column {name}: expected numbers, got {array.dtype}")
    return array.astype(np.float64)


def _value_column(name: str, values: Any) -> np.ndarray:
    """A label or condition column: bool, integer, float32/64 or string (stored at its longest width)."""
    array = _one_dimensional(name, values)
    if array.dtype.kind == "O":
        if not all(isinstance(item, str) for item in array):
            raise DatasetError(f"column {name}: expected numbers, booleans or strings, got mixed Python objects")
        array = array.astype(str)
    kind = array.dtype.kind
    if kind == "U":
        width = int(np.char.str_len(array).max()) if array.size else 1
        return array.astype(f"<U{max(width, 1)}")
    if kind in "biu" or (kind == "f" and array.dtype.itemsize in (4, 8)):
        return array
    raise DatasetError(f"column {name}: dtype {array.dtype} cannot be stored "
                       "(expected bool, integer, float32, float64 or string)")


def _bits(buffer: pa.Buffer, offset: int, count: int) -> np.ndarray:
    """``count`` bits of an Arrow bitmap from bit ``offset`` on, as booleans (Arrow packs them least
    significant first)."""
    return np.unpackbits(np.frombuffer(buffer, dtype=np.uint8), bitorder="little")[offset:offset + count].astype(bool)


def arrow_numbers(column: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """A boolean, integer or floating Arrow column as a new numpy array, read from its buffers, missing
    values NaN (a float column's) or left as stored (others'). Arrow's own ``to_numpy`` imports pandas, half
    a second of a command's start."""
    array = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    kind = array.type
    validity, values = array.buffers()[:2]
    if pa.types.is_boolean(kind):
        numbers = _bits(values, array.offset, len(array)) if len(array) else np.zeros(0, dtype=bool)
    elif pa.types.is_integer(kind) or pa.types.is_floating(kind):
        code = "f" if pa.types.is_floating(kind) else "i" if pa.types.is_signed_integer(kind) else "u"
        dtype = np.dtype(f"{code}{kind.bit_width // 8}")  # Arrow keeps the host's byte order
        numbers = np.frombuffer(values, dtype=dtype, count=len(array), offset=array.offset * dtype.itemsize) \
            if len(array) else np.zeros(0, dtype=dtype)
        numbers = numbers.copy()
        if array.null_count and pa.types.is_floating(kind):
            numbers[~_bits(validity, array.offset, len(array))] = np.nan
    else:
        raise TypeError(f"arrow_numbers: expected a boolean, integer or floating column, got {kind}")
    return numbers


def column_to_numpy(name: str, column: pa.ChunkedArray | pa.Array, *, row_word: str = "row",
                    first_row: int = 0) -> np.ndarray:
    """An Arrow column as a numpy array; missing values are NaN in float columns and refused elsewhere.

    A refusal names the first missing value as ``row_word`` and its index counted from ``first_row``.
    """
    if pa.types.is_dictionary(column.type):
        column = column.cast(column.type.value_type)
    if column.null_count and not pa.types.is_floating(column.type):
        row = int(np.flatnonzero(arrow_numbers(pc.is_null(column)))[0])
        raise DatasetError(f"column {name}: missing value at {row_word} {first_row + row}")
    if pa.types.is_string(column.type) or pa.types.is_large_string(column.type):
        return column.to_numpy(zero_copy_only=False).astype(str)
    if pa.types.is_boolean(column.type) or pa.types.is_integer(column.type) or pa.types.is_floating(column.type):
        return arrow_numbers(column)
    return np.asarray(column.to_numpy(zero_copy_only=False))


def _declared(units: Mapping[str, str] | None, role: str) -> dict[str, str]:
    """Validated label, condition or channel declarations: identifier names, each with a unit string.
    A magnetic channel's name is reserved for its channel, in µT."""
    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise DatasetError(f"{role}: expected a mapping of name to unit, got {type(units).__name__}")
    for name, unit in units.items():
        if not isinstance(name, str) or not _NAME_PATTERN.fullmatch(name):
            raise DatasetError(f"{role}: {name!r} is not a valid column name (letters, digits, underscores)")
        if name in (TRIAL, TIME) or (is_channel(name) and role != "channels"):
            raise DatasetError(f"{role}: {name!r} is reserved for the trial id, the time or a channel")
        if not isinstance(unit, str) or not unit.strip():
            raise DatasetError(f"{role}: {name} has no unit (give a unit string; \"{DIMENSIONLESS}\" if dimensionless)")
        if role == "channels" and is_channel(name) and unit != CHANNEL_UNIT:
            raise DatasetError(f"channels: {name} [{unit}] is a magnetic channel, in {CHANNEL_UNIT}")
    return dict(units)


# --------------------------------------------------------------------------
# Metadata
# --------------------------------------------------------------------------


def _utc_now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _json_object(value: Any, name: str) -> dict | None:
    """A JSON object as it reads back from JSON (tuples become lists), or None."""
    if value is None:
        return None
    if not isinstance(value, Mapping):
        raise DatasetError(f"metadata {name}: expected a JSON object (a dict), got {type(value).__name__}")
    try:
        return json.loads(json.dumps(dict(value), allow_nan=False))
    except (TypeError, ValueError) as problem:
        raise DatasetError(f"metadata {name}: not representable as JSON ({problem})") from None


Description = Annotated[str, Strict(), expect("a string")]
Seed = Annotated[Whole, expect("an integer or None")]


@dataclass(frozen=True)
class DatasetMetadata:
    """Provenance of a dataset. ``design``, ``sensor_settings`` and ``protocol`` are opaque JSON objects."""

    description: str = ""
    design: dict | None = None
    sensor_settings: dict | None = None
    protocol: dict | None = None
    seed: int | None = None
    softtip_version: str = __version__
    created_utc: str = field(default_factory=_utc_now)

    def __post_init__(self):
        checked(Description, "metadata description", self.description, DatasetError)
        for name in ("design", "sensor_settings", "protocol"):
            object.__setattr__(self, name, _json_object(getattr(self, name), name))
        if self.seed is not None:
            object.__setattr__(self, "seed", checked(Seed, "metadata seed", self.seed, DatasetError))
        checked(Text, "metadata softtip_version", self.softtip_version, DatasetError)
        try:
            datetime.fromisoformat(self.created_utc)
        except (TypeError, ValueError):
            raise DatasetError(f"metadata created_utc: expected an ISO 8601 time, got {self.created_utc!r}") from None


# --------------------------------------------------------------------------
# The dataset
# --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Dataset:
    """Trials of samples: channels, labels and per-trial conditions; validated and read-only.

    ``columns`` maps names to 1-D arrays of one length: ``trial``, ``time_s``, every channel
    (a magnetic one recognised by its name, any other declared in ``channel_units``: name -> unit),
    and every declared label and condition. The stored columns are copies, in canonical order, made
    read-only; ``channel_units`` then holds every channel with its unit, in storage order.
    """

    columns: Mapping[str, Any]
    labels: Mapping[str, str] = field(default_factory=dict)
    conditions: Mapping[str, str] = field(default_factory=dict)
    metadata: DatasetMetadata = field(default_factory=DatasetMetadata)
    channel_units: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self):
        labels = _declared(self.labels, "labels")
        conditions = _declared(self.conditions, "conditions")
        declared = _declared(self.channel_units, "channels")
        both = sorted(set(labels) & set(conditions))
        if both:
            raise DatasetError(f"{both[0]} is declared both as a label and as a condition")
        twice = [name for name in declared if name in labels or name in conditions]
        if twice:
            raise DatasetError(f"{twice[0]} is declared both as a channel and as a label or condition")
        if not isinstance(self.metadata, DatasetMetadata):
            raise DatasetError(f"metadata: expected a DatasetMetadata, got {type(self.metadata).__name__}")
        given = dict(self.columns)
        for required in (TRIAL, TIME):
            if required not in given:
                raise DatasetError(f"missing column {required}")
        magnetic = sorted((name for name in given if isinstance(name, str) and is_channel(name)), key=channel_order)
        channels = {**{name: CHANNEL_UNIT for name in magnetic},
                    **{name: unit for name, unit in declared.items() if not is_channel(name)}}
        if not channels:
            raise DatasetError("no channel columns (expected names like s0_bx_uT, or channels declared with units)")
        for name in given:
            if name not in (TRIAL, TIME) and name not in labels and name not in conditions and name not in channels:
                raise DatasetError(f"column {name!r} is neither a channel (s<k>_b<x|y|z>_uT, or declared with its "
                                   "unit) nor a declared label or condition")
        for role, names in (("channel", declared), ("label", labels), ("condition", conditions)):
            for name in names:
                if name not in given:
                    raise DatasetError(f"missing column {name} (declared as a {role})")

        columns = {TRIAL: _trial_column(given[TRIAL]), TIME: _float_column(TIME, given[TIME])}
        for name in channels:
            values = _float_column(name, given[name])
            if not np.all(np.isfinite(values)):
                raise DatasetError(f"column {name}: row {np.flatnonzero(~np.isfinite(values))[0]} is not finite")
            columns[name] = values
        for name, unit in (*labels.items(), *conditions.items()):
            columns[name] = _value_column(name, given[name])
            if columns[name].dtype.kind == "U" and unit != DIMENSIONLESS:
                raise DatasetError(f"column {name} holds text but is declared in {unit}: "
                                   f"text columns are categories, declared with unit \"{DIMENSIONLESS}\"")
        lengths = {name: len(values) for name, values in columns.items()}
        if len(set(lengths.values())) > 1:
            shortest, longest = min(lengths, key=lengths.get), max(lengths, key=lengths.get)
            raise DatasetError(f"columns differ in length: {longest} has {lengths[longest]} rows, "
                               f"{shortest} has {lengths[shortest]}")
        _check_trial_structure(columns[TRIAL], columns[TIME], {name: columns[name] for name in conditions})
        for values in columns.values():
            values.setflags(write=False)
        object.__setattr__(self, "columns", columns)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "conditions", conditions)
        object.__setattr__(self, "channel_units", channels)

    # -- structure --------------------------------------------------------

    def __len__(self) -> int:
        return len(self.columns[TRIAL])

    def __repr__(self) -> str:
        return (f"Dataset({len(self)} samples, {len(self.trials)} trials, channels {list(self.channels)}, "
                f"labels {self.labels}, conditions {self.conditions})")

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.channel_units)

    @property
    def groups(self) -> np.ndarray:
        """The trial id of every row: the ``groups`` of scikit-learn's group-aware splitters."""
        return self.columns[TRIAL]

    @cached_property
    def _runs(self) -> tuple[np.ndarray, np.ndarray]:
        return trial_runs(self.columns[TRIAL])

    @property
    def trials(self) -> np.ndarray:
        """The trial ids, in the order their rows appear."""
        return self.columns[TRIAL][self._runs[0]]

    @property
    def trial_lengths(self) -> np.ndarray:
        """Samples per trial, in the order of :attr:`trials`."""
        return self._runs[1]

    @property
    def trial_conditions(self) -> dict[str, np.ndarray]:
        """One row per trial (in the order of :attr:`trials`): ``trial`` and every condition."""
        starts = self._runs[0]
        return {TRIAL: self.trials, **{name: self.columns[name][starts] for name in self.conditions}}

    # -- values -----------------------------------------------------------

    def column(self, name: str) -> np.ndarray:
        """One column, read-only."""
        if name not in self.columns:
            raise DatasetError(f"no column {name!r} (columns: {', '.join(self.columns)})")
        return self.columns[name]

    def require_finite(self, names: Sequence[str]) -> None:
        """Refuses, naming the column, the first row and its trial, a NaN or infinite value in the numeric
        columns ``names``: what no fit or score can take (channels are finite in every dataset; a label may
        be missing, NaN)."""
        for name in names:
            values = self.column(name)
            if values.dtype.kind != "f":
                continue
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                row = int(bad[0])
                raise DatasetError(f"column {name}: row {row} (trial {int(self.groups[row])}) is {values[row]}, and "
                                   f"{bad.size} rows in all are not finite: expected finite values to fit or score on "
                                   "(drop those rows or trials)")

    def X(self, channels: Sequence[str] | None = None) -> np.ndarray:
        """The channels as an (n_samples, n_channels) float64 array, all of them in storage order by default."""
        names = self.channels if channels is None else tuple(channels)
        if not names:
            raise DatasetError("X: no channels asked for")
        for name in names:
            if name not in self.channels:
                raise DatasetError(f"X: {name!r} is not a channel of this dataset "
                                   f"(channels: {', '.join(self.channels)})")
        return np.column_stack([self.columns[name] for name in names])

    def y(self, targets: str | Sequence[str]) -> np.ndarray:
        """One label or condition as stored (1-D), or several numeric ones as an (n_samples, k) float64 array."""
        if isinstance(targets, str):
            return self.column(self._target(targets))
        names = [self._target(name) for name in targets]
        if not names:
            raise DatasetError("y: no labels asked for")
        for name in names:
            if self.columns[name].dtype.kind not in "biuf":
                raise DatasetError(f"y: {name} holds {self.columns[name].dtype} values; ask for it alone")
        return np.column_stack([self.columns[name] for name in names]).astype(np.float64)

    def _target(self, name: str) -> str:
        if name not in self.labels and name not in self.conditions:
            raise DatasetError(f"y: {name!r} is not a label or condition "
                               f"(labels: {', '.join(self.labels) or 'none'}; "
                               f"conditions: {', '.join(self.conditions) or 'none'})")
        return name

    # -- derived datasets -------------------------------------------------

    def select(self, rows: Any = None, *, trials: Iterable[int] | None = None) -> Dataset:
        """The rows given by a boolean mask or increasing row indices, or every row of the given trials."""
        if (rows is None) == (trials is None):
            raise DatasetError("select: give either rows or trials")
        if trials is not None:
            wanted = np.asarray(list(trials) if isinstance(trials, Iterable) else [trials])
            unknown = np.setdiff1d(wanted, self.trials)
            if unknown.size:
                raise DatasetError(f"select: no trial {unknown[0]} in this dataset")
            rows = np.isin(self.groups, wanted)
        rows = np.asarray(rows)
        if rows.dtype == bool:
            if rows.shape != (len(self),):
                raise DatasetError(f"select: a row mask needs {len(self)} entries, got shape {rows.shape}")
        elif rows.dtype.kind in "iu" and rows.ndim == 1:
            if rows.size and (rows.min() < 0 or rows.max() >= len(self)):
                raise DatasetError(f"select: row indices must be in [0, {len(self)}), got {rows.min()}..{rows.max()}")
        else:
            raise DatasetError(f"select: rows must be a boolean mask or 1-D integer indices, got {rows.dtype}")
        return Dataset({name: values[rows] for name, values in self.columns.items()},
                       self.labels, self.conditions, self.metadata, self.channel_units)

    # -- files ------------------------------------------------------------

    def _document(self) -> dict:
        meta = self.metadata
        return {
            "format": FORMAT,
            "schema_version": SCHEMA_VERSION,
            "description": meta.description,
            "channels": [{"name": name, "unit": unit} for name, unit in self.channel_units.items()],
            "labels": [{"name": name, "unit": unit} for name, unit in self.labels.items()],
            "conditions": [{"name": name, "unit": unit} for name, unit in self.conditions.items()],
            "design": meta.design,
            "sensor_settings": meta.sensor_settings,
            "protocol": meta.protocol,
            "seed": meta.seed,
            "softtip_version": meta.softtip_version,
            "created_utc": meta.created_utc,
        }

    def write(self, path: str | os.PathLike) -> Path:
        """Writes the dataset as one Parquet file (replacing ``path`` only once the file is complete)."""
        path = Path(path)
        if not path.parent.is_dir():
            raise DatasetError(f"dataset file {path}: directory {path.parent} does not exist")
        document = json.dumps(self._document() | {CHECKSUM_KEY: _UNSEALED}, allow_nan=False).encode()
        table = pa.Table.from_arrays([pa.array(values) for values in self.columns.values()], names=list(self.columns))
        buffer = io.BytesIO()
        with pq.ParquetWriter(buffer, table.schema, **PARQUET_OPTIONS) as writer:
            writer.write_table(table)
            writer.add_key_value_metadata({METADATA_KEY: document})
        content = bytearray(buffer.getvalue())
        place = _checksum_place(content, _UNSEALED)
        content[place] = hashlib.sha256(content).hexdigest().encode()
        return atomic_write(path, bytes(content))

    @classmethod
    def read(cls, path: str | os.PathLike) -> Dataset:
        """Reads a dataset file, refusing anything that is not a valid softtip dataset with one line."""
        path = Path(path)
        problem = not_a_file(path)
        if problem:
            raise DatasetError(f"dataset file {path} {problem}")
        content = path.read_bytes()  # read once: what is verified is what is parsed
        try:
            schema = pq.read_schema(pa.BufferReader(content))
        except (pa.ArrowException, OSError, UnicodeDecodeError) as problem:  # names of a damaged file may not decode
            raise DatasetError(f"{path}: not a Parquet file ({first_line(problem)})") from None
        try:
            return cls._from_file(path, content, schema)
        except DatasetError as problem:
            raise DatasetError(f"{path}: {problem}") from None

    @classmethod
    def _from_file(cls, path: Path, content: bytes, schema: pa.Schema) -> Dataset:
        raw = (schema.metadata or {}).get(METADATA_KEY)
        if raw is None:
            raise DatasetError(f"not a softtip dataset (no '{METADATA_KEY.decode()}' entry in the Parquet metadata)")
        document = _parse_document(raw)
        declared = [TRIAL, TIME, *document["channels"], *document["labels"], *document["conditions"]]
        for name in declared:
            if name not in schema.names:
                raise DatasetError(f"missing column {name}")
        for name in schema.names:
            if name not in declared:
                raise DatasetError(f"column {name!r} is not declared in the metadata")
        if len(set(schema.names)) != len(schema.names):
            raise DatasetError("duplicate column names")
        try:
            table = pq.ParquetFile(pa.BufferReader(content), page_checksum_verification=True).read()
        except (pa.ArrowException, OSError, UnicodeDecodeError) as problem:  # names of a damaged file may not decode
            raise DatasetError(f"unreadable Parquet data ({first_line(problem)})") from None
        columns = {name: column_to_numpy(name, table.column(name)) for name in declared}
        dataset = cls(columns, document["labels"], document["conditions"], document["metadata"], document["channels"])
        if document["checksum"] is None:
            warnings.warn(f"{path}: no checksum (written by softtip {dataset.metadata.softtip_version}, before "
                          "datasets carried one): its content cannot be verified; write it again to add one",
                          UnverifiedDatasetWarning, stacklevel=3)
        elif not _sealed(content, document["checksum"]):
            raise DatasetError("checksum mismatch: the file was altered or damaged after it was written")
        return dataset


def is_dataset_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a Parquet file that says it is a softtip dataset (its metadata entry), to be
    read by :meth:`Dataset.read`, which verifies it; False for any other file or none."""
    try:
        return METADATA_KEY in (pq.read_schema(path).metadata or {})
    except (pa.ArrowException, OSError):
        return False


def _checksum_place(content: bytes | bytearray, digest: str) -> slice | None:
    """Where the document's checksum ``digest`` is written in the file ``content`` (its last
    occurrence: the document is in the footer), or None."""
    entry = json.dumps({CHECKSUM_KEY: digest})[1:-1].encode()  # as json.dumps wrote it in the document
    found = content.rfind(entry)
    if found < 0:
        return None
    stop = found + len(entry) - 1  # the closing quote
    return slice(stop - len(digest), stop)


def _sealed(content: bytes, digest: str) -> bool:
    """Whether ``content`` hashes to ``digest`` with ``digest`` written as zeros (see the module notes)."""
    place = _checksum_place(content, digest)
    if place is None or len(digest) != len(_UNSEALED):
        return False
    unsealed = bytearray(content)
    unsealed[place] = _UNSEALED.encode()
    return hashlib.sha256(unsealed).hexdigest() == digest


def first_line(problem: Exception) -> str:
    """The first line of an error's message (its type's name if it has none), for a one-line refusal."""
    return str(problem).strip().splitlines()[0] if str(problem).strip() else type(problem).__name__


def require_columns(source: str | os.PathLike, wanted: Iterable[str], present: Sequence[str]) -> None:
    """Refuses, in one line naming ``source``, a column of ``wanted`` that is not among the columns
    ``present`` of a file, or that is there more than once."""
    for name in wanted:
        if name not in present:
            raise DatasetError(f"{source}: no column {name!r} (columns: {', '.join(present)})")
        if present.count(name) > 1:
            raise DatasetError(f"{source}: column {name!r} appears more than once")


def unknown_and_missing(keys: Iterable[str], expected: Sequence[str]) -> tuple[list[str], list[str]]:
    """The keys that are not expected and the expected ones that are not among the keys, in order."""
    keys = list(keys)
    return [key for key in keys if key not in expected], [key for key in expected if key not in keys]


def _parse_document(raw: bytes) -> dict:
    """The metadata document: declarations with units, a DatasetMetadata and the checksum (or None)."""
    try:
        document = json.loads(raw)
    except (UnicodeDecodeError, ValueError):
        raise DatasetError("the softtip metadata is not valid JSON") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        found = document.get("format") if isinstance(document, dict) else None
        raise DatasetError(f"not a softtip dataset (format {found!r}, expected {FORMAT!r})")
    if document.get("schema_version") != SCHEMA_VERSION:
        raise DatasetError(f"schema version {document.get('schema_version')!r} is not supported "
                           f"(this softtip reads version {SCHEMA_VERSION})")
    unknown, missing = unknown_and_missing([key for key in document if key != CHECKSUM_KEY], _DOCUMENT_KEYS)
    if missing:
        raise DatasetError(f"metadata field {missing[0]!r} is missing")
    if unknown:
        raise DatasetError(f"unknown metadata field {unknown[0]!r}")
    declared = {key: _named_units(document[key], key) for key in ("channels", "labels", "conditions")}
    try:
        _declared(declared["channels"], "channels")
    except DatasetError as problem:
        raise DatasetError(f"metadata {problem}") from None
    metadata = DatasetMetadata(**{key: document[key] for key in ("description", "design", "sensor_settings",
                                                                 "protocol", "seed", "softtip_version",
                                                                 "created_utc")})
    checksum = document.get(CHECKSUM_KEY)
    if checksum is not None and not isinstance(checksum, str):
        raise DatasetError(f"metadata {CHECKSUM_KEY}: expected a hex digest, got {checksum!r}")
    return {**declared, "metadata": metadata, "checksum": checksum}


def _named_units(entries: Any, key: str) -> dict[str, str]:
    if not isinstance(entries, list) or not all(
            isinstance(entry, dict) and set(entry) == {"name", "unit"} and isinstance(entry["name"], str)
            for entry in entries):
        raise DatasetError(f"metadata {key}: expected a list of {{name, unit}} objects")
    return {entry["name"]: entry["unit"] for entry in entries}


# --------------------------------------------------------------------------
# Combining datasets and writing trial by trial
# --------------------------------------------------------------------------


def _merged_metadata(parts: Sequence[DatasetMetadata]) -> DatasetMetadata:
    """Fields equal in every part are kept; a differing description is joined, protocols are listed."""
    first = parts[0]

    def same(name: str) -> bool:
        return all(getattr(part, name) == getattr(first, name) for part in parts)

    descriptions = list(dict.fromkeys(part.description for part in parts if part.description))
    return DatasetMetadata(
        description="; ".join(descriptions),
        design=first.design,
        sensor_settings=first.sensor_settings,
        protocol=first.protocol if same("protocol") else {"concatenated": [part.protocol for part in parts]},
        seed=first.seed if same("seed") else None,
        **({"softtip_version": first.softtip_version, "created_utc": first.created_utc}
           if same("softtip_version") and same("created_utc") else {}),
    )


def _value_class(values: np.ndarray) -> str:
    """What a column holds; integer and float columns combine (into float), the others only with their own."""
    return {"b": "boolean", "U": "string"}.get(values.dtype.kind, "numeric")


def concat(datasets: Iterable[Dataset], *, renumber_trials: bool = False) -> Dataset:
    """The rows of several datasets of the same channels, labels, conditions, design and sensor settings.

    Trial ids must not repeat across the datasets unless ``renumber_trials`` is set, which
    numbers the trials 0, 1, ... in order.
    """
    parts = list(datasets)
    if not parts:
        raise DatasetError("concat: no datasets given")
    first = parts[0]
    for index, part in enumerate(parts[1:], start=1):
        for what in ("channel_units", "labels", "conditions"):
            if getattr(part, what) != getattr(first, what):
                raise DatasetError(f"concat: dataset {index} has {what.replace('_units', 's')} {getattr(part, what)}, "
                                   f"dataset 0 has {getattr(first, what)}")
        for what in ("design", "sensor_settings"):
            if getattr(part.metadata, what) != getattr(first.metadata, what):
                raise DatasetError(f"concat: dataset {index} has a different {what.replace('_', ' ')} from dataset 0")
        for name, values in part.columns.items():
            if _value_class(values) != _value_class(first.columns[name]):
                raise DatasetError(f"concat: column {name} holds {_value_class(values)} values in dataset {index} "
                                   f"and {_value_class(first.columns[name])} values in dataset 0")
    if renumber_trials:
        offsets = np.cumsum([0] + [len(part.trials) for part in parts[:-1]])
        trial = np.concatenate([offset + np.repeat(np.arange(len(part.trials)), part.trial_lengths)
                                for offset, part in zip(offsets, parts, strict=True)])
    else:
        ids, counts = np.unique(np.concatenate([part.trials for part in parts]), return_counts=True)
        if np.any(counts > 1):
            raise DatasetError(f"concat: trial {ids[counts > 1][0]} occurs in more than one dataset "
                               "(pass renumber_trials=True to number the trials afresh)")
        trial = np.concatenate([part.groups for part in parts])
    columns = {name: np.concatenate([part.columns[name] for part in parts]) for name in first.columns if name != TRIAL}
    return Dataset({TRIAL: trial, **columns}, first.labels, first.conditions,
                   _merged_metadata([part.metadata for part in parts]), first.channel_units)


class TrialWriter:
    """Collects trials one at a time and turns them into one dataset (or file).

    Every trial is checked when it is added, so an error names the trial at fault.
    """

    def __init__(self, channels: int | Sequence[str] | Mapping[str, str], labels: Mapping[str, str] | None = None,
                 conditions: Mapping[str, str] | None = None, metadata: DatasetMetadata | None = None):
        if isinstance(channels, Mapping):  # any sensor's channels, each with its unit
            self.channel_units = _declared(channels, "channels")
            names = tuple(self.channel_units)
        else:  # magnetic channels: a number of 3-axis Hall sensors, or their channel names
            names = channel_names(channels) if isinstance(channels, numbers.Integral) else tuple(channels)
            for name in names:
                if not isinstance(name, str) or not is_channel(name):
                    raise DatasetError(f"channels: {name!r} is not a channel name (s<k>_b<x|y|z>_uT)")
            self.channel_units = dict.fromkeys(names, CHANNEL_UNIT)
        if len(set(names)) != len(names) or not names:
            raise DatasetError("channels: expected distinct channel names, at least one")
        self.channels = names
        self.labels = _declared(labels, "labels")
        self.conditions = _declared(conditions, "conditions")
        self.metadata = DatasetMetadata() if metadata is None else metadata
        self._trials: list[Dataset] = []
        self._ids: set[int] = set()

    @property
    def n_trials(self) -> int:
        return len(self._trials)

    def add(self, samples: Mapping[str, Any], conditions: Mapping[str, Any] | None = None, *,
            trial: int | None = None) -> int:
        """Adds one trial and returns its id (the next free one unless given).

        ``samples`` maps ``time_s``, every channel and every label to equal-length arrays
        (:func:`softtip.data.channel_columns` names an (n, sensors, 3) array); ``conditions`` maps every
        condition to one value.
        """
        if trial is None:
            trial = max(self._ids) + 1 if self._ids else 0
        elif isinstance(trial, bool) or not isinstance(trial, numbers.Integral):
            raise DatasetError(f"trial: expected an integer id, got {trial!r}")
        trial = int(trial)
        if trial in self._ids:
            raise DatasetError(f"trial {trial} was already added")
        conditions = {} if conditions is None else dict(conditions)
        self._check_keys(trial, "samples", set(samples), {TIME, *self.channels, *self.labels})
        self._check_keys(trial, "conditions", set(conditions), set(self.conditions))
        n = np.size(samples[TIME])
        if n == 0:
            raise DatasetError(f"trial {trial}: no samples")
        columns = {TRIAL: np.full(n, trial, dtype=np.int64), **samples}
        for name, value in conditions.items():
            if np.ndim(value) != 0:
                raise DatasetError(f"trial {trial}: condition {name} must be one value, got shape {np.shape(value)}")
            columns[name] = np.full(n, value)
        try:
            part = Dataset(columns, self.labels, self.conditions, self.metadata, self.channel_units)
        except DatasetError as problem:
            raise DatasetError(f"trial {trial}: {problem}") from None
        self._trials.append(part)
        self._ids.add(trial)
        return trial

    @staticmethod
    def _check_keys(trial: int, what: str, given: set, expected: set) -> None:
        missing, unexpected = sorted(expected - given), sorted(given - expected, key=str)
        if missing:
            raise DatasetError(f"trial {trial}: {what} lack {', '.join(missing)}")
        if unexpected:
            raise DatasetError(f"trial {trial}: {what} hold undeclared {', '.join(map(str, unexpected))}")

    def to_dataset(self) -> Dataset:
        if not self._trials:
            raise DatasetError("no trials were added")
        return concat(self._trials)

    def write(self, path: str | os.PathLike) -> Dataset:
        """Writes every trial added so far to ``path`` and returns the dataset written."""
        dataset = self.to_dataset()
        dataset.write(path)
        return dataset
