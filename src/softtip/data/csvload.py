"""Real recordings from CSV files, mapped onto the softtip dataset format.

A mapping names, for each CSV column used, the softtip column it becomes: a channel
(``s0_bx_uT``...), a label or a condition (declared with its unit). Magnetic columns are
converted to µT from the unit they were recorded in; time is converted to seconds and
counted from the first sample of each trial. Errors name the file, the CSV column and the
line (the header is line 1). The mapping is a dict, or a TOML file::

    trial_column = "run"
    time_column = "t"
    time_unit = "ms"
    units = "mT"              # or a [units] table: CSV column -> unit, per magnetic column

    [columns]
    Bx = "s0_bx_uT"
    By = "s0_by_uT"
    Bz = "s0_bz_uT"
    Fz = "fz_N"
    angle = "board_angle_deg"

    [labels]
    fz_N = "N"

    [conditions]
    board_angle_deg = "deg"

Every top-level key of the file is also a keyword of :func:`read_csv_recording`; a setting
given both ways is refused.

:func:`read_columns` reads chosen columns of any delimited text (a header or none, one character or
whitespace between the cells) as numbers: the reader under ``softtip import``
(:mod:`softtip.lab.importing`), for any command that takes such files.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
from pydantic import Field, Strict

from softtip._core.channels import MAGNETIC, is_channel
from softtip._core.config import choice, expect, integer, number, parse, read_toml, schema
from softtip._core.files import not_a_file

from softtip.data.dataset import (
    DIMENSIONLESS,
    TIME,
    TRIAL,
    Dataset,
    DatasetError,
    DatasetMetadata,
    arrow_numbers,
    column_to_numpy,
    first_line,
    require_columns,
    subtract_trial_baseline,
    trial_runs,
    unknown_and_missing,
)

WHITESPACE = "whitespace"  # the delimiter of columns separated by runs of spaces or tabs
TIME_UNITS_IN_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6}
_FIRST_DATA_LINE = 2  # line 1 is the header

ColumnName = Annotated[str, Strict(), Field(min_length=1), expect("a CSV column name")]
_MagneticUnit = Literal[tuple(MAGNETIC.units)]
MagneticUnits = Annotated[_MagneticUnit | dict[str, _MagneticUnit], expect(
    f"a magnetic unit ({', '.join(MAGNETIC.units)}) or a table of them per CSV column")]
UnitTable = Annotated[dict[str, Any], expect("a table of name = unit")]  # names and units: checked by the dataset
Delimiter = Annotated[str, Strict(), Field(min_length=1, max_length=1), expect("one character")]
SamplingRate = number("a positive sampling rate in Hz", gt=0)
SampleCount = integer(0, expected="a number of samples >= 0")


@schema
class CsvLayout:
    """Every setting of a reading but the column mapping (see :func:`read_csv_recording`)."""

    trial_column: ColumnName | None = None
    time_column: ColumnName | None = None
    time_unit: choice(*TIME_UNITS_IN_S) = "s"
    rate_hz: SamplingRate | None = None
    units: MagneticUnits = "uT"
    labels: UnitTable = field(default_factory=dict)
    conditions: UnitTable = field(default_factory=dict)
    baseline_samples: SampleCount = 0
    delimiter: Delimiter = ","


@schema
class _MappingFile(CsvLayout):
    _: KW_ONLY
    columns: Annotated[dict[str, Any], expect("a table of CSV column = softtip column")]


def _check_columns(source: str, columns: Any, labels: Mapping[str, str], conditions: Mapping[str, str]) -> dict:
    if not isinstance(columns, Mapping) or not columns:
        raise DatasetError(f"{source}: columns: expected a non-empty table of CSV column = softtip column")
    targets: dict[str, str] = {}
    for csv_name, name in columns.items():
        if not isinstance(name, str):
            raise DatasetError(f"{source}: columns: {csv_name!r} = {name!r}: expected a softtip column name")
        if name in (TRIAL, TIME):
            raise DatasetError(f"{source}: columns: {csv_name!r} = {name!r}: give it as "
                               f"{'trial_column' if name == TRIAL else 'time_column'} instead")
        if not (is_channel(name) or name in labels or name in conditions):
            raise DatasetError(f"{source}: columns: {csv_name!r} = {name!r} is neither a channel (s<k>_b<x|y|z>_uT) "
                               "nor declared in labels or conditions (with its unit)")
        if name in targets:
            raise DatasetError(f"{source}: columns: both {targets[name]!r} and {csv_name!r} map to {name}")
        targets[name] = csv_name
    for name in (*labels, *conditions):
        if name not in targets:
            raise DatasetError(f"{source}: {name} is declared but no CSV column maps to it")
    return dict(columns)


def _magnetic_units(source: str, units: str | Mapping[str, str], magnetic: list[str]) -> dict[str, str]:
    if isinstance(units, str):
        return dict.fromkeys(magnetic, units)
    unknown, missing = unknown_and_missing(units, magnetic)
    if unknown:
        raise DatasetError(f"{source}: units: {unknown[0]!r} is not a CSV column mapped to a channel")
    if missing:
        raise DatasetError(f"{source}: units: no unit for magnetic column {missing[0]!r}")
    return dict(units)


def parse_numbers(path: Path, csv_name: str, column: pa.ChunkedArray, *, first_line: int = _FIRST_DATA_LINE
                  ) -> np.ndarray:
    """A CSV column read as text, parsed as float64, with the first bad cell named on failure (its line
    counted from ``first_line``, the line of the first row: 2 below a header)."""
    text = pc.utf8_trim_whitespace(column)
    try:
        return arrow_numbers(pc.cast(text, pa.float64()))
    except pa.ArrowInvalid:
        for line, cell in enumerate(text.to_pylist(), start=first_line):
            try:
                float(cell)
            except (TypeError, ValueError):
                shown = "empty" if not cell else f"{cell!r} is not a number"
                raise DatasetError(f"{path}: column {csv_name!r}, line {line}: {shown}") from None
        raise DatasetError(f"{path}: column {csv_name!r}: not all values are numbers") from None


def _is_text(column: pa.ChunkedArray) -> bool:
    return pa.types.is_string(column.type) or pa.types.is_large_string(column.type)


@dataclass(frozen=True)
class _Layout:
    """Every setting of one reading, resolved and checked."""

    source: str  # where the mapping came from, for messages
    columns: dict[str, str]  # CSV column -> softtip column
    magnetic_units: dict[str, str]  # CSV column -> unit, for the columns mapped to channels
    options: CsvLayout

    @property
    def numeric(self) -> list[str]:
        """The CSV columns read as text and parsed as numbers here (for one-line messages naming the cell)."""
        own = (self.options.trial_column, self.options.time_column)
        return [*self.magnetic_units, *(name for name in own if name is not None)]


def _layout(mapping: Any, arguments: dict[str, Any]) -> _Layout:
    """The layout from the mapping (a dict of columns, or a file with the columns and settings) and the
    settings given as arguments (those not None)."""
    arguments = {key: value for key, value in arguments.items() if value is not None}
    parse(CsvLayout, arguments, "read_csv_recording", error=DatasetError)
    if isinstance(mapping, (str, os.PathLike)):
        source = str(mapping)
        document = read_toml(mapping, "CSV mapping", DatasetError)
        columns = parse(_MappingFile, document, source, error=DatasetError).columns
        settings = {key: value for key, value in document.items() if key != "columns"}
        for key in arguments:
            if key in settings:
                raise DatasetError(f"{source}: {key} is also given as an argument")
    elif isinstance(mapping, Mapping):
        source, columns, settings = "mapping", mapping, {}
    else:
        raise DatasetError(f"mapping: expected a dict or the path of a TOML file, got {type(mapping).__name__}")
    options = parse(CsvLayout, settings | arguments, source, error=DatasetError)
    if options.time_column is not None and options.rate_hz is not None:
        raise DatasetError(f"{source}: give either time_column or rate_hz, not both")
    if options.time_column is None and options.rate_hz is None:
        options = replace(options, time_column=TIME)
    columns = _check_columns(source, columns, options.labels, options.conditions)
    magnetic = [csv_name for csv_name, name in columns.items() if is_channel(name)]
    return _Layout(source, columns, _magnetic_units(source, options.units, magnetic), options)


def read_csv_table(path: Path, numeric: Sequence[str], *, delimiter: str = ",",
                   only: Sequence[str] | None = None) -> pa.Table:
    """softtip's one reader of CSV files: the file as an Arrow table (``only`` these columns, if given),
    the ``numeric`` columns kept as text for :func:`parse_numbers`, which names the first bad cell; a
    file that cannot be read is refused in one line."""
    try:
        return pacsv.read_csv(path, parse_options=pacsv.ParseOptions(delimiter=delimiter),
                              convert_options=pacsv.ConvertOptions(include_columns=only,
                                                                   column_types=dict.fromkeys(numeric, pa.string())))
    except (pa.ArrowException, OSError) as problem:
        raise DatasetError(f"{path}: cannot be read as CSV ({first_line(problem)})") from None


def _read_table(path: Path, layout: _Layout) -> pa.Table:
    problem = not_a_file(path)
    if problem:
        raise DatasetError(f"recording {path} {problem}")
    table = read_csv_table(path, layout.numeric, delimiter=layout.options.delimiter)
    require_columns(path, [*layout.columns, *layout.numeric], table.column_names)
    return table


def read_csv_recording(path: str | os.PathLike, mapping: Mapping[str, str] | str | os.PathLike, *,
                       trial_column: str | None = None, time_column: str | None = None,
                       time_unit: str | None = None, rate_hz: float | None = None,
                       units: str | Mapping[str, str] | None = None, labels: Mapping[str, str] | None = None,
                       conditions: Mapping[str, str] | None = None, baseline_samples: int | None = None,
                       delimiter: str | None = None, metadata: DatasetMetadata | None = None) -> Dataset:
    """A dataset from a CSV recording and a column mapping (a dict, or the path of a TOML file).

    - ``trial_column``: the CSV column of integer trial ids; without it the file is one trial (id 0);
    - ``time_column`` (default ``time_s``) in ``time_unit`` (s, ms, us), or, without a time column,
      ``rate_hz``: samples evenly spaced at that rate; times count from each trial's first sample;
    - ``units``: the unit of the magnetic columns as recorded (uT, mT, G, T), one for all or a
      table per CSV column; values are stored in µT;
    - ``labels`` / ``conditions``: name -> unit of every mapped column that is not a channel;
    - ``baseline_samples``: when > 0, the mean of each trial's first that many samples is
      subtracted from its magnetic columns (for recordings of absolute flux density);
    - ``delimiter``: the CSV field separator.
    """
    path = Path(path)
    layout = _layout(mapping, {"trial_column": trial_column, "time_column": time_column, "time_unit": time_unit,
                               "rate_hz": rate_hz, "units": units, "labels": labels, "conditions": conditions,
                               "baseline_samples": baseline_samples, "delimiter": delimiter})
    options = layout.options
    table = _read_table(path, layout)

    if options.trial_column is None:
        trial = np.zeros(table.num_rows, dtype=np.int64)
    else:
        ids = parse_numbers(path, options.trial_column, table.column(options.trial_column))
        if not np.all(np.isfinite(ids) & (ids == np.round(ids))):
            raise DatasetError(f"{path}: trial column {options.trial_column!r} holds values that are not integers")
        trial = ids.astype(np.int64)
    starts, lengths = trial_runs(trial)
    first_row = np.repeat(starts, lengths)
    if options.rate_hz is not None:
        time = (np.arange(len(trial)) - first_row) / options.rate_hz
    else:
        time = parse_numbers(path, options.time_column, table.column(options.time_column))
        time = (time - time[first_row]) * TIME_UNITS_IN_S[options.time_unit]

    data: dict[str, Any] = {TRIAL: trial, TIME: time}
    units_of = {**options.labels, **options.conditions}
    for csv_name, name in layout.columns.items():
        column = table.column(csv_name)
        if csv_name in layout.magnetic_units:
            values = parse_numbers(path, csv_name, column) * MAGNETIC.units[layout.magnetic_units[csv_name]]
            if options.baseline_samples:
                try:
                    values = subtract_trial_baseline(values, trial, options.baseline_samples)
                except DatasetError as problem:
                    raise DatasetError(f"{path}: {problem}") from None
            data[name] = values
        elif _is_text(column) and units_of[name] != DIMENSIONLESS:
            data[name] = parse_numbers(path, csv_name, column)  # a physical quantity read as text: name the bad cell
        else:
            try:
                data[name] = column_to_numpy(repr(csv_name), column, row_word="line", first_row=_FIRST_DATA_LINE)
            except DatasetError as problem:
                raise DatasetError(f"{path}: {problem}") from None
    if metadata is None:
        metadata = DatasetMetadata(description=f"CSV recording {path.name}")
    try:
        return Dataset(data, options.labels, options.conditions, metadata)
    except DatasetError as problem:
        raise DatasetError(f"{path}: {problem}") from None


def read_columns(path: str | os.PathLike, columns: Sequence[int | str], *, header: bool = True,
                 delimiter: str = ",") -> np.ndarray:
    """The ``columns`` (numbered from 1, or named by the header) of a delimited text file as an
    (n_rows, len(columns)) float array. ``delimiter`` is one character or ``"whitespace"`` (runs of
    spaces and tabs, as in DaISy's and MATLAB's ``.dat`` files). A missing column, a row of the wrong
    length or a cell that is not a number is one line naming the file, the column and the line."""
    path = Path(path)
    problem = not_a_file(path)
    if problem:
        raise DatasetError(f"{path}: {problem}")
    try:
        content = path.read_bytes()
    except OSError as problem:
        raise DatasetError(f"{path}: cannot be read ({problem.strerror})") from None
    if delimiter == WHITESPACE:
        lines = content.decode("utf-8", errors="replace").splitlines()
        content = "\n".join(" ".join(line.split()) for line in lines).encode()  # empty lines are skipped below
        delimiter = " "
    names = _header(path, content, header, delimiter)
    wanted = [str(ref) if isinstance(ref, int) else ref for ref in columns]
    for ref, name in zip(columns, wanted, strict=True):
        if name not in names:
            shown = f"column {ref}" if isinstance(ref, int) else f"no column {ref!r}"
            raise DatasetError(f"{path}: {shown} " + (f"(it has {len(names)})" if isinstance(ref, int) else
                                                      f"(columns: {', '.join(names)})"))
    try:
        table = pacsv.read_csv(io.BytesIO(content), read_options=pacsv.ReadOptions(
            column_names=names, skip_rows=1 if header else 0),
            parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(include_columns=list(dict.fromkeys(wanted)),
                                                 column_types=dict.fromkeys(wanted, pa.string())))
    except (pa.ArrowException, OSError) as problem:
        raise DatasetError(f"{path}: cannot be read as delimited text ({first_line(problem)})") from None
    first = 2 if header else 1
    return np.column_stack([parse_numbers(path, name, table.column(name), first_line=first) for name in wanted]
                           ) if table.num_rows else np.zeros((0, len(wanted)))


def _header(path: Path, content: bytes, header: bool, delimiter: str) -> list[str]:
    """The column names: the header's, or the numbers 1..n of the first line's cells."""
    line = content.split(b"\n", 1)[0].decode("utf-8", errors="replace").strip().lstrip("\ufeff")
    if not line:
        raise DatasetError(f"{path}: the first line is empty, expected {'a header' if header else 'numbers'}")
    cells = [cell.strip() for cell in line.split(delimiter)]
    if not header:
        return [str(k) for k in range(1, len(cells) + 1)]
    if len(set(cells)) != len(cells):
        twice = next(cell for k, cell in enumerate(cells) if cell in cells[:k])
        raise DatasetError(f"{path}: column {twice!r} appears more than once in the header")
    return cells
