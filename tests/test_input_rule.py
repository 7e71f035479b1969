"""Issue 39: nothing misread — the input rule at the root of every reader.

Each test feeds the CLI an input that used to give a wrong number without a word, or an
internal error, and checks the fix: one clear refusal (exit 3, the file, the line where
there is one, and what was expected) or a warning that says what was skipped.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from slamrel.cli import main


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    for needle in needles:
        assert needle in err, err
    return err


# ---------------------------------------------------------------- 1. TORO ids and values

_EDGE = "1 0 0 1 0 1 1 0 0"  # dx dy dθ and TORO's information entries (the identity)


def _toro(tmp_path: Path, text: str) -> list[str]:
    p = tmp_path / "g.graph"
    p.write_text(text)
    return ["solve", str(p), "-o", str(tmp_path / "out"), "-q"]


def test_toro_fractional_id_is_refused_not_truncated(tmp_path, capsys):
    """``VERTEX2 3.5`` used to become vertex 3 (the edge ``1 3`` then found it): exit 0."""
    argv = _toro(
        tmp_path,
        f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX2 3.5 2 0 0\n"
        f"EDGE2 0 1 {_EDGE}\nEDGE2 1 3 {_EDGE}\n",
    )
    _refused(argv, capsys, "g.graph:3:", "'VERTEX2 id'", "expected an integer id", "3.5")
    assert not (tmp_path / "out").exists()


def test_toro_ids_beyond_2_53_are_exact(tmp_path, capsys):
    """2**60 and 2**60 + 1 are one double: an edge to the missing 2**60 used to land on
    vertex 2**60 + 1 (exit 0). Read exactly, the edge's end is unknown, at its line."""
    big = 2**60
    argv = _toro(
        tmp_path, f"VERTEX2 0 0 0 0\nVERTEX2 {big + 1} 1 0 0\nEDGE2 0 {big} {_EDGE}\n"
    )
    _refused(argv, capsys, "g.graph:3:", f"unknown vertex {big}")
    # the same ids, all present, solve: exact ids are kept, not refused
    argv = _toro(
        tmp_path, f"VERTEX2 0 0 0 0\nVERTEX2 {big + 1} 1 0 0\nEDGE2 0 {big + 1} {_EDGE}\n"
    )
    assert main(argv) == 0
    solved = (tmp_path / "out" / "solved.g2o").read_text().split("\n")
    assert solved[1].split()[:2] == ["VERTEX_SE2", str(big + 1)]  # was written as 2**60


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("VERTEX2 0 0 0 0\nVERTEX2 1e19 1 0 0\n", ("g.graph:2:", "'VERTEX2 id'")),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX 1 2 0 0\nEDGE2 0 1 {_EDGE}\n",
            ("g.graph:3:", "vertex id 1 is defined twice (first on line 2)"),
        ),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1e31 0 0\nEDGE2 0 1 {_EDGE}\n",
            ("g.graph:2:", "pose: position"),
        ),
        (
            "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 -1 0 0\n",
            ("g.graph:3:", "EDGE2 information matrix"),
        ),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1.5 {_EDGE}\n",
            ("g.graph:3:", "'EDGE2 vertex 2'"),
        ),
    ],
)
def test_toro_records_follow_the_g2o_rules(tmp_path, capsys, text, needles):
    """The g2o reader's checks, from the same functions: id range, repeated ids (across
    both spellings, at the second line), coordinates, information matrices, edge ends."""
    _refused(_toro(tmp_path, text), capsys, *needles)
