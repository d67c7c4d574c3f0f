"""What a study's analysis returns: its results (JSON), its paper-shaped tables, figures and notes,
and the one figure that heads its row in the index."""

from __future__ import annotations

from dataclasses import dataclass, field

from softtip.report.document import Figure
from softtip.report.tables import Comparison, Table


@dataclass(frozen=True)
class Headline:
    """The figure that sums a study up: softtip's value and, where the publication has one, its comparison."""

    label: str
    value: float | None
    unit: str
    comparison: Comparison | None = None

    @classmethod
    def of(cls, table: Table, row: str, column: str, label: str, unit: str | None = None) -> Headline:
        """The cell (row, column) of ``table``, with its comparison when it has a published figure;
        ``unit`` when the table's rows differ in unit."""
        match = [c for c in table.comparisons() if c.row == row and c.column == column]
        value = table.cells.get((row, column))
        unit = table.unit if unit is None else unit
        return cls(label, None if value is None else float(value), unit, match[0] if match else None)

    def to_dict(self) -> dict:
        return {"label": self.label, "softtip": self.value, "unit": self.unit,
                "published": None if self.comparison is None else self.comparison.published.text,
                "verdict": None if self.comparison is None else self.comparison.verdict,
                "source": None if self.comparison is None else self.comparison.source}


@dataclass
class StudyOutcome:
    results: dict
    tables: list[Table]
    figures: list[Figure]
    headline: Headline
    notes: list[str] = field(default_factory=list)
    designs: list[str] = field(default_factory=list)  # when the study runs several, e.g. designs A-D
