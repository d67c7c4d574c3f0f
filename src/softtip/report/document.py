"""A report: one self-contained HTML file (styles inline, figures as embedded PNG) that opens
offline, and the same content inline in Jupyter (``_repr_html_``)."""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field
from pathlib import Path

from softtip._core.files import atomic_write
from softtip.report.tables import Table

STYLE = """
.softtip-report { font-family: system-ui, sans-serif; color: #222; line-height: 1.4; }
body .softtip-report { margin: 2em auto; max-width: 78em; padding: 0 1em; }
.softtip-report h1 { font-size: 1.5em; margin-bottom: 0.2em; }
.softtip-report h2 { font-size: 1.15em; margin-top: 1.8em; border-bottom: 1px solid #ccc; }
.softtip-report .lead { color: #555; margin-top: 0; }
.softtip-report table { border-collapse: collapse; margin: 0.4em 0 0.2em; font-size: 0.88em; }
.softtip-report .paper-table { margin: 1.2em 0 1.4em; }
.softtip-report h3 { font-size: 1em; margin: 0 0 0.2em; }
.softtip-report .about { margin: 0 0 0.3em; max-width: 60em; font-size: 0.92em; }
.softtip-report .about .source { color: #555; } .softtip-report .about .look { color: #444; font-style: italic; }
.softtip-report th, .softtip-report td { border: 1px solid #ccc; padding: 0.2em 0.55em; vertical-align: top; }
.softtip-report th { background: #f3f3f3; text-align: left; font-weight: 600; }
.softtip-report td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.softtip-report td.blank { color: #aaa; text-align: center; }
.softtip-report .published { background: #eef3fb; color: #234; font-style: italic; }
.softtip-report tr.published th { background: #e3ebf8; }
.softtip-report td.within .mark { color: #1a7f37; }
.softtip-report td.outside { background: #fde8e4; } .softtip-report td.outside .mark { color: #b42318; }
.softtip-report td.better .mark { color: #1f5fbf; } .softtip-report td.fitted .mark { color: #777; }
.softtip-report td.note { max-width: 30em; font-size: 0.95em; color: #333; background: #fbfbf3; }
.softtip-report .legend { font-size: 0.85em; color: #444; margin: 0.1em 0 1.2em; }
.softtip-report .notes p { background: #f7f7f0; padding: 0.5em 0.9em; border-left: 3px solid #bb9; margin: 0.5em 0; }
.softtip-report figure { margin: 1em 0 1.5em; } .softtip-report img { max-width: 100%; }
.softtip-report figcaption { font-size: 0.9em; color: #333; max-width: 60em; }
.softtip-report code { background: #f3f3f3; padding: 0 0.2em; }
.softtip-report a { color: #1f5fbf; }
"""


def figure_png(figure) -> bytes:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100, bbox_inches="tight")
    return buffer.getvalue()


@dataclass(frozen=True)
class Figure:
    """A rendered plot: its title, a caption that says what to look for, and the PNG."""

    title: str
    caption: str
    png: bytes

    @classmethod
    def of(cls, title: str, caption: str, figure) -> Figure:
        """Render a matplotlib figure."""
        return cls(title, caption, figure_png(figure))

    def html(self) -> str:
        data = base64.b64encode(self.png).decode()
        return (f"<figure><img alt='{html.escape(self.title)}' src='data:image/png;base64,{data}'>"
                f"<figcaption><b>{html.escape(self.title)}.</b> {html.escape(self.caption)}</figcaption></figure>")


@dataclass
class Section:
    heading: str
    notes: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    html_parts: list[str] = field(default_factory=list)  # already-escaped fragments (links, lists)

    def html(self) -> str:
        parts = [f"<h2>{html.escape(self.heading)}</h2>"]
        if self.notes:
            parts.append("<div class='notes'>" + "".join(f"<p>{html.escape(n)}</p>" for n in self.notes) + "</div>")
        parts += [table.html() for table in self.tables]
        parts += self.html_parts
        parts += [figure.html() for figure in self.figures]
        return "\n".join(parts)


@dataclass
class Report:
    """Title, a lead line, and sections; ``html()`` is the whole self-contained page."""

    title: str
    lead: str = ""
    sections: list[Section] = field(default_factory=list)

    def body(self) -> str:
        lead = f"<p class='lead'>{html.escape(self.lead)}</p>" if self.lead else ""
        return (f"<div class='softtip-report'><h1>{html.escape(self.title)}</h1>{lead}\n"
                + "\n".join(section.html() for section in self.sections) + "</div>")

    def html(self) -> str:
        return (f"<!doctype html>\n<html lang='en'><head><meta charset='utf-8'>"
                f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
                f"<title>{html.escape(self.title)}</title><style>{STYLE}</style></head>"
                f"<body>{self.body()}</body></html>\n")

    def _repr_html_(self) -> str:
        return f"<style>{STYLE}</style>{self.body()}"

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return atomic_write(path, self.html())
