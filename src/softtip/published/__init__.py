"""The published figures each study follows, as data: one ``published.toml`` per registered system,
laid out as the publications' tables, read by the reports, by ``softtip reproduce --json`` and by
the tests. No published number is typed anywhere else.

A cell is a number as printed, a bound the publication states (``"< 0.5"``, ``"<= 10"``, ``"> 0.9"``),
a range (``"0.8..0.92"``) or blank (``""``). A table's ``close`` says when softtip's figure counts
as close to a published number, and why; ``better = "lower"`` or ``"higher"`` (or a list, one per
column, ``""`` for none) makes a figure past the published one on that side count as meeting it; ``fitted = true`` marks a figure a model
parameter was set from (agreement by construction, not a prediction).

The publications' procedures are data there too: ``[procedures.PROTOCOL]`` gives a ``source`` and,
under a protocol's own parameter names, the value the publication used (a number, true/false, a list
of numbers or of [x, y] pairs); a protocol's report marks every setting that differs from it.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Mapping

import numpy as np

from softtip._core.systems import systems
from softtip._core.config import ConfigError, Flag, PositiveNumber, Text, choice, integer, parse, read_toml, schema

WITHIN, OUTSIDE, BETTER, FITTED = "within", "outside", "better", "fitted"
Direction = choice("lower", "higher")
_BOUND = re.compile(r"\s*(<=|>=|<|>)\s*([-+0-9.eE]+)\s*")
_RANGE = re.compile(r"\s*([-+0-9.eE]+)\s*\.\.\s*([-+0-9.eE]+)\s*")


@dataclass(frozen=True)
class PublishedValue:
    """One cell: a number (``low == high``), a bound (one side infinite) or a range, as printed."""

    low: float
    high: float
    text: str

    @property
    def is_number(self) -> bool:
        return self.low == self.high

    @property
    def centre(self) -> float | None:
        """The number, or the middle of a range; None for a one-sided bound."""
        return (self.low + self.high) / 2 if math.isfinite(self.low) and math.isfinite(self.high) else None


def parse_value(value: Any, digits: int, where: str) -> PublishedValue | None:
    """A cell of a published table: None for a blank."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a number, a bound like '< 0.5', a range like '0.8..0.92' or ''")
    if isinstance(value, int):  # a count, printed as one
        return PublishedValue(float(value), float(value), str(value))
    if isinstance(value, float):
        return PublishedValue(value, value, f"{value:.{digits}f}")
    if isinstance(value, str) and not value.strip():
        return None
    if isinstance(value, str) and (bound := _BOUND.fullmatch(value)):
        limit = float(bound[2])
        low, high = (-math.inf, limit) if bound[1].startswith("<") else (limit, math.inf)
        return PublishedValue(low, high, f"{bound[1]} {bound[2]}")
    if isinstance(value, str) and (span := _RANGE.fullmatch(value)):
        low, high = float(span[1]), float(span[2])
        if low < high:
            return PublishedValue(low, high, f"{span[1]}–{span[2]}")
    raise ConfigError(f"{where} = {value!r}: expected a number, a bound like '< 0.5', a range like '0.8..0.92' or ''")


@schema
class Closeness:
    """When softtip's figure is close to a published number: within a ``ratio`` or an ``absolute`` gap."""

    why: Text
    ratio: PositiveNumber | None = None
    absolute: PositiveNumber | None = None

    def __post_init__(self):
        if (self.ratio is None) == (self.absolute is None):
            raise ConfigError("close: expected exactly one of ratio or absolute")
        if self.ratio is not None and self.ratio <= 1:
            raise ConfigError(f"close.ratio = {self.ratio}: expected a factor > 1")

    def describe(self, unit: str) -> str:
        if self.ratio is not None:
            return f"within a factor {self.ratio:g}"
        return f"within ±{self.absolute:g}{' ' + unit if unit else ''}"

    def holds(self, value: float, published: float) -> bool:
        slack = 1 + 1e-12  # a gap equal to the tolerance holds, whatever the binary rounding
        if self.absolute is not None:
            return abs(value - published) <= self.absolute * slack
        if published == 0 or value == 0:
            return value == published
        ratio = value / published
        return ratio > 0 and 1 / (self.ratio * slack) <= ratio <= self.ratio * slack


