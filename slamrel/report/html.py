"""Self-contained HTML reports.

A report is a list of sections, each with a heading, prose, tables and figures. Figures are
embedded as base64 PNG, styles are inline: the single ``report.html`` opens offline. Every
number shown in a table comes from the same dictionaries that are written to
``metrics.json``, so the two cannot disagree.

The report folder is written by :func:`slamrel.pipeline.write_report` through
:func:`slamrel.outputs.staged_directory`: built beside the target and swapped in only
when everything is written, so an interrupted run (Ctrl-C) leaves no half-written report.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from slamrel.report.verdict import Verdict

__all__ = [
    "Table",
    "Figure",
    "Section",
    "render_html",
    "verdict_html",
    "figure_png",
    "format_intervals",
]


@dataclass(frozen=True)
class Table:
    """A table: a caption, column names and rows of cells (numbers are formatted)."""

    caption: str
    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]


@dataclass(frozen=True)
class Figure:
    """A PNG image with a caption; ``data``: numbers about what it draws (e.g. its x range),
    written as ``data-*`` attributes of the ``<figure>`` element (keys: lower-case letters,
    digits and ``-``), so that a test or a reader of the page can check them."""

    caption: str
    png: bytes
    data: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Section:
    """A heading with paragraphs, tables and figures."""

    title: str
    paragraphs: Sequence[str] = field(default_factory=tuple)
    tables: Sequence[Table] = field(default_factory=tuple)
    figures: Sequence[Figure] = field(default_factory=tuple)
    #: ``(href, text)`` links shown after the paragraphs (files beside report.html)
    links: Sequence[tuple[str, str]] = field(default_factory=tuple)


def _cell(value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:d}"
    if isinstance(value, float):
        return _number(value)
    return html.escape(str(value))


def _td(value: Any) -> str:
    """A table cell: numbers and names right-aligned (the default), prose (text with a
    space, e.g. a rule) left-aligned."""
    if isinstance(value, str) and " " in value.strip():
        return f'<td class="text">{_cell(value)}</td>'
    return f"<td>{_cell(value)}</td>"


def _number(value: float) -> str:
    """3 significant digits (``0.0565``, ``0.00182``), whole numbers from 1000 on (``2089``)."""
    if not math.isfinite(value):
        return "–" if math.isnan(value) else ("∞" if value > 0 else "−∞")
    if value == 0.0:
        return "0"
    if abs(value) >= 1000.0:
        return f"{value:.0f}"
    return f"{value:.3g}"


def format_intervals(intervals: Sequence[tuple[float, float]], *, unit: str = "s") -> list[str]:
    """Intervals ``(a, b)`` as ``"312.4–318.9 s"``: one decimal, or as many more (up to 3) as
    it takes for distinct intervals to print distinctly (and for ``a < b`` to show).

    The intervals are expected on a readable axis (seconds since the run's start, not Unix
    time: :class:`slamrel.runs.time_base.TimeBase`).
    """
    iv = [(float(a), float(b)) for a, b in intervals]
    for decimals in (1, 2, 3):
        text = [f"{a:.{decimals}f}–{b:.{decimals}f} {unit}" for a, b in iv]
        clash = len(set(text)) < len(set(iv)) or any(
            a < b and f"{a:.{decimals}f}" == f"{b:.{decimals}f}" for a, b in iv
        )
        if not clash:
            break
    return text


def verdict_html(verdict: Verdict) -> str:
    """The verdict block: overall level, evidence, one row per judgement with its rule."""
    rows = "".join(
        f'<tr class="{_css(j.level)}"><td>{html.escape(j.what)}</td>'
        f"<td>{html.escape(j.value)}</td>"
        f'<td><span class="lamp {_css(j.level)}">{j.level}</span></td>'
        f'<td class="rule">{html.escape(j.rule)}</td>'
        "</tr>"
        for j in verdict.lines
    )
    return (
        f'<section id="verdict" class="verdict {verdict.level}"><h2>Verdict: '
        f'<span class="lamp {verdict.level}">{verdict.level}</span></h2>'
        f"<p>The worst of the judgements below. {html.escape(verdict.evidence)}</p>"
        "<table><thead><tr><th>what</th><th>value</th><th>judgement</th><th>rule</th></tr>"
        f"</thead><tbody>{rows}</tbody></table></section>"
    )


def _css(level: str) -> str:
    """A level as one CSS class name (``"not judged"`` → ``not-judged``)."""
    return level.replace(" ", "-")


_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 60rem; margin: 2rem auto; color: #222; }
h1 { font-size: 1.6rem; }
h2 { font-size: 1.25rem; margin-top: 2rem; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 1rem 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.6rem; text-align: right; }
th:first-child, td:first-child, td.text { text-align: left; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.3rem; }
figure { margin: 1rem 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.9rem; color: #555; }
.verdict { border: 2px solid #ccc; padding: 0 1rem; border-radius: 6px; }
.verdict.green { border-color: #1a7f37; } .verdict.amber { border-color: #b7791f; }
.verdict.red { border-color: #b42318; }
.lamp { display: inline-block; padding: 0 0.5rem; border-radius: 4px; color: #fff;
  background: #777; font-weight: 600; white-space: nowrap; }
.lamp.green { background: #1a7f37; } .lamp.amber { background: #b7791f; }
.lamp.red { background: #b42318; } .lamp.info { background: #6b7280; }
.lamp.not-judged { background: #fff; color: #555; border: 1px dashed #888; }
.verdict th, .verdict td { text-align: left; } td.rule { font-size: 0.85rem; color: #555; }
nav ol { columns: 2; }
"""


