"""Start-up cost: what each entry point imports (a command pays only for what it uses).

Each check runs a fresh interpreter (``sys.modules`` of the test process already holds
everything) and lists the heavy modules it ended up with. The oracle is the rule itself:
the modules named must be absent. The option choices the parsers offer are defined once,
in numpy-free constants modules that their owners import too.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("matplotlib", "scipy.stats", "scipy.optimize", "scipy.spatial", "slamrel.pipeline")


def _imported_after(code: str) -> set[str]:
    """The heavy modules in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    probe = (
        "import sys, json, io, contextlib\n"
        f"{code}\n"
        f"print(json.dumps([m for m in sys.modules if m in {list(HEAVY)!r}]))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_import_relation_metric_is_light() -> None:
    assert _imported_after("import relation_metric") == set()


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["evaluate", "--help"], ["recover", "--help"], ["import", "isam", "--help"]],
)
def test_help_imports_no_heavy_module(argv: list[str]) -> None:
    code = (
        "from slamrel.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    try:\n        main({argv!r})\n    except SystemExit:\n        pass"
    )
    assert _imported_after(code) == set()


@pytest.mark.parametrize("module", ["recovery.ekf", "recovery.recover", "recovery.smoother"])
def test_recovery_modules_import_no_scipy_stats(module: str) -> None:
    """χ²(2) quantiles are analytic (consistency.chi2_quantile), others imported when used."""
    assert _imported_after(f"import {module}") == set()


def test_recover_with_ground_truth_imports_no_scipy_stats(tmp_path: Path) -> None:
    """NIS and NEES bounds (2 and 3 dof) and the NEES band are computed without
    scipy.stats, so a whole ``slamrel recover`` of a bundle with ground truth needs none."""
    from slamrel.cli import main

    sim, slam = tmp_path / "sim", tmp_path / "slam"
    assert main(["simulate", "simple1", "-o", str(sim), "-q"]) == 0
    assert main(["slam", str(sim), "-o", str(slam), "-q"]) == 0
    argv = [
        "recover",
        str(slam),
        "-o",
        str(tmp_path / "t.txt"),
        "--report",
        str(tmp_path / "r.json"),
        "-q",
    ]
    code = f"from slamrel.cli import main\nassert main({argv!r}) == 0"
    assert "scipy.stats" not in _imported_after(code)
    assert "nees" in json.loads((tmp_path / "r.json").read_text())


