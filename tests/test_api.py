"""The Python front door: ``import slamrel`` and the packages' lazy exports.

The README's "Python API" example is executed as written (from the repository root) and two
of its numbers are checked against oracles of their own: the relation errors recomputed with
plain numpy, and ``slamrel evaluate --json`` for the files-level evaluation.
"""

from __future__ import annotations

import ast
import importlib
import json
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("slamrel", "relation_metric", "recovery", "landmark_graph")


def _readme_example() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = re.search(r"^## Python API\n(.*?)(?=^## )", text, re.S | re.M)
    assert section, "README.md has no '## Python API' section"
    block = re.search(r"^```python\n(.*?)^```", section.group(1), re.S | re.M)
    assert block, "the Python API section has no ```python block"
    return block.group(1)


def _relation_rmse(reference: np.ndarray, estimate: np.ndarray) -> float:
    """Translational RMSE of the consecutive relations, written out with numpy (SE(2)).

    ``δ = x_k⁻¹ ∘ x_{k+1}`` for both, ``e = δ*⁻¹ ∘ δ``; ``‖e_xy‖ = ‖t − t*‖`` in SE(2).
    """

    def between(p: np.ndarray) -> np.ndarray:
        d = p[1:, :2] - p[:-1, :2]
        c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
        return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))

    diff = between(estimate) - between(reference)
    return float(np.sqrt(np.mean(np.sum(diff**2, axis=1))))


def test_readme_example_runs_and_its_numbers_hold(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(ROOT)
    namespace: dict[str, object] = {"__name__": "readme_example"}
    exec(compile(_readme_example(), "README.md (Python API)", "exec"), namespace)
    printed = capsys.readouterr().out.split("\n")
    assert all(np.isfinite(float(v)) for line in printed if line for v in line.split())

    ref, est = namespace["reference"], namespace["estimate"]
    result = namespace["result"]
    oracle = _relation_rmse(ref.poses, est.poses)  # type: ignore[attr-defined]
    assert result.translation.abs.rmse == pytest.approx(oracle, rel=1e-12)  # type: ignore[attr-defined]

    out = tmp_path / "e.json"
    from slamrel.cli import main

    argv = ["evaluate", "data/example/reference.relations", "data/example/estimate.txt"]
    assert main([*argv, "-q", "--json", str(out)]) == 0
    cli = json.loads(out.read_text())
    on_files = namespace["on_files"]
    assert on_files.translation.abs.rmse == cli["translation"]["abs"]["rmse"]  # type: ignore[attr-defined]
    assert on_files.epsilon == cli["epsilon"]  # type: ignore[attr-defined]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_resolves_to_its_module(package: str) -> None:
    module = importlib.import_module(package)
    exports: dict[str, str] = module._EXPORTS
    assert set(exports) <= set(module.__all__)
    for name in module.__all__:
        value = getattr(module, name)
        if name in exports:
            assert value is getattr(importlib.import_module(exports[name]), name), name
    assert set(module.__all__) <= set(dir(module))
    with pytest.raises(AttributeError, match="no_such_name"):
        module.no_such_name  # noqa: B018


@pytest.mark.parametrize("package", PACKAGES)
def test_type_checking_block_names_what_all_lists(package: str) -> None:
    """mypy and IDEs see the names of the ``if TYPE_CHECKING:`` imports; they are the lazy ones."""
    module = importlib.import_module(package)
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    seen: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom)
                seen.update({a.asname or a.name: imp.module or "" for a in imp.names})
    assert seen == module._EXPORTS


@pytest.mark.parametrize("package", PACKAGES)
def test_no_public_name_is_hidden_by_a_submodule(package: str) -> None:
    """``import pkg.name`` would replace a lazy ``pkg.name`` by the module (``evaluate``,
    ``recover``: hence not exported by relation_metric and recovery)."""
    module = importlib.import_module(package)
    submodules = {m.name for m in pkgutil.iter_modules(module.__path__)}
    assert not submodules & set(module.__all__)


def test_star_import_gives_every_name() -> None:
    namespace: dict[str, object] = {}
    exec("from slamrel import *", namespace)
    import slamrel

    assert set(slamrel.__all__) <= set(namespace)


@pytest.mark.parametrize("package", PACKAGES)
def test_import_loads_no_numpy(package: str) -> None:
    code = f"import sys, {package}; print([m for m in ('numpy', 'scipy') if m in sys.modules])"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    assert out.stdout.strip() == "[]"


