"""Paper-shaped tables: rows and columns as the publication laid them out, softtip's figure in each
cell, the published figure beside it (visually distinct), and the verdict of every comparison.

A table follows a :class:`~softtip.published.PublishedTable` (``paper_table``) or stands alone
(``Table(...)``: softtip's own figures, e.g. a matrix the publication only drew). Narrow tables put
each published column beside softtip's (``layout="columns"``); wide ones (angles across) put the
published row under softtip's (``layout="rows"``).
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from typing import Literal, Mapping

import numpy as np

from softtip.published import BETTER, FITTED, OUTSIDE, WITHIN, PublishedTable, PublishedValue

MARKS = {WITHIN: "✓", OUTSIDE: "✗", BETTER: "▲", FITTED: "◆"}
MEANINGS = {WITHIN: "close to the published figure", OUTSIDE: "outside the tolerance: a gap the notes explain",
            BETTER: "past the published figure on its better side", FITTED: "a figure the model was set from (not a prediction)"}


def format_number(value: float, digits: int) -> str:
    """``digits`` decimals as the publication prints them, but never fewer than two significant figures;
    an integer (a count) as it is."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    if not math.isfinite(value):
        return "n/a"
    if value != 0 and abs(value) < 10 ** (1 - digits):
        return f"{value:.2g}"
    return f"{value:.{digits}f}"


@dataclass(frozen=True)
class Comparison:
    """softtip's figure beside a published one."""

    table: str
    row: str
    column: str
    value: float
    published: PublishedValue
    unit: str
    verdict: str
    source: str

    @property
    def difference(self) -> float | None:
        """softtip minus the published number (or the middle of a published range); None for a bound."""
        centre = self.published.centre
        return None if centre is None else self.value - centre

    def to_dict(self) -> dict:
        difference = self.difference
        return {"table": self.table, "row": self.row, "column": self.column, "softtip": _plain(self.value),
                "published": self.published.text, "unit": self.unit,
                "difference": None if difference is None else _plain(difference), "verdict": self.verdict,
                "source": self.source}


def _plain(value: float) -> float | None:
    return round(float(value), 6) if math.isfinite(value) else None


Value = float | str | None


