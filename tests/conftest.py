"""Shared fixtures: where the real data lives, and seeded generators."""

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


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator; tests that need several streams derive them from it."""
    return np.random.default_rng(20091122)
