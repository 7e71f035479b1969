"""Monte Carlo consistency of the recovery (50 seeded runs each, Bar-Shalom et al. NEES).

* Perfect map (landmarks at ground truth, 1e-12 m² covariance), known noise: the filter's
  run-averaged NEES lies in the 95% χ² band; smoother and batch have lower RMSE than the
  filter.
* Perturbed map (errors drawn from the stated joint covariance, with a common offset): the
  Schmidt recovery that uses the joint covariance is consistent; ignoring the map's
  uncertainty is overconfident (NEES far above the band), and so is using only its marginals.
"""

from __future__ import annotations

import numpy as np
import pytest

from recovery.anchoring import NeesFrame
from recovery.recover import recover
from relation_metric.consistency import summarize_nees
from slamrel.runs.nees import recovery_nees
from slamrel.simulation.bundles import simulate_bundle

RUNS = 50
# The simulated map's errors are drawn in the truth frame (the start pose is the true one):
# its covariance is stated in the truth frame, so consistency is judged there, unaligned.
TRUTH = NeesFrame(None, "the map's covariance is stated in the truth frame")


def _nees(b, r):  # type: ignore[no-untyped-def]
    """The recovery's pose NEES against the truth, unaligned (the prior left out)."""
    got = recovery_nees(b, r, TRUTH)
    assert got is not None
    return got[0].values


def _rmse(r, b) -> float:  # type: ignore[no-untyped-def]
    e = r.trajectory.poses[:, :2] - b.groundtruth.poses[:, :2]
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


@pytest.mark.slow  # 50 runs x three methods: the smoother and the batch make it the full tier's
@pytest.mark.parametrize("motion", ["velocity", "odometry"])
def test_perfect_map_filter_consistent_smoother_and_batch_better(motion: str) -> None:
    nees = {m: [] for m in ("filter", "smoother", "batch")}
    rmse = {m: [] for m in nees}
    for seed in range(RUNS):
        b = simulate_bundle(1000 + seed, steps=300, motion=motion)
        for m in nees:
            r = recover(b, method=m)
            nees[m].append(_nees(b, r))
            rmse[m].append(_rmse(r, b))
    f = summarize_nees(np.array(nees["filter"]), dof=3)
    assert f.band[0] < f.mean < f.band[1], f
    assert f.inside > 0.85, f
    for m in ("smoother", "batch"):
        s = summarize_nees(np.array(nees[m]), dof=3)
        assert s.band[0] < s.mean < s.band[1], (m, s)
        assert np.mean(rmse[m]) < 0.85 * np.mean(rmse["filter"]), (m, rmse)
        # better in most runs, not only on average
        assert np.mean(np.array(rmse[m]) < np.array(rmse["filter"])) > 0.9


@pytest.mark.slow
def test_perturbed_map_needs_the_map_covariance() -> None:
    means = {}
    for mode in ("joint", "marginal", "ignore"):
        values = []
        for seed in range(RUNS):
            b = simulate_bundle(2000 + seed, steps=300, map_sigma=(0.03, 0.08), map_covariance=True)
            r = recover(b, method="filter", map_mode=mode, max_outlier_run=None)
            values.append(_nees(b, r))
        means[mode] = summarize_nees(np.array(values), dof=3)
    joint = means["joint"]
    assert joint.band[0] < joint.mean < joint.band[1], joint
    assert joint.inside > 0.85
    assert means["ignore"].mean > 5 * joint.band[1], means["ignore"]
    assert means["marginal"].mean > 3 * joint.band[1], means["marginal"]
