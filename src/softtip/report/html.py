"""One self-contained HTML report: tables from nested results, figures embedded as PNG."""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path
from typing import Any, Iterable

from softtip._core.files import atomic_write

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 72em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; } .note { background: #f7f7f0; padding: 0.6em 1em; border-left: 3px solid #bb9; }
code { background: #f3f3f3; padding: 0 0.2em; }
"""


def _rows(value: Any, path: tuple[str, ...] = ()) -> Iterable[tuple[tuple[str, ...], Any]]:
    """Leaves of nested dicts as (path, value); lists of numbers stay whole."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _rows(item, path + (str(key),))
    else:
        yield path, value


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f'<td class="num">{value:.4g}</td>'
    if isinstance(value, (int,)) and not isinstance(value, bool):
        return f'<td class="num">{value}</td>'
    if isinstance(value, list):
        return f"<td><code>{html.escape(json.dumps(value))}</code></td>"
    return f"<td>{html.escape(str(value))}</td>"


def results_table(results: dict) -> str:
    rows = list(_rows(results))
    depth = max((len(path) for path, _ in rows), default=1)
    head = "".join(f"<th>{'level ' + str(k + 1) if k else 'result'}</th>" for k in range(depth)) + "<th>value</th>"
    body = []
    for path, value in rows:
        cells = "".join(f"<td>{html.escape(part)}</td>" for part in path) + "<td></td>" * (depth - len(path))
        body.append(f"<tr>{cells}{_cell(value)}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def figure_png(figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    return base64.b64encode(buffer.getvalue()).decode()


def write_report(path: str | Path, title: str, sections: list[dict]) -> Path:
    """Sections: ``{"heading", "notes": [str], "results": dict, "figures": [(caption, figure)], "text": str}``."""
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1>"]
    for section in sections:
        parts.append(f"<h2>{html.escape(section['heading'])}</h2>")
        if section.get("text"):
            parts.append(f"<p>{html.escape(section['text'])}</p>")
        for note in section.get("notes", []):
            parts.append(f"<p class='note'>{html.escape(note)}</p>")
        if section.get("results"):
            parts.append(results_table(section["results"]))
        for caption, figure in section.get("figures", []):
            parts.append(f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{figure_png(figure)}'>"
                         f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, "\n".join(parts))
