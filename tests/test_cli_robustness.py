"""No traceback from any command: option mistakes exit 2, bad input exits 3, both in one line.

The oracle is the exit-code contract of ``slamrel.cli`` (0 ok, 1 a bug, 2 usage, 3 bad input,
130 interrupted) and the message rules: the file is named, no numpy repr (``np.float64(…)``),
no Python traceback.
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from slamrel import cli
from slamrel.cli import main

NUMPY_REPR = re.compile(r"\bnp\.\w+\(")


def _clean_message(err: str) -> None:
    assert "Traceback" not in err, err
    assert not NUMPY_REPR.search(err), err
    assert "\\ufeff" not in err and "allow_pickle" not in err, err


# ------------------------------------------------------------------------------ option values

BAD_OPTIONS = [
    (["evaluate", "r", "e"], "--max-time-diff", "nan"),
    (["evaluate", "r", "e"], "--max-time-diff", "-0.1"),
    (["evaluate", "r", "e"], "--max-interpolation-gap", "0"),
    (["evaluate", "r", "e"], "--weights", "1,2"),
    (["evaluate", "r", "e"], "--step", "0"),
    (["evaluate", "r", "e"], "--count", "0"),
    (["evaluate", "r", "e"], "--count", "100000000"),
    (["evaluate", "r", "e"], "--seed", "-1"),
    (["evaluate", "r", "e"], "--radius", "inf"),
    (["evaluate", "r", "e"], "--distance", "-2"),
    (["relations", "generate", "r", "-o", "o"], "--count", "200000000"),
    (["relations", "generate", "r", "-o", "o"], "--min-separation-time", "-1"),
    (["recover", "b", "-o", "o"], "--gate", "2"),
    (["recover", "b", "-o", "o"], "--gate", "0"),
    (["recover", "b", "-o", "o"], "--max-outlier-run", "-3"),
    (["run"], "--noise-scale", "-1"),
    (["run"], "--corrupt", "1.5"),
    (["run"], "--seed", "-1"),
    (["run"], "--rate", "-1"),
    (["simulate", "simple1", "-o", "o"], "--seed", "x"),
    (["slam", "b", "-o", "o"], "--outlier-gate", "1"),
    (["slam", "b", "-o", "o"], "--noise-scale", "0"),
    (["slam", "b", "-o", "o"], "--corrupt", "-0.1"),
    (["map-compare", "a", "b"], "--thin-angle", "200"),
    (["map-compare", "a", "b"], "--cutoff", "0"),
    (["map-compare", "a", "b"], "--order", "0.5"),
    (["compare", "d:a=x.csv", "-o", "o"], "--alpha", "2"),
    (["solve", "g", "-o", "o"], "--batch", "-1"),
    (["solve", "g", "-o", "o"], "--max-iterations", "0"),
    (["import", "mrclam", "d", "-o", "o"], "--robot", "6"),
    (["example", "-o", "o"], "--seed", "1.5"),
    (["evaluate", "r", "e"], "--plot", "x.xyz"),
    (["map-compare", "a", "b"], "--plot", "figure"),
    (["review", "a", "b", "-o", "r.html"], "--cutoff", "-1"),
    (["review", "a", "b", "-o", "r.html"], "--seed", "-5"),
]


@pytest.mark.parametrize(("command", "option", "value"), BAD_OPTIONS)
def test_option_mistakes_exit_2_naming_the_option(command, option, value, capsys):
    with pytest.raises(SystemExit) as e:
        main([*command, option, value])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and repr(value) in err, err
    _clean_message(err)


# ------------------------------------------------------------------------------ hostile inputs


def _hostile_files(tmp_path):
    """Each kind of unusable input file: (label, path)."""
    d = tmp_path / "in"
    d.mkdir()
    (d / "empty.txt").write_bytes(b"")
    (d / "binary.txt").write_bytes(bytes(range(256)))
    (d / "nul.txt").write_bytes(b"0 0 0 0\n\x00\n")
    (d / "latin1.txt").write_bytes("t x y theta\n0 0 0 \xb0\n".encode("latin-1"))
    (d / "words.txt").write_text("hello world\nthis is not data\n")
    (d / "nan.txt").write_text("0 0 0 0\n1 nan 0 0\n")
    (d / "folder").mkdir()
    return {
        "missing": d / "missing.txt",
        "folder": d / "folder",
        "empty": d / "empty.txt",
        "binary": d / "binary.txt",
        "nul": d / "nul.txt",
        "latin1": d / "latin1.txt",
        "words": d / "words.txt",
        "nan": d / "nan.txt",
    }


def _commands(f, out):
    """Every command with ``f`` as its (first) input and ``out`` as its output."""
    good = str(f)
    return {
        "evaluate-ref": ["evaluate", good, good],
        "evaluate-est": ["evaluate", good, good, "--strategy", "consecutive"],
        "relations": ["relations", "generate", good, "--strategy", "consecutive", "-o", out],
        "recover": ["recover", good, "-o", out],
        "map-compare": ["map-compare", good, good],
        "review": ["review", good, good, "-o", out + ".html"],
        "slam": ["slam", good, "-o", out],
        "run": ["run", good, "-o", out],
        "compare": ["compare", f"d:a={good}", "-o", out],
        "import-isam": ["import", "isam", good, "-o", out],
        "import-mrclam": ["import", "mrclam", good, "--robot", "1", "-o", out],
        "solve": ["solve", good, "-o", out],
    }


@pytest.mark.parametrize(
    "kind", ["missing", "folder", "empty", "binary", "nul", "latin1", "words", "nan"]
)
def test_hostile_inputs_give_one_clean_error_in_every_command(tmp_path, capsys, kind):
    path = _hostile_files(tmp_path)[kind]
    out = str(tmp_path / "out" / "result")
    for name, argv in _commands(path, out).items():
        try:
            code = main([*argv, "-q"])
        except SystemExit as e:  # argparse
            code = e.code
        err = capsys.readouterr().err
        assert code in (2, 3), (name, kind, code, err)
        assert "error:" in err, (name, kind, err)
        _clean_message(err)
        assert len(err.strip().splitlines()) <= 3, (name, kind, err)  # one message (+ usage)


# ------------------------------------------------------------------------------ the last line


def test_interrupt_during_start_up_exits_130(monkeypatch, capsys):
    def interrupted(command=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert main(["evaluate", "a", "b"]) == 130
    assert "interrupted" in capsys.readouterr().err


def test_operating_system_errors_exit_3_naming_the_file(monkeypatch, tmp_path, capsys):
    def denied(args):
        raise PermissionError(13, "Permission denied", str(tmp_path / "x.json"))

    from slamrel.commands import example

    monkeypatch.setattr(example, "run", denied)
    assert main(["example", "-o", str(tmp_path / "ex")]) == 3
    err = capsys.readouterr().err
    assert "x.json: permission denied" in err
    _clean_message(err)


def test_a_bug_is_one_line_and_debug_shows_it(monkeypatch, tmp_path, capsys):
    def bug(args):
        raise RuntimeError("boom")

    from slamrel.commands import example

    monkeypatch.setattr(example, "run", bug)
    monkeypatch.delenv("SLAMREL_DEBUG", raising=False)
    assert main(["example", "-o", str(tmp_path / "ex")]) == 1
    err = capsys.readouterr().err
    assert "internal error (RuntimeError: boom)" in err and "SLAMREL_DEBUG" in err
    _clean_message(err)
    monkeypatch.setenv("SLAMREL_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(["example", "-o", str(tmp_path / "ex")])


def test_the_console_script_prints_no_traceback(tmp_path):
    """The same contract as a whole process (what a user's shell sees)."""
    proc = subprocess.run(
        [sys.executable, "-m", "slamrel", "evaluate", str(tmp_path / "nope.relations"), "x"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 3, proc.stderr
    assert "nope.relations" in proc.stderr
    _clean_message(proc.stderr)


# ------------------------------------------------------------------------------ huge values


@pytest.mark.parametrize("value", ["1e300", "1e308", "-1e31"])
def test_coordinates_beyond_float64_statistics_are_input_errors(tmp_path, capsys, value):
    """1e300 m squared is inf: refused with file and line instead of inf/nan statistics."""
    good = tmp_path / "good.csv"
    good.write_text("landmark,x,y\n1,0,0\n2,1,1\n3,1,0\n4,2,2\n")
    huge = tmp_path / "huge.csv"
    huge.write_text(f"landmark,x,y\n1,0,0\n2,{value},1\n3,1,0\n4,2,2\n")
    for argv in (["map-compare", str(huge), str(good)], ["map-compare", str(good), str(huge)]):
        for assoc in ("id", "auto"):
            assert main([*argv, "--associate", assoc, "-q"]) == 3
            err = capsys.readouterr().err
            assert f"{huge}:3: " in err and "beyond 1e+30 m" in err, err
            assert "warning" not in err
            _clean_message(err)


def test_trajectory_coordinates_beyond_float64_statistics_are_input_errors(tmp_path, capsys):
    ref = tmp_path / "ref.txt"
    ref.write_text("".join(f"{k} {k} 0 0\n" for k in range(10)))
    est = tmp_path / "est.txt"
    est.write_text("".join(f"{k} {1e300 if k == 4 else k} 0 0\n" for k in range(10)))
    for argv in (["evaluate", str(ref), str(est)], ["evaluate", str(est), str(ref)]):
        assert main([*argv, "--strategy", "global", "--count", "20", "-q"]) == 3
        err = capsys.readouterr().err
        assert f"{est}:5: " in err and "beyond 1e+30 m" in err, err
        _clean_message(err)


@pytest.mark.filterwarnings("default::RuntimeWarning")  # as a user's interpreter shows them
def test_a_numpy_floating_point_warning_is_said_as_slamrels_bug(
    monkeypatch: pytest.MonkeyPatch, tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A numpy RuntimeWarning reaching the command line (none is known: the suite turns
    every one into an error) is not shown as numpy's bare phrase but as a bug, with where."""
    import numpy as np

    from slamrel.commands import simulate

    def divide(args):  # type: ignore[no-untyped-def]
        np.array([0.0]) / np.array([0.0])
        return 0

    monkeypatch.setattr(simulate, "run_simulate", divide)
    assert main(["simulate", "simple1", "-o", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    said = "warning: floating-point problem inside slamrel: invalid value encountered in divide"
    assert said in err
    assert "test_cli_robustness.py:" in err and "bug in slamrel" in err
    _clean_message(err)
