"""The import layers README.md's Layout section promises, read from the source (every import
statement, also those inside functions and under ``TYPE_CHECKING``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = ("relation_metric", "recovery", "landmark_graph", "slamrel")
# package -> the packages of ours it may import (itself always)
ALLOWED = {
    "relation_metric": set(),
    "recovery": {"relation_metric"},
    "landmark_graph": {"relation_metric"},
    "slamrel": {"relation_metric", "recovery", "landmark_graph"},
}


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, top-level package) of every absolute import in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name.split(".")[0]) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module.split(".")[0]))
    return found


def test_import_scan_sees_nested_imports(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("import os\nif 0:\n    def f():\n        from slamrel.cli import main\n")
    assert _imports(src) == [(1, "os"), (4, "slamrel")]


@pytest.mark.parametrize("package", OURS)
def test_package_imports_only_the_layers_below(package: str) -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{line} imports {top}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, top in _imports(path)
        if top in OURS and top != package and top not in ALLOWED[package]
    ]
    assert wrong == []