def test_evaluate_files_takes_the_commands_options(tmp_path: Path) -> None:
    import slamrel
    from slamrel.cli import main

    ref, est = ROOT / "data/example/reference.txt", ROOT / "data/example/estimate.txt"
    ev = slamrel.evaluate_files(ref, est, strategy="global", count=50, seed=3)
    out = tmp_path / "e.json"
    argv = ["evaluate", str(ref), str(est), "--strategy", "global", "--count", "50"]
    assert main([*argv, "--seed", "3", "-q", "--json", str(out)]) == 0
    cli = json.loads(out.read_text())
    assert len(ev.relations) == cli["relations"] == 50
    assert ev.translation.sqr.mean == cli["translation"]["sqr"]["mean"]
    assert ev.rotation.abs.max == cli["rotation"]["abs"]["max"]
    with pytest.raises(TypeError, match="json"):
        slamrel.evaluate_files(ref, est, json="x.json")
    options = slamrel.EvaluateOptions(strategy="global", count=50, seed=3)
    again = slamrel.evaluate_files(ref, est, options)
    assert again.translation.sqr.mean == ev.translation.sqr.mean
    moved = slamrel.evaluate_files(ref, est, options, seed=4)  # a keyword overrides options
    assert moved.translation.sqr.mean != ev.translation.sqr.mean


def test_evaluate_parser_defaults_are_the_options_defaults() -> None:
    """The parser of ``slamrel evaluate`` takes every scoring default from EvaluateOptions."""
    import dataclasses

    from slamrel.cli import build_parser
    from slamrel.evaluation_options import SCORING_OPTIONS, EvaluateOptions

    args = build_parser().parse_args(["evaluate", "r", "e"])
    defaults = {f.name: f.default for f in dataclasses.fields(EvaluateOptions)}
    assert tuple(defaults) == SCORING_OPTIONS
    assert {name: getattr(args, name) for name in SCORING_OPTIONS} == defaults


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("max_time_diff", -0.1),
        ("max_time_diff", float("nan")),
        ("max_interpolation_gap", 0.0),
        ("mode", "fast"),
        ("format", "xyz"),
        ("strategy", "nearest"),
        ("step", 0),
        ("step", 1.5),
        ("radius", float("inf")),
        ("min_separation_time", -1.0),
        ("min_distance", -1.0),
        ("count", 0),
        ("count", 10**9),
        ("seed", -1),
        ("weights", "1,1"),
        ("strict", "yes"),
    ],
)
def test_evaluate_options_are_checked_in_library_words(option: str, value: object) -> None:
    """What the command's option types refuse, EvaluateOptions refuses too, naming it."""
    import slamrel

    with pytest.raises(ValueError, match=f"^{option}[: ].*expected"):
        slamrel.EvaluateOptions(**{option: value})  # type: ignore[arg-type]


def test_evaluate_options_normalise_their_values() -> None:
    import slamrel

    options = slamrel.EvaluateOptions(weights="1,1,0,0,0,0", radius=2, times=Path("t.txt"))
    assert options.weights == (1.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    assert options.radius == 2.0 and isinstance(options.radius, float)
    assert options.times == "t.txt"


def test_errors_are_one_family() -> None:
    import relation_metric
    import slamrel

    assert slamrel.InputError is relation_metric.InputError
    assert issubclass(slamrel.AssociationError, slamrel.InputError)
    assert issubclass(slamrel.InputError, slamrel.SlamrelError)
    assert issubclass(slamrel.DivergenceError, slamrel.SlamrelError)
    with pytest.raises(slamrel.InputError, match="no-such-file"):
        slamrel.read_trajectory(ROOT / "no-such-file.txt")


# --- library messages in library words; the CLI adds its option words ------------------------

LIBRARIES = ("relation_metric", "recovery", "landmark_graph")
LIBRARY_DIRS = [ROOT / p for p in LIBRARIES] + [
    ROOT / "slamrel" / p for p in ("formats", "backends", "simulation")
]


def test_library_messages_name_no_command_line_option() -> None:
    """Every string of the library code that is not a docstring (messages, warnings) is free
    of ``--option`` words: a Python caller has parameters, the CLI says its own options."""
    option = re.compile(r"(?<![\w-])--[a-z]")
    found = []
    for directory in LIBRARY_DIRS:
        for path in sorted(directory.glob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            docstrings = {
                id(node.body[0].value)
                for node in ast.walk(tree)
                if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef)
                and node.body
                and isinstance(node.body[0], ast.Expr)
                and isinstance(node.body[0].value, ast.Constant)
            }
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Constant)
                    and isinstance(node.value, str)
                    and id(node) not in docstrings
                    and option.search(node.value)
                ):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert not found, "\n".join(found)


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    from slamrel.cli import main

    capsys.readouterr()
    code = main(argv)
    return code, capsys.readouterr().err


