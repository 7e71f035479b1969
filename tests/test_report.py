"""HTML report rendering and atomic report directories."""

from __future__ import annotations

import html.parser

import pytest

from slamrel.outputs import MANIFEST, staged_directory
from slamrel.report.html import Figure, Section, Table, render_html

PNG = b"\x89PNG\r\n\x1a\n" + b"\x00" * 16


class _Collect(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.cells, self.tags = [], []
        self._in_td = False

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self._in_td = tag == "td"

    def handle_endtag(self, tag):
        self._in_td = False

    def handle_data(self, data):
        if self._in_td:
            self.cells.append(data)


def test_render_html_tables_and_figures_are_embedded():
    sec = Section(
        "Trajectory <recovered>",
        paragraphs=["a & b"],
        tables=[
            Table(
                "stats",
                ["part", "mean", "count"],
                [["translation", 0.0123456789, 5], ["rot", None, 0]],
            )
        ],
        figures=[Figure("where", PNG)],
    )
    text = render_html("report", [sec])
    parser = _Collect()
    parser.feed(text)
    assert parser.cells == ["translation", "0.0123", "5", "rot", "–", "0"]  # 3 significant digits
    assert "&lt;recovered&gt;" in text and "a &amp; b" in text
    assert "data:image/png;base64," in text and "http" not in text  # self-contained


def test_report_folder_replaces_only_when_complete(tmp_path):
    target = tmp_path / "rep"
    with staged_directory(target, kind="report") as d:
        (d / "a.txt").write_text("1")
    assert (target / "a.txt").read_text() == "1"
    with pytest.raises(KeyboardInterrupt):
        with staged_directory(target, kind="report") as d:
            (d / "a.txt").write_text("half")
            raise KeyboardInterrupt
    assert (target / "a.txt").read_text() == "1"  # the old report survives
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]  # nothing half-written left
    with staged_directory(target, kind="report") as d:
        (d / "b.txt").write_text("2")
    assert sorted(p.name for p in target.iterdir()) == ["b.txt", MANIFEST]  # a.txt is gone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]
