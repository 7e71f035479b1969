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
    assert result.translation["abs"].rmse == pytest.approx(oracle, rel=1e-12)  # type: ignore[attr-defined]

    out = tmp_path / "e.json"
    from slamrel.cli import main

    argv = ["evaluate", "data/example/reference.relations", "data/example/estimate.txt"]
    assert main([*argv, "-q", "--json", str(out)]) == 0
    cli = json.loads(out.read_text())
    on_files = namespace["on_files"]
    assert on_files.translation["abs"].rmse == cli["translation"]["abs"]["rmse"]  # type: ignore[attr-defined]
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
    assert ev.translation["sqr"].mean == cli["translation"]["sqr"]["mean"]
    assert ev.rotation["abs"].max == cli["rotation"]["abs"]["max"]
    with pytest.raises(TypeError, match="json"):
        slamrel.evaluate_files(ref, est, json="x.json")


def test_errors_are_one_family() -> None:
    import relation_metric
    import slamrel

    assert slamrel.InputError is relation_metric.InputError
    assert issubclass(slamrel.AssociationError, slamrel.InputError)
    assert issubclass(slamrel.InputError, slamrel.SlamrelError)
    assert issubclass(slamrel.DivergenceError, slamrel.SlamrelError)
    with pytest.raises(slamrel.InputError, match="no-such-file"):
        slamrel.read_trajectory(ROOT / "no-such-file.txt")