RELATIONS = "0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0\n"
PLAIN = "0 0 0 0\n1 1 0 0\n2 2 0 0\n"


def test_map_compare_without_common_ids(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import slamrel

    est, ref = tmp_path / "e.csv", tmp_path / "r.csv"
    est.write_text("landmark,x,y\n1,0,0\n2,1,0\n3,0,1\n")
    ref.write_text("landmark,x,y\n11,0,0\n12,1,0\n13,0,1\n")
    with pytest.raises(slamrel.InputError) as exc:
        slamrel.compare_maps(slamrel.read_map(est), slamrel.read_map(ref), associate="id")
    assert exc.value.message == (
        "no landmark of the estimate matches the reference by id; "
        'associate="auto" matches them by position, an association of your own by hand'
    )
    # the default (id-or-auto) falls back to the automatic association and says so
    res = slamrel.compare_maps(slamrel.read_map(est), slamrel.read_map(ref))
    assert res.association_source == "auto" and res.association.estimate_rows.size == 3
    assert res.notes == ("the maps share 0 landmark id(s): associated automatically by position",)
    code, err = _cli(["map-compare", str(est), str(ref), "--associate", "id"], capsys)
    assert code == 3
    assert err == (
        f"slamrel map-compare: error: {est}: no landmark of the estimate matches the "
        "reference by id; --associate auto matches them by position, an association file by "
        "hand\n"
    )


def test_relations_file_given_as_a_trajectory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import slamrel

    (tmp_path / "r.relations").write_text(RELATIONS)
    (tmp_path / "e.rel").write_text(RELATIONS)
    with pytest.raises(slamrel.InputError, match=r"; pass format=\.\.\. to read it as a"):
        slamrel.read_trajectory(tmp_path / "e.rel")
    code, err = _cli(["evaluate", str(tmp_path / "r.relations"), str(tmp_path / "e.rel")], capsys)
    assert code == 3
    assert "not a trajectory; pass --format to read it as a trajectory anyway" in err


def test_unrecognised_reference_trajectory_names_its_own_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--format`` is the estimate's: a reference is given its format with --reference-format."""
    (tmp_path / "r.txt").write_text("0 1 2\n1 2 3\n")
    (tmp_path / "e.txt").write_text(PLAIN)
    argv = ["evaluate", str(tmp_path / "r.txt"), str(tmp_path / "e.txt"), "--strategy", "random"]
    code, err = _cli(argv, capsys)
    assert code == 3 and "cannot recognise the trajectory format" in err
    assert err.rstrip().endswith("; pass --reference-format")


def test_non_finite_carmen_pose(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import slamrel

    log = tmp_path / "e.log"
    log.write_text("".join(f"ODOM {x} 0 0 0 0 0 {t} h 0\n" for t, x in enumerate((0, "nan", 2))))
    (tmp_path / "r.relations").write_text(RELATIONS)
    with pytest.raises(slamrel.InputError, match=r"\(skip_invalid=True skips such records and "):
        slamrel.read_trajectory(log)
    code, err = _cli(["evaluate", str(tmp_path / "r.relations"), str(log)], capsys)
    assert code == 3 and f"{log}:2: ODOM record with a non-finite pose" in err
    assert "(the metricevaluator mode, or --skip-invalid-poses, skips such records and" in err


def test_planar_projection_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import slamrel

    tum = tmp_path / "t.tum"
    rows = [f"{k} {0.5 * k} 0 {0.3 * k} 0 0 0 1" for k in range(5)]
    tum.write_text("\n".join(rows) + "\n")
    with pytest.warns(UserWarning, match=r'scored in 2-D \(dimension="2d"\): discarding'):
        slamrel.read_trajectory(tum, dimension="2d")
    argv = ["evaluate", str(tum), str(tum), "--planar", "-q"]
    code, err = _cli(argv, capsys)
    assert code == 0
    assert f"warning: {tum}: 3-D trajectory scored in 2-D (--planar): discarding its" in err


def test_strict_evaluation(capsys: pytest.CaptureFixture[str]) -> None:
    import slamrel

    est = slamrel.Trajectory(np.array([0.0, 1.0]), np.zeros((2, 3)))
    rel = slamrel.RelationSet(np.array([0.0, 0.0]), np.array([1.0, 5.0]), np.zeros((2, 3)))
    with pytest.raises(slamrel.AssociationError) as exc:
        slamrel.evaluate(rel, est, strict=True)
    assert exc.value.message.endswith("(strict=True)") and "--" not in exc.value.message
