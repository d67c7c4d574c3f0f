"""``index.html``: one row per study report — its headline figure, the published one, the verdict,
how many of its comparisons fall outside their tolerance, the run time and a link."""

from __future__ import annotations

import html

from softtip.report.document import Report, Section
from softtip.report.tables import MARKS, format_number


def _headline(entry: dict) -> tuple[str, str, str]:
    headline = entry["headline"]
    value = headline.get("softtip")
    unit = headline.get("unit") or ""
    shown = "n/a" if value is None else f"{format_number(value, 3)} {unit}".strip()
    published = headline.get("published") or "— (no published figure)"
    return html.escape(headline["label"]), html.escape(shown), html.escape(published)


def index_report(entries: list[dict]) -> Report:
    """The index of study reports; each entry is a study report's JSON (see softtip.studies.reproduce)."""
    rows = []
    for entry in entries:
        label, value, published = _headline(entry)
        verdict = entry["headline"].get("verdict")
        verdict_cell = ("<td class='blank'>—</td>" if verdict is None else
                        f"<td class='{verdict}'><span class='mark'>{MARKS[verdict]}</span> {html.escape(verdict)}</td>")
        total, outside = len(entry["comparisons"]), entry["outside"]
        provenance = entry["provenance"]
        quick = " (quick)" if provenance.get("quick (smoke run)", "no") != "no" else ""
        rows.append(
            f"<tr><th><a href='{html.escape(entry['report'])}'>{html.escape(entry['study'])}</a></th>"
            f"<td>{html.escape(entry['follows'])}</td><td>{label}</td><td class='num'>{value}</td>"
            f"<td class='published num'>{published}</td>{verdict_cell}"
            f"<td class='num'>{outside} of {total}</td><td class='num'>{entry['seconds']:.0f} s</td>"
            f"<td>{html.escape(provenance.get('seed', ''))}{quick}</td></tr>")
    table = ("<div class='paper-table'><p class='about'><span class='look'>Each study's headline figure beside "
             "the published one; 'outside tolerance' counts the study's comparisons outside their tolerance (each "
             "explained in its report).</span></p><table class='paper'><thead><tr><th>study</th><th>follows</th><th>headline</th>"
             "<th>softtip</th><th class='published'>published</th><th>verdict</th><th>outside tolerance</th>"
             "<th>run time</th><th>seed</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table></div>")
    versions = sorted({e["provenance"].get("softtip version", "") for e in entries})
    return Report("softtip reproduce: index", f"{len(entries)} studies; softtip {', '.join(versions)}",
                  [Section("Studies", html_parts=[table])])