@dataclass
class Table:
    """A table of softtip's figures. ``cells`` maps (row, column) to a number, a text or None (blank);
    ``notes`` maps a row to the note that explains its gap; ``caption`` says what to look for."""

    title: str
    row_label: str
    rows: list[str]
    columns: list[str]
    cells: Mapping[tuple[str, str], Value]
    unit: str = ""
    digits: int = 3
    caption: str = ""
    notes: Mapping[str, str] = field(default_factory=dict)
    published: PublishedTable | None = None
    layout: Literal["columns", "rows"] = "columns"
    published_rows: Mapping[str, str] = field(default_factory=dict)  # a row -> the published row it faces

    def comparisons(self) -> list[Comparison]:
        """Every cell that has both softtip's number and a published figure."""
        if self.published is None:
            return []
        found = []
        for row in self.rows:
            for column in self.columns:
                value, published = self.cells.get((row, column)), self._published(row, column)
                if isinstance(value, (int, float)) and published is not None:
                    found.append(Comparison(self.published.key, row, column, float(value), published,
                                            self.published.unit, self.published.verdict(float(value), published, column),
                                            self.published.source))
        return found

    def _published(self, row: str, column: str) -> PublishedValue | None:
        row = self.published_rows.get(row, row)
        if self.published is None or row not in self.published.rows or column not in self.published.columns:
            return None
        return self.published.value(row, column)

    # -- HTML --------------------------------------------------------------

    def _unit_header(self, column: str) -> str:
        return f"{column} ({self.unit})" if self.unit else column

    def _softtip_cell(self, row: str, column: str, verdicts: dict) -> str:
        value = self.cells.get((row, column))
        if value is None:
            return "<td class='blank'>—</td>"
        if isinstance(value, str):
            return f"<td>{html.escape(value)}</td>"
        comparison = verdicts.get((row, column))
        if comparison is None:
            return f"<td class='num'>{format_number(value, self.digits)}</td>"
        difference = comparison.difference
        tip = f"published {comparison.published.text}" + ("" if difference is None else f"; difference {difference:+.3g}")
        return (f"<td class='num {comparison.verdict}' title='{html.escape(tip)}'>"
                f"{format_number(value, self.digits)} <span class='mark'>{MARKS[comparison.verdict]}</span></td>")

    def _published_cell(self, row: str, column: str) -> str:
        published = self._published(row, column)
        if published is None:
            return "<td class='published blank'>—</td>"
        return f"<td class='published num'>{html.escape(published.text)}</td>"

    def html(self) -> str:
        verdicts = {(c.row, c.column): c for c in self.comparisons()}
        parts = [f"<div class='paper-table'><h3>{html.escape(self.title)}</h3><p class='about'>"]
        if self.published is not None:
            parts.append(f"<span class='source'>Published: {html.escape(self.published.source)}.</span> ")
        if self.caption:
            parts.append(f"<span class='look'>{html.escape(self.caption)}</span>")
        parts.append("</p><table class='paper'>")
        has_notes = any(row in self.notes for row in self.rows)
        paired = self.published is not None and self.layout == "columns"
        head = f"<th>{html.escape(self.row_label)}</th>"
        if paired:
            top = f"<th rowspan='2'>{html.escape(self.row_label)}</th>" + "".join(
                f"<th colspan='2'>{html.escape(self._unit_header(c))}</th>" for c in self.columns)
            sub = "".join("<th>softtip</th><th class='published'>published</th>" for _ in self.columns)
            parts.append(f"<thead><tr>{top}{'<th rowspan=2>note</th>' if has_notes else ''}</tr><tr>{sub}</tr></thead>")
        else:
            head += "".join(f"<th>{html.escape(self._unit_header(c))}</th>" for c in self.columns)
            parts.append(f"<thead><tr>{head}{'<th>note</th>' if has_notes else ''}</tr></thead>")
        parts.append("<tbody>")
        for row in self.rows:
            note = f"<td class='note'>{html.escape(self.notes[row])}</td>" if row in self.notes else (
                "<td></td>" if has_notes else "")
            if paired:
                cells = "".join(self._softtip_cell(row, c, verdicts) + self._published_cell(row, c) for c in self.columns)
                parts.append(f"<tr><th>{html.escape(row)}</th>{cells}{note}</tr>")
            elif self.published is not None:
                cells = "".join(self._softtip_cell(row, c, verdicts) for c in self.columns)
                published = "".join(self._published_cell(row, c) for c in self.columns)
                span = " rowspan='2'" if has_notes else ""
                note = note.replace("<td", f"<td{span}", 1) if has_notes else ""
                parts.append(f"<tr><th>{html.escape(row)} · softtip</th>{cells}{note}</tr>"
                             f"<tr class='published'><th>{html.escape(row)} · published</th>{published}</tr>")
            else:
                cells = "".join(self._softtip_cell(row, c, verdicts) for c in self.columns)
                parts.append(f"<tr><th>{html.escape(row)}</th>{cells}{note}</tr>")
        parts.append("</tbody></table>")
        if verdicts:
            used = sorted({c.verdict for c in verdicts.values()}, key=list(MARKS).index)
            legend = "; ".join(f"{MARKS[v]} {MEANINGS[v]}" for v in used)
            parts.append(f"<p class='legend'>{html.escape(legend)}. Close means "
                         f"{html.escape(self.published.tolerance())}.</p>")
        parts.append("</div>")
        return "".join(parts)


def paper_table(published: PublishedTable, cells: Mapping[tuple[str, str], Value], *, caption: str = "",
                notes: Mapping[str, str] | None = None, layout: Literal["columns", "rows"] | None = None,
                rows: Mapping[str, str] | None = None) -> Table:
    """The publication's table with softtip's figures in its cells (rows and columns as published).
    ``rows`` maps softtip's own rows to the published row each faces, when the publication gives one
    figure for several of softtip's (a range over axes, say); softtip's rows then replace the published."""
    rows = dict(rows or {})
    names = list(rows) if rows else list(published.rows)
    unknown = [r for r, p in rows.items() if p not in published.rows]
    if unknown:
        raise KeyError(f"published table {published.key} has no row {rows[unknown[0]]!r}: rows {list(published.rows)}")
    unknown = [key for key in cells if key[0] not in names or key[1] not in published.columns]
    if unknown:
        raise KeyError(f"published table {published.key} has no cell {unknown[0]}: rows {names}, "
                       f"columns {list(published.columns)}")
    if layout is None:
        layout = "columns" if len(published.columns) <= 4 else "rows"
    return Table(title=published.title, row_label=published.row_label, rows=names, columns=list(published.columns),
                 cells=dict(cells), unit=published.unit, digits=published.digits, caption=caption,
                 notes=dict(notes or {}), published=published, layout=layout, published_rows=rows)
