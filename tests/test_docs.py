"""The front page and the reference pages: README.md stays a page a newcomer reads to the end,
links every page of docs/, and every link of README.md and docs/ leads somewhere; docs/
commands.md names every sub-command and every option the parser has (the parser is the
oracle: a new option without its line in the reference fails here).

The README's examples are run by tests/test_api.py (the Python API) and tests/test_data.py
(the commands on data/); its two setup commands are CI's (tests/test_cli_evaluate.py).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from slamrel.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
MAX_README_LINES = 250
MAX_FIGURE_BYTES = 150_000

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^\s*```")


def _prose(path: Path) -> list[str]:
    """The lines of a Markdown file outside fenced code blocks."""
    lines, inside = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            inside = not inside
            continue
        if not inside:
            lines.append(line)
    return lines


def _headings(path: Path) -> list[tuple[int, str]]:
    """``(level, text)`` of every ATX heading outside code blocks."""
    out = []
    for line in _prose(path):
        m = re.match(r"^(#{1,6})\s+(.*?)\s*#*\s*$", line)
        if m:
            out.append((len(m.group(1)), m.group(2)))
    return out


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _links(path: Path) -> list[str]:
    return [m.group(1) for line in _prose(path) for m in LINK.finditer(line)]


def _local_target(source: Path, link: str) -> tuple[Path, str] | None:
    """The file and anchor a relative link names (None for a web address)."""
    if re.match(r"^[a-z][a-z0-9+.-]*:", link):
        return None
    target, _, anchor = link.partition("#")
    return ((source.parent / target).resolve() if target else source), anchor


def test_readme_is_short() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, (
        f"README.md has {len(lines)} lines; at most {MAX_README_LINES}: move the manual into "
        "docs/ and link it"
    )


@pytest.mark.parametrize("index", [README, DOCS / "README.md"], ids=["README", "docs-index"])
def test_every_docs_page_is_linked(index: Path) -> None:
    linked = {t[0] for link in _links(index) if (t := _local_target(index, link))}
    missing = [p.name for p in PAGES if p.resolve() not in linked and p != index]
    assert not missing, f"{index.relative_to(ROOT)} links no {missing}"


@pytest.mark.parametrize("page", [README, *PAGES], ids=lambda p: p.name)
def test_links_lead_somewhere(page: Path) -> None:
    broken = []
    for link in _links(page):
        target = _local_target(page, link)
        if target is None:
            continue
        path, anchor = target
        if not path.exists():
            broken.append(f"{link}: no such file")
        elif anchor and path.suffix == ".md":
            if anchor not in {_slug(text) for _, text in _headings(path)}:
                broken.append(f"{link}: no heading with that anchor")
    assert not broken, f"{page.relative_to(ROOT)}:\n" + "\n".join(broken)


def test_readme_has_one_small_figure_from_docs_img() -> None:
    images = [
        m.group(1) for line in _prose(README) for m in re.finditer(r"!\[[^\]]*\]\(([^)]+)\)", line)
    ]
    assert len(images) == 1, images
    figure = ROOT / images[0]
    assert figure.parent == DOCS / "img" and figure.suffix == ".png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert figure.stat().st_size < MAX_FIGURE_BYTES


def _leaf_parsers(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> list[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every (sub-)command's parser with its words (``("traj", "info")``), leaves only; an
    alias (``ape mcap`` of ``ape bag2``, evo's) is its command's parser, described there."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [(words, parser)]
    firsts = [
        (name, child)
        for action in subs
        for name, child in {id(c): (n, c) for n, c in reversed(action.choices.items())}.values()
    ]
    return [leaf for name, child in firsts for leaf in _leaf_parsers(child, (*words, name))]


def _section(page: Path, heading: str) -> str:
    """The prose under ``heading`` up to the next heading of the same or a higher level."""
    lines = _prose(page)
    levels = [
        (len(m.group(1)), m.group(2)) if (m := re.match(r"^(#{1,6})\s+(.*?)\s*$", line)) else None
        for line in lines
    ]
    starts = [i for i, h in enumerate(levels) if h and h[1] == heading]
    assert starts, f"{page.name} has no heading {heading!r}"
    first, level = starts[0], levels[starts[0]][0]  # type: ignore[index]
    end = next(
        (i for i in range(first + 1, len(lines)) if (h := levels[i]) and h[0] <= level),
        len(lines),
    )
    return "\n".join(lines[first:end])


COMMANDS = _leaf_parsers(build_parser())


@pytest.mark.parametrize("words,parser", COMMANDS, ids=[" ".join(w) for w, _ in COMMANDS])
def test_commands_page_names_every_option(
    words: tuple[str, ...], parser: argparse.ArgumentParser
) -> None:
    section = _section(DOCS / "commands.md", f"`slamrel {' '.join(words)}`")
    missing = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        if action.option_strings:
            name = max(action.option_strings, key=len)
            if not re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", section):
                missing.append(name)
        else:
            name = action.metavar if isinstance(action.metavar, str) else action.dest.upper()
            if not re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", section):
                missing.append(name)
    assert not missing, f"docs/commands.md, `slamrel {' '.join(words)}`: {missing} not described"


def test_commands_page_lists_every_command() -> None:
    """The table at the top links each command's section (a nested one: its own or its
    command's)."""
    table = _section(DOCS / "commands.md", "Commands")
    for words, _ in COMMANDS:
        names = [" ".join(words[:k]) for k in range(1, len(words) + 1)]
        anchors = {"(#" + _slug(f"`slamrel {name}`") + ")" for name in names}
        assert any(a in table for a in anchors), f"the table links no section of {words}"
