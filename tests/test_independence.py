"""Tests and benchmarks are independent: neither imports a module of the other.

What both need lives in the libraries, or is copied on purpose with the reason beside the
copy (the evo run of ``test_evo_parity.py``, the old EKF update of ``bench_ekfslam.py``), so
editing or removing a benchmark never changes what a test checks, and the other way round.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _imported(path: Path) -> set[str]:
    """Top-level names of the modules ``path`` imports."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize(("importer", "other"), [("tests", "benchmarks"), ("benchmarks", "tests")])
def test_no_module_of_the_other_folder_is_imported(importer: str, other: str) -> None:
    theirs = {p.stem for p in (ROOT / other).glob("*.py")} | {other}
    found = {
        f"{p.relative_to(ROOT)} imports {sorted(_imported(p) & theirs)}"
        for p in sorted((ROOT / importer).glob("*.py"))
        if _imported(p) & theirs
    }
    assert not found, found
