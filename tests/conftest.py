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

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
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