def test_help_imports_no_numpy() -> None:
    """``slamrel --help`` builds every parser from the numpy-free constants modules: no numpy,
    no scipy, and of the libraries only their package files, the error types and constants."""
    code = (
        "from slamrel.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
        "import json\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('numpy', 'scipy', 'relation_metric', 'recovery', 'landmark_graph'))))"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [sys.executable, "-c", "import sys, io, contextlib\n" + code],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    loaded = set(json.loads(out.stdout.strip().splitlines()[-1]))
    light = {
        "relation_metric",
        "relation_metric.errors",
        "relation_metric.lazy",
        "relation_metric.constants",
        "recovery",
        "recovery.constants",
        "landmark_graph",
        "landmark_graph.constants",
    }
    assert loaded <= light, sorted(loaded - light)


def test_evaluate_imports_no_heavy_module(tmp_path: Path) -> None:
    from slamrel.cli import main

    assert main(["example", "-o", str(tmp_path / "ex"), "-q"]) == 0
    ex = tmp_path / "ex"
    for reference in ("reference.relations", "reference.txt"):
        argv = ["evaluate", str(ex / reference), str(ex / "estimate.txt"), "-q"]
        code = f"from slamrel.cli import main\nassert main({argv!r}) == 0"
        assert _imported_after(code) == set(), reference


def test_ape_and_rpe_import_no_heavy_module(tmp_path: Path) -> None:
    """evo's command lines on TUM files (aligned, scale-corrected, by metres): numpy only."""
    import numpy as np

    t = np.arange(50) * 0.1
    rows = np.column_stack((t, np.cos(t), np.sin(t), 0.1 * t, np.zeros((50, 3)), np.ones(50)))
    ref, est = tmp_path / "r.txt", tmp_path / "e.txt"
    np.savetxt(ref, rows)
    rows[:, 1] += 0.01
    np.savetxt(est, rows)
    for argv in (
        ["ape", "tum", str(ref), str(est), "-as", "--silent"],
        ["rpe", "tum", str(ref), str(est), "-d", "0.2", "-u", "m", "-a", "--silent"],
    ):
        code = f"from slamrel.cli import main\nassert main({argv!r}) == 0"
        assert _imported_after(code) == set(), argv[0]


@pytest.mark.parametrize(
    ("owner", "name", "constants", "as_name"),
    [
        ("relation_metric.metric", "MODES", "relation_metric.constants", None),
        ("relation_metric.relations", "STRATEGIES", "relation_metric.constants", None),
        ("recovery.recover", "METHODS", "recovery.constants", None),
        ("recovery.map_uncertainty", "MAP_MODES", "recovery.constants", None),
        ("recovery.recover", "DEFAULT_ROBUST", "recovery.constants", None),
        ("recovery.ekf", "ROBUST", "recovery.constants", None),
        ("recovery.ekf", "DEFAULT_MAX_OUTLIER_RUN", "recovery.constants", None),
        ("slamrel.formats.trajectories", "TRAJECTORY_FORMATS", "slamrel.constants", None),
        ("slamrel.simulation.worlds", "WORLDS", "slamrel.constants", None),
        ("slamrel.simulation.worlds", "PAPER_WORLDS", "slamrel.constants", None),
        ("slamrel.studies.pose_only", "METHODS", "slamrel.constants", "POSE_ONLY_METHODS"),
    ],
)
def test_option_choices_are_defined_once(
    owner: str, name: str, constants: str, as_name: str | None
) -> None:
    """The owner's constant is the very object of the numpy-free constants module the parsers
    read (a literal copy in the owner would be another object, and could drift)."""
    import importlib

    value = getattr(importlib.import_module(owner), name)
    assert value is getattr(importlib.import_module(constants), as_name or name)


def test_noise_types_are_keyed_by_the_noise_names() -> None:
    from slamrel.constants import NOISE_NAMES
    from slamrel.simulation.worlds import NOISE_TYPES

    assert tuple(NOISE_TYPES) == NOISE_NAMES == ("a", "b", "c")
    assert NOISE_TYPES["b"].sigma_dtheta == 0.2 and NOISE_TYPES["c"].sigma_observation == 0.3


def test_command_table_names_what_each_module_registers() -> None:
    """cli.COMMANDS (read before any command module is imported) is what the modules
    register, and a parser built for one command gives that command the same help."""
    import argparse
    import importlib

    from slamrel import cli

    registered = {}
    for module in cli.COMMAND_MODULES:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(module).register(sub)
        registered.update(dict.fromkeys(sub.choices, module))
    assert registered == cli.COMMANDS
    full = cli.build_parser()
    full_choices = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction))
    assert list(full_choices.choices) == list(cli.COMMANDS)
    for name in cli.COMMANDS:
        one = cli.build_parser(name)
        action = next(a for a in one._actions if isinstance(a, argparse._SubParsersAction))
        assert name in action.choices and len(action.choices) <= 2  # simulate/slam share one
        assert action.choices[name].format_help() == full_choices.choices[name].format_help()