@schema
class _TableFile:
    study: Text
    title: Text
    source: Text
    unit: str
    digits: integer(0, 6)
    row_label: Text
    rows: list[Text]
    columns: list[Text]
    values: list[list[Any]]
    close: Closeness | None = None
    better: Direction | list[Direction | Literal[""]] | None = None
    fitted: Flag = False


@dataclass(frozen=True)
class PublishedTable:
    """One table of a publication: its cells by (row, column), what close means for them, and where it is."""

    key: str
    system: str
    study: str
    title: str
    source: str
    unit: str
    digits: int
    row_label: str
    rows: tuple[str, ...]
    columns: tuple[str, ...]
    cells: tuple[tuple[PublishedValue | None, ...], ...]
    close: Closeness | None
    better: tuple[str | None, ...]  # per column: "lower", "higher" or None
    fitted: bool

    def value(self, row: str, column: str) -> PublishedValue | None:
        if row not in self.rows or column not in self.columns:
            raise KeyError(f"published table {self.key} has no cell ({row!r}, {column!r}): rows {list(self.rows)}, "
                           f"columns {list(self.columns)}")
        return self.cells[self.rows.index(row)][self.columns.index(column)]

    def verdict(self, value: float, published: PublishedValue, column: str) -> str:
        """``within``, ``outside``, ``better`` (past the published figure on its column's better side)
        or ``fitted`` (a figure the model was set from, judged within/outside all the same)."""
        if not math.isfinite(value):
            return OUTSIDE
        better = self.better[self.columns.index(column)]
        if better == "lower" and value < published.low or better == "higher" and value > published.high:
            return BETTER
        if published.is_number and self.close is not None:
            close = self.close.holds(value, published.low)
        else:
            close = published.low <= value <= published.high
        if self.fitted:
            return FITTED if close else OUTSIDE
        return WITHIN if close else OUTSIDE

    def tolerance(self) -> str:
        """What close means, in words, with its reason."""
        if self.close is None:
            return "within the stated bound"
        return f"{self.close.describe(self.unit)} ({self.close.why})"


def _table(system: str, source: str, key: str, table: dict) -> PublishedTable:
    parsed = parse(_TableFile, table, source, key)
    if len(parsed.values) != len(parsed.rows):
        raise ConfigError(f"{source}: {key}.values has {len(parsed.values)} rows for {len(parsed.rows)} row names")
    cells = []
    for i, row in enumerate(parsed.values):
        if len(row) != len(parsed.columns):
            raise ConfigError(f"{source}: {key}.values[{i}] has {len(row)} cells for {len(parsed.columns)} columns")
        cells.append(tuple(parse_value(value, parsed.digits, f"{source}: {key}.values[{i}][{j}]")
                           for j, value in enumerate(row)))
    better = parsed.better if isinstance(parsed.better, list) else [parsed.better] * len(parsed.columns)
    if len(better) != len(parsed.columns):
        raise ConfigError(f"{source}: {key}.better has {len(better)} directions for {len(parsed.columns)} columns")
    numbers = [cell for row in cells for cell in row if cell is not None and cell.is_number]
    if numbers and parsed.close is None:
        raise ConfigError(f"{source}: {key}: its numbers need a close = {{ ratio or absolute, why }}")
    return PublishedTable(key=key, system=system, study=parsed.study, title=parsed.title, source=parsed.source,
                          unit=parsed.unit, digits=parsed.digits, row_label=parsed.row_label, rows=tuple(parsed.rows),
                          columns=tuple(parsed.columns), cells=tuple(cells), close=parsed.close, better=tuple(b or None for b in better),
                          fitted=parsed.fitted)


