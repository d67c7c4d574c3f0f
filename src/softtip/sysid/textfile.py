"""Text files of numbers as sysid reads them: DaISy's whitespace ``.dat`` files, MATLAB's ``save
-ascii``, a logger's ``.txt``, and CSV files without a header.

The data stage's delimited-text reader (:func:`softtip.data.csvload.read_columns`) parses them; here a
header row is recognised (a first line that is not all numbers), and the columns of a file without
one are named ``names`` or, lacking those, by their position (``1``, ``2`` ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from softtip.data.csvload import WHITESPACE, read_columns
from softtip.data.dataset import DatasetError, first_line

SUFFIXES = (".dat", ".txt")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _first_cells(path: Path, delimiter: str | None) -> list[str]:
    """The cells of the file's first line that is not blank."""
    try:
        with path.open(encoding="utf-8") as handle:
            line = next((line for line in handle if line.strip()), "")
    except (OSError, UnicodeDecodeError) as problem:
        raise DatasetError(f"{path}: cannot be read as text ({first_line(problem)})") from None
    if not line:
        raise DatasetError(f"{path}: no rows of numbers")
    return [cell.strip() for cell in line.strip().lstrip("\ufeff").split(delimiter)]


def text_columns(path: Path, names: Sequence[str] | None = None, delimiter: str | None = None
                 ) -> dict[str, np.ndarray]:
    """Every column of the file at ``path`` as float64, by name: its header's names, else ``names``, else
    1, 2 ... by position. ``delimiter``: the character between fields (None: runs of whitespace)."""
    cells = _first_cells(path, delimiter)
    if delimiter is None and any(mark in cells[0] for mark in ",;"):
        raise DatasetError(f"{path}: its first line is separated by commas or semicolons, not whitespace: "
                           "name the file .csv")
    header = not all(_is_number(cell) for cell in cells)
    if header and names is not None:
        raise DatasetError(f"{path}: the file names its columns in its first line ({' '.join(cells)}); "
                           "column names are for a file without a header")
    if names is not None and len(names) != len(cells):
        raise DatasetError(f"{path}: {len(names)} column names given for {len(cells)} columns "
                           f"(its first line: {' '.join(cells)})")
    columns: list[int | str] = cells if header else list(range(1, len(cells) + 1))
    values = read_columns(path, columns, header=header, delimiter=WHITESPACE if delimiter is None else delimiter)
    called = cells if header else (list(names) if names is not None else [str(k) for k in columns])
    return {name: values[:, k] for k, name in enumerate(called)}
