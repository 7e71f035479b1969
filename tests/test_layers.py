"""The import layers docs/design.md promises ("Who may import whom"), read from the source
(every import statement, also those inside functions and under ``TYPE_CHECKING``).

A *layer* is one of the three libraries, or one sub-package or top-level module of
``slamrel`` (``slamrel.formats``, ``slamrel.pipeline``, ...). :data:`ALLOWED` says which
layers of ours each layer may import besides itself; an entry narrower than a layer (a
module, such as ``slamrel.backends.graph``) allows that module only. An import made only for
annotations (under ``if TYPE_CHECKING:``) obeys the same rules: a type a layer needs from
above it moves down (as the run's result types did, into ``slamrel.runs``) or is stated as a
Protocol (``slamrel.backends.pose_only.SimulatedLog``). The same rules, in words, are in
docs/design.md ("Who may import whom").
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
LIBRARIES = ("relation_metric", "recovery", "landmark_graph")
OURS = (*LIBRARIES, "slamrel")

# The package ``slamrel`` itself (its __init__.py: the public API), as an import target.
TOP = "slamrel.__init__"
OUTPUTS, FORMATS, BACKENDS, SIMULATION = (
    "slamrel.outputs",
    "slamrel.formats",
    "slamrel.backends",
    "slamrel.simulation",
)
PLOTS, REVIEW, REPORT, IMPORTERS = (
    "slamrel.plots",
    "slamrel.review",
    "slamrel.report",
    "slamrel.importers",
)
EVALUATION_OPTIONS, EVALUATION = "slamrel.evaluation_options", "slamrel.evaluation"
# the run's result types and its NEES: below the pipeline and the report, which both read them
RUNS = "slamrel.runs"
SCANS, TRAJINFO = "slamrel.scans", "slamrel.trajinfo"
# files scored as evo_ape/evo_rpe score them (`slamrel ape`/`rpe`), on evaluation's readers
EVO = "slamrel.evo_metrics"
PIPELINE, STUDIES, COMMANDS, CLI, MAIN = (
    "slamrel.pipeline",
    "slamrel.studies",
    "slamrel.commands",
    "slamrel.cli",
    "slamrel.__main__",
)

# named choices without numpy (format names, worlds, ...), importable by every slamrel layer
CONSTANTS = "slamrel.constants"

# layer -> what of ours it may import at run time (itself always)
ALLOWED: dict[str, tuple[str, ...]] = {
    "relation_metric": (),
    "recovery": ("relation_metric",),
    "landmark_graph": ("relation_metric",),
    CONSTANTS: (),
    OUTPUTS: ("relation_metric",),
    # the scoring options of a files-level evaluation, without numpy (the parser's defaults)
    EVALUATION_OPTIONS: ("relation_metric",),
    # back-ends and the simulator are maths on records: the libraries only, no file I/O
    BACKENDS: LIBRARIES,
    # the laser simulator returns the laser reader's record (formats.laser.LaserScans)
    SIMULATION: (*LIBRARIES, "slamrel.formats.laser"),
    # scan alignment: maths on the laser records of formats.laser (no file I/O of its own)
    SCANS: (*LIBRARIES, FORMATS),
    # the numbers of `slamrel traj info`: maths on a Trajectory
    TRAJINFO: LIBRARIES,
    # the pose-graph files (g2o, TORO, iSAM) are read into the record graph.PoseGraph
    FORMATS: (*LIBRARIES, OUTPUTS, "slamrel.backends.graph"),
    IMPORTERS: (*LIBRARIES, OUTPUTS, FORMATS, BACKENDS),
    PLOTS: (*LIBRARIES, OUTPUTS, FORMATS),
    REVIEW: (*LIBRARIES, OUTPUTS, FORMATS, SCANS),
    RUNS: LIBRARIES,
    REPORT: (*LIBRARIES, OUTPUTS, FORMATS, PLOTS, RUNS),
    PIPELINE: (*LIBRARIES, OUTPUTS, FORMATS, BACKENDS, SIMULATION, PLOTS, REVIEW, RUNS, REPORT),
    # `slamrel batch` scores each run as `slamrel evaluate` does (studies.batch)
    STUDIES: (
        *LIBRARIES,
        OUTPUTS,
        FORMATS,
        BACKENDS,
        SIMULATION,
        SCANS,  # studies.end_to_end: laser reference relations beside EKF-SLAM
        PLOTS,
        RUNS,
        REPORT,
        PIPELINE,
        EVALUATION_OPTIONS,
        EVALUATION,
    ),
    # what ``slamrel evaluate`` scores, as a library (the command writes the outputs)
    EVALUATION: (*LIBRARIES, FORMATS, EVALUATION_OPTIONS),
    EVO: (*LIBRARIES, FORMATS, EVALUATION_OPTIONS, EVALUATION),
    COMMANDS: (
        *LIBRARIES,
        OUTPUTS,
        FORMATS,
        EVALUATION_OPTIONS,
        EVALUATION,
        BACKENDS,
        SIMULATION,
        IMPORTERS,
        PLOTS,
        REVIEW,
        RUNS,
        REPORT,
        PIPELINE,
        STUDIES,
        SCANS,
        TRAJINFO,
        EVO,
    ),
    CLI: (*LIBRARIES, COMMANDS, TOP),  # TOP: __version__
    MAIN: (CLI,),
    # the public API re-exports from everywhere; its imports are lazy (made on first use)
    TOP: OURS,
}
for _layer in ALLOWED:
    if _layer.startswith("slamrel.") and _layer not in (CONSTANTS, TOP):
        ALLOWED[_layer] = (*ALLOWED[_layer], CONSTANTS)


class Import(NamedTuple):
    line: int
    module: str  # dotted name of the module imported (``from p import m``: ``p.m``)
    type_only: bool  # under ``if TYPE_CHECKING:``
    relative: bool = False


def _is_module(dotted: str) -> bool:
    """Is ``dotted`` a module or package of this repository?"""
    base = ROOT.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """``id`` of every node inside the body of an ``if TYPE_CHECKING:`` block."""
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.attr if isinstance(test, ast.Attribute) else getattr(test, "id", None)
            if name == "TYPE_CHECKING":
                inside.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return inside


def _imports(path: Path) -> list[Import]:
    """Every import statement of ``path``, with the module it brings in."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typed = _type_checking_nodes(tree)
    found = []
    for node in ast.walk(tree):
        only = id(node) in typed
        if isinstance(node, ast.Import):
            found += [Import(node.lineno, a.name, only) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                found.append(Import(node.lineno, node.module or "", only, relative=True))
                continue
            assert node.module is not None
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                found.append(Import(node.lineno, sub if _is_module(sub) else node.module, only))
    return sorted(found)


def _layer(path: Path) -> str:
    """The layer a source file belongs to."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[0] != "slamrel":
        return parts[0]
    return "slamrel." + parts[1]


def _target(module: str) -> str:
    """An imported module as :func:`_is_allowed` compares it (the package slamrel: TOP)."""
    return TOP if module == "slamrel" else module


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _is_allowed(layer: str, imp: Import) -> bool:
    target = _target(imp.module)
    if target.split(".")[0] not in OURS or _within(target, layer):
        return True
    return any(_within(target, a) for a in ALLOWED[layer])


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def test_import_scan_sees_nested_and_type_only_imports(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text(
        "import os\n"
        "from typing import TYPE_CHECKING\n"
        "if 0:\n"
        "    def f():\n"
        "        from slamrel.cli import main\n"
        "if TYPE_CHECKING:\n"
        "    from slamrel.pipeline import RunResult\n"
        "from slamrel import commands, __version__\n"
        "from . import sibling\n"
    )
    assert _imports(src) == [
        Import(1, "os", False),
        Import(2, "typing", False),
        Import(5, "slamrel.cli", False),
        Import(7, "slamrel.pipeline", True),
        Import(8, "slamrel", False),
        Import(8, "slamrel.commands", False),
        Import(9, "", False, relative=True),
    ]
    assert not _is_allowed(SIMULATION, Import(1, "slamrel.backends.pose_only", False))
    assert _is_allowed(FORMATS, Import(1, "slamrel.backends.graph", False))
    assert not _is_allowed(FORMATS, Import(1, "slamrel.backends.least_squares", False))
    assert not _is_allowed(FORMATS, Import(1, "slamrel.backends.ekf_slam", False))
    assert not _is_allowed(REPORT, Import(1, "slamrel.pipeline", False))
    assert not _is_allowed(REPORT, Import(1, "slamrel.pipeline", True))  # no type-only pass
    assert _is_allowed(REPORT, Import(1, "slamrel.runs.result", True))
    assert not _is_allowed(BACKENDS, Import(1, "slamrel.simulation.worlds", True))
    assert not _is_allowed(COMMANDS, Import(1, "slamrel", False))
    assert _is_allowed(CLI, Import(1, "slamrel", False))


def test_every_layer_has_a_rule() -> None:
    """A new sub-package or top-level module of slamrel needs its line in ALLOWED."""
    layers = {_layer(p) for package in OURS for p in _sources(package)}
    assert layers - ALLOWED.keys() == set()
    assert ALLOWED.keys() - layers == set()


def test_the_rules_are_layers() -> None:
    """No layer imports itself through others: the rules order the layers (lazy TOP aside)."""

    def layer_of(entry: str) -> str:
        return max((k for k in ALLOWED if _within(entry, k)), key=len)

    below = {
        layer: {layer_of(a) for a in allowed} - {layer, TOP}
        for layer, allowed in ALLOWED.items()
        if layer != TOP
    }
    done: set[str] = set()
    while len(done) < len(below):
        ready = {k for k, v in below.items() if k not in done and v <= done}
        assert ready, f"import cycle among {sorted(below.keys() - done)}"
        done |= ready


def test_only_the_cli_imports_the_commands_and_nothing_the_cli() -> None:
    may_import = {k for k, v in ALLOWED.items() if any(_within(COMMANDS, a) for a in v)}
    assert may_import - {TOP} == {CLI}
    assert {k for k, v in ALLOWED.items() if CLI in v} - {TOP} == {MAIN}
    assert all(_within(a, "relation_metric") for a in ALLOWED["recovery"])
    assert all(_within(a, "relation_metric") for a in ALLOWED["landmark_graph"])


@pytest.mark.parametrize("package", OURS)
def test_package_imports_only_the_layers_below(package: str) -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{imp.line} ({_layer(path)}) imports "
        + ("relatively (use absolute imports)" if imp.relative else imp.module)
        + (" (type only)" if imp.type_only else "")
        for path in _sources(package)
        for imp in _imports(path)
        if imp.relative or not _is_allowed(_layer(path), imp)
    ]
    assert wrong == []
