"""The published-figure registry and the paper tables built on it, against hand-worked cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from softtip._core.config import ConfigError
from softtip.published import (BETTER, FITTED, OUTSIDE, WITHIN, PublishedTable, _table, parse_value, published_table,
                               published_tables, tables_of)
from softtip.report.tables import Table, format_number, paper_table
from softtip._core.systems import studies


def test_cells_read_as_printed_numbers_bounds_ranges_and_blanks():
    assert parse_value(1.584, 3, "t") .text == "1.584"
    assert parse_value(2197, 1, "t").text == "2197" and parse_value(10.0, 1, "t").text == "10.0"  # a count as one
    bound = parse_value("< 0.5", 2, "t")
    assert (bound.low, bound.high, bound.centre) == (-math.inf, 0.5, None)
    at_least = parse_value(">= 0.9", 2, "t")
    assert (at_least.low, at_least.high) == (0.9, math.inf)
    band = parse_value("0.8..0.92", 2, "t")
    assert (band.low, band.high) == (0.8, 0.92) and band.centre == pytest.approx(0.86)
    assert parse_value("", 2, "t") is None
    for bad in ("about 3", True, "0.9..0.8", [1.0]):
        with pytest.raises(ConfigError, match="t"):
            parse_value(bad, 2, "t")


def test_the_s1_tables_hold_the_publications_cells():
    # spot checks against S1's publications: article Table 2 (design D, network), thesis Table 9 (state 3, trial 2)
    assert published_table("pushing-orientation-error").value("D", "network (FNN)").low == 0.779
    assert published_table("inverter-detection-force").value("3 (right clip hits)", "2").low == 0.48
    assert published_table("grasp-positions-trained").value("Fg (N)", "overall").high == 0.5
    # each published average of Table 9 is the mean of its ten trials, to the two decimals printed
    table = published_table("inverter-detection-force")
    for row in table.rows:
        cells = table.cells[table.rows.index(row)]
        assert sum(c.low for c in cells[:10]) / 10 == pytest.approx(cells[10].low, abs=0.006), row
    # every table belongs to a study softtip reproduces
    assert {t.study for t in published_tables().values()} <= set(studies())
    assert [t.key for t in tables_of("pushing")] == ["pushing-feature-displacement", "pushing-orientation-error",
                                                     "pushing-estimate-time"]


def _toy(**changes) -> PublishedTable:
    table = {"study": "pushing", "title": "t", "source": "Table 1", "unit": "deg", "digits": 2, "row_label": "r",
             "rows": ["a"], "columns": ["x", "y", "z"], "values": [[2.0, "< 0.5", "0.8..0.92"]],
             "close": {"ratio": 2.0, "why": "same size"}}
    table.update(changes)
    return _table("S0", "a system: published.toml", "toy", table)


def test_verdicts_follow_the_stated_tolerance():
    toy = _toy()
    number, bound, band = toy.cells[0]
    assert [toy.verdict(v, number, "x") for v in (1.0, 4.0, 0.99, 4.01, -2.0)] == [WITHIN, WITHIN, OUTSIDE, OUTSIDE,
                                                                                   OUTSIDE]
    assert [toy.verdict(v, bound, "y") for v in (0.49, 0.5, 0.51, math.nan)] == [WITHIN, WITHIN, OUTSIDE, OUTSIDE]
    assert [toy.verdict(v, band, "z") for v in (0.8, 0.95)] == [WITHIN, OUTSIDE]
    absolute = _toy(close={"absolute": 0.1, "why": "w"})
    assert [absolute.verdict(v, number, "x") for v in (2.1, 2.11)] == [WITHIN, OUTSIDE]
    higher = _toy(better="higher")
    assert higher.verdict(0.95, band, "z") == BETTER and higher.verdict(0.7, band, "z") == OUTSIDE
    # one direction per column: lower is better for x only
    mixed = _toy(better=["lower", "", "higher"])
    assert mixed.verdict(0.5, number, "x") == BETTER and mixed.verdict(0.95, band, "z") == BETTER
    assert mixed.verdict(0.3, bound, "y") == WITHIN
    fitted = _toy(fitted=True)
    assert fitted.verdict(2.5, number, "x") == FITTED and fitted.verdict(5.0, number, "x") == OUTSIDE


def test_malformed_tables_are_refused_in_one_line():
    with pytest.raises(ConfigError, match="toy.values has 2 rows for 1 row names"):
        _toy(values=[[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    with pytest.raises(ConfigError, match=r"toy.values\[0\] has 2 cells for 3 columns"):
        _toy(values=[[1.0, 1.0]])
    with pytest.raises(ConfigError, match="need a close"):
        _toy(close=None)
    with pytest.raises(ConfigError, match="toy.better has 1 directions for 3 columns"):
        _toy(better=["lower"])
    with pytest.raises(ConfigError, match="exactly one of ratio or absolute"):
        _toy(close={"ratio": 2.0, "absolute": 1.0, "why": "w"})


def test_a_paper_table_compares_each_cell_with_its_published_figure():
    published = published_table("pushing-orientation-error")
    table = paper_table(published, {("A", "network (FNN)"): 2.5, ("D", "network (FNN)"): 0.5})
    by_row = {c.row: c for c in table.comparisons()}
    # A: 2.5 / 1.185 = 2.11 > 2 -> outside; D: 0.5 / 0.779 = 0.64 -> within; difference is softtip - published
    assert by_row["A"].verdict == OUTSIDE and by_row["D"].verdict == WITHIN
    assert by_row["D"].to_dict()["difference"] == pytest.approx(0.5 - 0.779)
    page = table.html()
    assert page.count("class='published num'") == 8  # every published cell shown, softtip's or not
    assert "1.185" in page and "2.500" in page and "✗" in page and "✓" in page
    with pytest.raises(KeyError, match="no cell"):
        paper_table(published, {("E", "network (FNN)"): 1.0})


def test_numbers_keep_the_published_decimals_but_two_significant_figures():
    assert format_number(1.23456, 3) == "1.235"
    assert format_number(0.00123, 2) == "0.0012"
    assert format_number(82.4, 0) == "82" and format_number(0.05, 0) == "0.05"
    assert format_number(math.nan, 2) == "n/a"
    # a count is printed as one, whatever the table's decimals
    assert format_number(2197, 1) == "2197" and format_number(np.int64(3), 2) == "3"
    assert format_number(3.0, 2) == "3.00"


def test_a_table_without_a_publication_shows_only_softtips_figures():
    table = Table("t", "r", ["a"], ["x"], {("a", "x"): 1.0}, unit="N")
    assert table.comparisons() == [] and "published" not in table.html() and "x (N)" in table.html()


def test_several_of_softtips_rows_face_one_published_row():
    # S2 publishes one range over the three force axes: each axis faces it
    published = published_table("wearable-offline")
    rows = {f"transfer function, order 6 · {axis}": "transfer function, order 6" for axis in ("Fx", "Fy", "Fz")}
    table = paper_table(published, {("transfer function, order 6 · Fx", "R²"): 0.85,
                                    ("transfer function, order 6 · Fy", "R²"): 0.7,
                                    ("transfer function, order 6 · Fz", "R²"): 0.95,
                                    ("transfer function, order 6 · Fz", "RMSE (% FS)"): 12.0}, rows=rows)
    verdicts = {(c.row[-2:], c.column): c.verdict for c in table.comparisons()}
    assert verdicts == {("Fx", "R²"): WITHIN, ("Fy", "R²"): OUTSIDE, ("Fz", "R²"): BETTER,
                        ("Fz", "RMSE (% FS)"): OUTSIDE}
    assert table.rows == list(rows)
    with pytest.raises(KeyError, match="no row"):
        paper_table(published, {}, rows={"a": "nope"})


def test_a_report_is_one_self_contained_page_and_renders_inline_in_jupyter(tmp_path):
    import base64
    import re

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softtip.report.document import Figure, Report, Section

    figure, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    table = paper_table(published_table("hysteresis"), {("hysteresis", "1 mm/s, 3 s rest"): 7.1})
    report = Report("t", "lead", [Section("s", ["a note"], [table], [Figure.of("f", "what to look for", figure)])])
    page = report.write(tmp_path / "r.html").read_text()
    assert page.startswith("<!doctype html>") and "<style>" in page
    assert not re.search(r"(src|href)=['\"](?!data:)", page)  # nothing to fetch: it opens offline
    png = base64.b64decode(re.search(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)[1])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    inline = report._repr_html_()
    assert "<html" not in inline and "<style>" in inline and "7.3" in inline and "✓" in inline
