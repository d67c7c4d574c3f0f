"""Whitespace-separated text files of numbers: DaISy's ``.dat`` files, MATLAB's ``save -ascii``, a
logger's ``.txt`` (and a CSV file without a header, named from outside).

Rows of equal length, separated by spaces or tabs; an optional first row of column names; lines that
start with ``%`` or ``#`` are comments. A file without a header names its columns by position
(``1``, ``2`` ...) unless names are given. Every refusal is one
:class:`~softtip.data.DatasetError` line naming the file and, for a bad cell, its line and column.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from softtip.data.dataset import DatasetError, first_line

SUFFIXES = (".dat", ".txt")
_COMMENTS = ("%", "#")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _rows(path: Path, delimiter: str | None) -> list[tuple[int, list[str]]]:
    """(line number, fields) of every line that is neither blank nor a comment; fields split at
    ``delimiter`` (None: runs of whitespace)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as problem:
        raise DatasetError(f"{path}: cannot be read as text ({first_line(problem)})") from None
    return [(number, [field.strip() for field in line.split(delimiter)]) for number, line in enumerate(lines, start=1)
            if line.strip() and not line.lstrip().startswith(_COMMENTS)]


def _header(path: Path, rows: list[tuple[int, list[str]]], names: Sequence[str] | None,
            delimiter: str | None) -> list[str]:
    """The column names: the first row's when it is not numbers (and then removed from ``rows``),
    else ``names``, else the positions 1, 2 ..."""
    if not rows:
        raise DatasetError(f"{path}: no rows of numbers")
    first = rows[0][1]
    if delimiter is None and any(mark in rows[0][1][0] for mark in ",;"):
        raise DatasetError(f"{path}: line {rows[0][0]} is separated by commas or semicolons, not whitespace: "
                           "name the file .csv")
    if not all(_is_number(field) for field in first):
        if names is not None:
            raise DatasetError(f"{path}: the file names its columns in its first line ({' '.join(first)}); "
                               "column names are for a file without a header")
        rows.pop(0)
        return first
    if names is None:
        return [str(k) for k in range(1, len(first) + 1)]
    if len(names) != len(first):
        raise DatasetError(f"{path}: {len(names)} column names given for {len(first)} columns "
                           f"(line {rows[0][0]}: {' '.join(first)})")
    return list(names)


def whitespace_columns(path: Path, names: Sequence[str] | None = None,
                       delimiter: str | None = None) -> dict[str, np.ndarray]:
    """Every column of the file at ``path`` as float64, by name (see the module's notes); ``delimiter``
    a character between fields in place of whitespace (a CSV file without a header)."""
    rows = _rows(path, delimiter)
    header = _header(path, rows, names, delimiter)
    if len(set(header)) < len(header):
        repeated = next(name for name in header if header.count(name) > 1)
        raise DatasetError(f"{path}: column {repeated!r} appears more than once")
    if not rows:
        raise DatasetError(f"{path}: a header and no rows of numbers")
    for number, fields in rows:
        if len(fields) != len(header):
            raise DatasetError(f"{path}: line {number} has {len(fields)} values, expected {len(header)} "
                               f"({', '.join(header)})")
    try:
        values = np.array([fields for _, fields in rows], dtype=np.float64)
    except ValueError:
        number, column, cell = next((number, header[k], field) for number, fields in rows
                                    for k, field in enumerate(fields) if not _is_number(field))
        raise DatasetError(f"{path}: column {column!r}, line {number}: {cell!r} is not a number") from None
    return {name: values[:, k] for k, name in enumerate(header)}