def published_tables() -> dict[str, PublishedTable]:
    """Every published table of every registered system, by key (read again when the registry changes)."""
    return _published_of_files(_system_files())[0]


PROCEDURES = "procedures"  # published.toml's key of the publications' procedures, not a table of figures
ProcedureValue = bool | float | tuple[float, ...] | tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class PublishedProcedure:
    """How the publication ran one protocol's experiment: the value it used for each parameter it states."""

    protocol: str
    system: str
    source: str
    settings: Mapping[str, ProcedureValue]

    def differs(self, key: str, value: Any) -> bool | None:
        """Whether softtip's ``value`` of parameter ``key`` differs from the published one; None when the
        publication states none."""
        if key not in self.settings:
            return None
        published = self.settings[key]
        if isinstance(published, bool) or isinstance(value, bool):
            return published is not value
        mine, theirs = np.asarray(value, dtype=float), np.asarray(published, dtype=float)
        return mine.shape != theirs.shape or not np.allclose(mine, theirs, rtol=1e-9, atol=0.0)


def _procedure_value(value: Any, where: str) -> ProcedureValue:
    # numbers kept as written (a count stays an integer in reports); differs() compares them as floats
    numbers = (int, float)
    if isinstance(value, bool) or isinstance(value, numbers):
        return value
    if isinstance(value, list) and value and all(isinstance(v, numbers) and not isinstance(v, bool) for v in value):
        return tuple(value)
    if isinstance(value, list) and value and all(
            isinstance(v, list) and len(v) == 2 and all(isinstance(c, numbers) and not isinstance(c, bool) for c in v)
            for v in value):
        return tuple(tuple(v) for v in value)
    raise ConfigError(f"{where} = {value!r}: expected a number, true/false, a list of numbers or of [x, y] pairs")


def _procedures(label: str, source: str, table: Any) -> dict[str, PublishedProcedure]:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: {PROCEDURES}: expected a table of [{PROCEDURES}.PROTOCOL] tables")
    procedures = {}
    for protocol, entries in table.items():
        where = f"{source}: {PROCEDURES}.{protocol}"
        if not isinstance(entries, dict) or not isinstance(entries.get("source"), str) or not entries["source"].strip():
            raise ConfigError(f"{where}: expected a table with a source (text) and the published parameters")
        settings = {key: _procedure_value(value, f"{where}.{key}") for key, value in entries.items() if key != "source"}
        procedures[protocol] = PublishedProcedure(protocol, label, entries["source"], settings)
    return procedures


def published_procedure(protocol: str) -> PublishedProcedure | None:
    """The published procedure of protocol ``protocol``, if its system's ``published.toml`` declares one."""
    return _published_of_files(_system_files())[1].get(protocol)


def _system_files() -> tuple[tuple[str, str, str], ...]:
    return tuple((system.name, system.label, str(file)) for system in systems().values()
                 if (file := system.published()) is not None)


@functools.cache
def _published_of_files(files: tuple[tuple[str, str, str], ...]
                        ) -> tuple[dict[str, PublishedTable], dict[str, PublishedProcedure]]:
    tables: dict[str, PublishedTable] = {}
    procedures: dict[str, PublishedProcedure] = {}
    for name, label, file in files:
        source = f"{name}: published.toml"
        for key, table in read_toml(Path(file), "published figures").items():
            if key == PROCEDURES:
                procedures |= _procedures(label, source, table)
                continue
            if key in tables:
                raise ConfigError(f"{source}: table {key} is also {tables[key].system}'s")
            tables[key] = _table(label, source, key, table)
    return tables, procedures


def published_table(key: str) -> PublishedTable:
    tables = published_tables()
    if key not in tables:
        raise KeyError(f"no published table {key!r}: expected one of {', '.join(tables)}")
    return tables[key]


def tables_of(study: str) -> list[PublishedTable]:
    """The published tables study ``study`` follows, in file order."""
    return [table for table in published_tables().values() if table.study == study]
