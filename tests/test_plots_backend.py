"""slamrel.plots.relation_errors.pyplot must not take a backend the user (or Jupyter) chose."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _backend_after(prelude: str) -> str:
    code = (
        prelude
        + "\nfrom slamrel.plots.relation_errors import pyplot\nprint(pyplot().get_backend())"
    )
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    env["PYTHONPATH"] = str(ROOT)
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    return out.stdout.strip().lower()


@pytest.mark.parametrize(
    "prelude,expected",
    [
        ("", "agg"),  # nobody chose: headless Agg, no window from the CLI
        ("import matplotlib; matplotlib.use('svg'); import matplotlib.pyplot", "svg"),
    ],
)
def test_backend_is_left_to_the_user(prelude, expected):
    assert _backend_after(prelude) == expected
