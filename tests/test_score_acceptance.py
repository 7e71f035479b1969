"""Issue 37's scoring acceptance, run through ``benchmarks/score_acceptance.py`` (as a
script: tests import nothing from ``benchmarks/``).

Oracle: the true relations of the simulated log (``between(truth[i], truth[j])`` at the
pairs the same proposal rules pick from the true poses). Scoring three estimates against
relations made by ``align_scans`` and reviewed by script (accept unflagged) must give their
ranking and each mean translational error within 10 % of scoring against the truth.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(tmp_path: Path, *args: str) -> list[dict]:
    out = tmp_path / "acceptance.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, str(ROOT / "benchmarks" / "score_acceptance.py"), *args]
    subprocess.run([*cmd, "--json", str(out)], check=True, env=env, cwd=ROOT, timeout=900)
    return json.loads(out.read_text())


@pytest.mark.slow
def test_harness_passes_when_every_pair_is_aligned(tmp_path):
    """With the true poses as guesses (every pair proposed and aligned right) the harness
    accepts: it can pass, and the estimates' means are what the truth gives."""
    (r,) = _run(tmp_path, "--seeds", "1", "--guesses", "truth")
    assert r["pairs"] == r["true_pairs"] and r["loop_pairs"] > 50
    assert r["same_ranking"] and r["within_10_percent"], r["ratio"]
    assert r["ranking_true"] == ["jitter", "odometry", "drift"]


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="issue 37 open: the global aligner keeps the loop pairs it is given (14-16 of "
    "247-280 flagged, none grossly wrong accepted), but pairs proposed from the odometry "
    "are not the truth's (seed 2: no loop pair), so the means differ by 11-99 %",
)
def test_scoring_against_reviewed_relations_matches_the_truth(tmp_path):
    for r in _run(tmp_path, "--seeds", "0", "1", "--cycle-check"):
        assert r["same_ranking"] and r["within_10_percent"], (r["seed"], r["ratio"])
