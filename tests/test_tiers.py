"""The test tiers of tests/conftest.py, on a small suite of their own: the default tier leaves
the tests marked slow out and says so in one line; ``--full`` runs them; a ``-m`` expression
that names ``slow`` decides alone; a test named by its node id runs whatever its mark."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

SUITE = """
import pytest

def test_quick():
    pass

@pytest.mark.slow
def test_long():
    pass

@pytest.mark.parametrize("n", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_some(n):
    pass
"""


@pytest.fixture
def suite(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")  # the tiers need no plugin
    shutil.copy(Path(__file__).with_name("conftest.py"), pytester.path / "conftest.py")
    pytester.makeini("[pytest]\nmarkers =\n    slow: the full tier\n")
    pytester.makepyfile(test_suite=SUITE)
    return pytester


def _ran(result: pytest.RunResult) -> list[str]:
    return sorted(
        line.split("::", 1)[1].split(" ", 1)[0]
        for line in result.outlines
        if "::" in line and " PASSED" in line
    )


def test_default_tier_leaves_the_slow_tests_out_and_says_how_to_run_them(suite):
    result = suite.runpytest("-v")
    assert _ran(result) == ["test_quick", "test_some[1]"]
    result.assert_outcomes(passed=2, deselected=2)
    line = [x for x in result.outlines if "left to the full tier" in x]
    assert len(line) == 1 and line[0].startswith("2 slow tests") and "--full" in line[0]


def test_full_runs_everything(suite):
    result = suite.runpytest("-v", "--full")
    assert _ran(result) == ["test_long", "test_quick", "test_some[1]", "test_some[2]"]
    assert not [x for x in result.outlines if "left to the full tier" in x]


@pytest.mark.parametrize(
    "args, ran",
    [
        (["-m", "slow"], ["test_long", "test_some[2]"]),
        (["--full", "-m", "slow"], ["test_long", "test_some[2]"]),
        (["-m", "not slow"], ["test_quick", "test_some[1]"]),
        (["-k", "some"], ["test_some[1]"]),
        (["test_suite.py::test_long"], ["test_long"]),
        (["test_suite.py::test_some"], ["test_some[1]", "test_some[2]"]),
    ],
)
def test_a_user_selection_still_works(suite, args, ran):
    assert _ran(suite.runpytest("-v", *args)) == ran