def render_html(title: str, sections: Sequence[Section], *, verdict: Verdict | None = None) -> str:
    """The whole report as one HTML string (no external resources).

    With a ``verdict`` the page opens with it; a table of contents follows.
    """
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    if verdict is not None:
        out.append(verdict_html(verdict))
    out.append('<nav aria-label="contents"><h2>Contents</h2><ol>')
    out.extend(
        f'<li><a href="#s{k}">{html.escape(sec.title)}</a></li>' for k, sec in enumerate(sections)
    )
    out.append("</ol></nav>")
    for k, sec in enumerate(sections):
        out.append(f'<section id="s{k}"><h2>{html.escape(sec.title)}</h2>')
        out.extend(f"<p>{html.escape(p)}</p>" for p in sec.paragraphs)
        out.extend(
            f'<p><a href="{html.escape(href)}">{html.escape(text)}</a></p>'
            for href, text in sec.links
        )
        for tab in sec.tables:
            out.append(f"<table><caption>{html.escape(tab.caption)}</caption><thead><tr>")
            out.extend(f"<th>{html.escape(str(c))}</th>" for c in tab.columns)
            out.append("</tr></thead><tbody>")
            for row in tab.rows:
                out.append("<tr>" + "".join(_td(v) for v in row) + "</tr>")
            out.append("</tbody></table>")
        for fig in sec.figures:
            data = base64.b64encode(fig.png).decode("ascii")
            out.append(
                f"<figure{_data_attributes(fig.data)}>"
                f'<img alt="{html.escape(fig.caption)}" src="data:image/png;base64,{data}">'
                f"<figcaption>{html.escape(fig.caption)}</figcaption></figure>"
            )
        out.append("</section>")
    out.append("</body></html>")
    return "\n".join(out)


def _data_attributes(data: Mapping[str, float]) -> str:
    """`` data-k="v"`` for each entry (``repr`` of the float: exact, machine-readable)."""
    out = []
    for k, v in data.items():
        if not k or not all(c.islower() or c.isdigit() or c == "-" for c in k):
            raise ValueError(f"figure data key {k!r}: lower-case letters, digits and '-' only")
        out.append(f' data-{k}="{float(v)!r}"')
    return "".join(out)


def figure_png(fig: Any, *, dpi: int = 100) -> bytes:
    """Render a matplotlib figure to PNG bytes and close it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return buf.getvalue()
