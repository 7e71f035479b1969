"""The test tiers, where the real data lives, seeded generators, and the runs many tests share.

Tiers: ``python -m pytest -q`` runs the default tier, every module with its oracles; tests
marked ``slow`` (Monte Carlo acceptance, Dask, kill-and-resume, the notebooks, the browser)
belong to the full tier, which ``--full`` adds. A ``-m`` expression that names ``slow``
decides on its own (``-m slow`` runs only the full tier's share), and so does a test named
by its node id.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parent.parent

# Property tests explore new random examples on every local run (that is how they find edge
# cases); under CI=true they run a fixed, derandomised set, so that a submission's CI cannot
# fail on an example no earlier run drew (a subnormal variance did, 2026-12-06).
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI", "").lower() == "true":
    settings.load_profile("ci")
DATA_HELP = (
    "real data not found at {path}: set SLAMREL_DATA to the folder that holds freiburg/, "
    "mrclam/ and victoria_park/ (see ../shared/data/README.md for where each comes from)"
)


def data_root() -> Path:
    """``$SLAMREL_DATA``, or ``../shared/data`` beside the project root."""
    return Path(os.environ.get("SLAMREL_DATA", ROOT.parent / "shared" / "data"))


def require_data(*parts: str) -> Path:
    """Path to a real-data file or folder; skip when absent — fail under ``CI=true``."""
    path = data_root().joinpath(*parts)
    if not path.exists():
        message = DATA_HELP.format(path=path)
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    return path


FULL_HELP = (
    "also run the tests marked slow (the full tier: Monte Carlo acceptance, Dask, "
    "kill-and-resume, notebooks, browser); by default they are deselected"
)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--full", action="store_true", help=FULL_HELP)


#: How many slow tests the default tier left out (for the summary line).
_LEFT = pytest.StashKey[int]()


def _named_ids(config: pytest.Config) -> list[str]:
    """Node ids given on the command line (``tests/test_x.py::test_y``), relative to the
    rootdir as pytest writes them."""
    ids = []
    for arg in map(str, config.args):
        path, sep, rest = arg.partition("::")
        if sep:
            full = (config.invocation_params.dir / path).resolve()
            if full.is_relative_to(config.rootpath):
                ids.append(f"{full.relative_to(config.rootpath).as_posix()}::{rest}")
    return ids


def _is_named(nodeid: str, named: list[str]) -> bool:
    return any(nodeid == n or nodeid.startswith((n + "[", n + "::")) for n in named)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The default tier: leave out the tests marked ``slow``, unless ``--full`` is given, the
    ``-m`` expression names ``slow`` (then it decides), or the test was named by node id."""
    if config.getoption("--full") or "slow" in (config.getoption("-m") or ""):
        return
    named = _named_ids(config)
    left = [i for i in items if i.get_closest_marker("slow") and not _is_named(i.nodeid, named)]
    if left:
        out = set(map(id, left))
        items[:] = [i for i in items if id(i) not in out]
        config.hook.pytest_deselected(items=left)
    config.stash[_LEFT] = len(left)


def pytest_terminal_summary(
    terminalreporter: pytest.TerminalReporter, config: pytest.Config
) -> None:
    """One line: how many slow tests the default tier left out, and how to run them."""
    left = config.stash.get(_LEFT, 0)
    if left:
        terminalreporter.write_line(
            f"{left} slow tests left to the full tier: python -m pytest --full runs everything, "
            "python -m pytest --full -m slow only those"
        )


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator; tests that need several streams derive them from it."""
    return np.random.default_rng(20091122)


# ------------------------------------------------------------------ runs many tests read
#
# A pipeline run with its report takes seconds (the figures are half of it); these are the
# runs several test modules read without changing them, each computed once per session.
# Tests that change what they read (write into the folder, monkeypatch the pipeline) make
# their own.


class SharedRun(NamedTuple):
    """One ``slamrel run``: its report folder, what it printed, and the ``RunResult``."""

    folder: Path
    printed: str
    result: Any  # slamrel.pipeline.RunResult (imported when the fixture runs)

    @property
    def html(self) -> Path:
        return self.folder / "report.html"


def _cli_run(folder: Path, argv: list[str]) -> SharedRun:
    """``slamrel run ARGV -o FOLDER`` through the CLI, keeping the ``RunResult`` the report
    was written from (a spy on :func:`slamrel.pipeline.run_pipeline`, which the command
    calls once)."""
    import contextlib
    import io

    import slamrel.pipeline as pipeline
    from slamrel.cli import main

    real = pipeline.run_pipeline
    results = []

    def spy(*args: Any, **kwargs: Any) -> Any:
        results.append(real(*args, **kwargs))
        return results[-1]

    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        mp.setattr(pipeline, "run_pipeline", spy)
        code = main(["run", *argv, "-o", str(folder)])
    assert code == 0, printed.getvalue()
    assert len(results) == 1, f"slamrel run called run_pipeline {len(results)} times, not once"
    return SharedRun(folder, printed.getvalue(), results[0])


@pytest.fixture(scope="session")
def quickstart_run(tmp_path_factory: pytest.TempPathFactory) -> SharedRun:
    """``slamrel run`` as the quick start runs it: simple1, noise a, seed 0."""
    return _cli_run(tmp_path_factory.mktemp("quickstart") / "report", ["simple1"])


@pytest.fixture(scope="session")
def broken_run(tmp_path_factory: pytest.TempPathFactory) -> SharedRun:
    """``slamrel run simple1 --corrupt 0.1``: 10 % wrong associations in the reference
    EKF-SLAM, a broken map with stretches where it and the log disagree."""
    return _cli_run(tmp_path_factory.mktemp("broken") / "report", ["simple1", "--corrupt", "0.1"])