def test_a_named_command_imports_no_other_command_module() -> None:
    probe = (
        "import sys\n"
        "from slamrel.cli import build_parser\n"
        "build_parser('evaluate')\n"
        "print(sorted(m for m in sys.modules if m.startswith('slamrel.commands.')))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    loaded = set(ast.literal_eval(out.stdout.strip()))
    assert "slamrel.commands.evaluate" in loaded
    assert not loaded & {"slamrel.commands.run", "slamrel.commands.study", "slamrel.commands.solve"}


def test_import_commands_have_their_own_module() -> None:
    """``import isam`` / ``import mrclam`` live in commands/importers.py, ``solve`` in graph.py."""
    from slamrel.cli import build_parser

    parser = build_parser()
    owners = {
        tuple(argv): parser.parse_args(argv).func.__module__
        for argv in (["import", "isam", "f", "-o", "g"], ["import", "mrclam", "d", "-o", "b"])
    }
    assert set(owners.values()) == {"slamrel.commands.importers"}
    assert parser.parse_args(["solve", "g", "-o", "d"]).func.__module__ == "slamrel.commands.solve"


ISAM = """ODOMETRY 0 1 1.0 0 0 0.01 0 0 0.01 0 0.0001
LANDMARK 1 2 1.0 1.0 0.04 0 0.04
"""


def test_import_isam_through_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The moved command still reads iSAM text and writes the g2o graph and the log bundle."""
    from slamrel.cli import main

    src = tmp_path / "a.txt"
    src.write_text(ISAM)
    out, log = tmp_path / "a.g2o", tmp_path / "log"
    argv = ["import", "isam", str(src), "-o", str(out), "--bundle", str(log)]
    assert main([*argv, "--noise", "covariance"]) == 0
    printed = capsys.readouterr().out
    assert "2 poses, 1 landmarks, 1 pose-pose and 1 pose-landmark factors" in printed
    lines = out.read_text().splitlines()
    # by hand: two poses (the first at the origin, the second 1 m ahead), landmark 2 at (1, 1)
    assert sum(ln.startswith("VERTEX_SE2") for ln in lines) == 2
    assert sum(ln.startswith("VERTEX_XY 2 ") for ln in lines) == 1
    assert (log / "bundle.json").is_file() and (log / "measurements.csv").is_file()
    assert main(["import", "isam", str(tmp_path / "missing.txt"), "-o", str(out)]) == 3
    assert "slamrel import isam: error:" in capsys.readouterr().err


def test_import_mrclam_through_the_cli_names_the_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from slamrel.cli import main

    (tmp_path / "M").mkdir()
    rc = main(["import", "mrclam", str(tmp_path / "M"), "--robot", "1", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 3 and "slamrel import mrclam: error:" in err and str(tmp_path / "M") in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("ODOMETRY 0 1 1.0 0 0 0.01 0 0 0.01 0 0.0001\n", "LANDMARK observations: none"),
        (ISAM.replace("1.0 1.0 0.04", "0.0 0.0 0.04"), "LANDMARK observations: the median range"),
    ],
)
def test_import_isam_bundle_refused_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, reason: str
) -> None:
    """No landmark seen at a positive range: no log bundle (was a ZeroDivisionError / NaN
    sigma), exit 3 naming the file, and neither output written."""
    from slamrel.cli import main

    src = tmp_path / "a.txt"
    src.write_text(text)
    argv = [
        "import",
        "isam",
        str(src),
        "-o",
        str(tmp_path / "a.g2o"),
        "--bundle",
        str(tmp_path / "b"),
    ]
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert f"slamrel import isam: error: {src}: {reason}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


@pytest.mark.parametrize("preset", [None, "2"])
@pytest.mark.parametrize(
    ("variable", "setter", "default"),
    [
        ("OPENBLAS_NUM_THREADS", "_single_threaded_blas", "1"),
        ("NUMPY_MADVISE_HUGEPAGE", "_no_huge_page_requests", "0"),
    ],
)
def test_process_defaults_unless_the_user_says(preset, variable, setter, default) -> None:
    """A slamrel process runs OpenBLAS on one thread unless OPENBLAS_NUM_THREADS is set, and
    asks numpy for no huge pages unless NUMPY_MADVISE_HUGEPAGE is set; numpy, once imported,
    is left as it is."""
    env = {k: v for k, v in os.environ.items() if k != variable}
    if preset:
        env[variable] = preset
    probe = (
        "import os, sys\n"
        "from slamrel import cli\n"
        f"cli.{setter}()\n"
        f"first = os.environ.get('{variable}')\n"
        f"del os.environ['{variable}']\n"
        "import numpy\n"
        f"cli.{setter}()\n"
        f"print(first, os.environ.get('{variable}'))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True
    )
    assert out.stdout.split() == [preset or default, "None"]


def test_a_command_collects_its_young_objects_less_often(monkeypatch) -> None:
    """A slamrel command runs with Python's youngest-generation threshold raised to
    GC_YOUNG_THRESHOLD (fewer collections while numpy, scipy and its modules load), the
    older generations at the caller's; the caller's thresholds are back afterwards."""
    import gc

    from slamrel import cli

    seen = []
    monkeypatch.setattr(cli, "_main", lambda argv: seen.append(gc.get_threshold()) or 0)
    before = gc.get_threshold()
    try:
        gc.set_threshold(321, 7, 9)
        assert cli.main([]) == 0
        after = gc.get_threshold()
    finally:
        gc.set_threshold(*before)
    assert cli.GC_YOUNG_THRESHOLD == 10_000
    assert seen == [(10_000, 7, 9)]
    assert after == (321, 7, 9)
