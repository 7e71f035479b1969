"""Recovery is faithful: it ranks SLAM runs as their online trajectories do."""

from __future__ import annotations

import numpy as np
import pytest

from slamrel.studies.faithfulness import faithfulness_study


@pytest.mark.slow
def test_recovered_ranks_runs_like_online(capsys):
    study = faithfulness_study("complex1")
    n = len(study.configs)
    tau_g, tau_l = study.kendall_tau("global"), study.kendall_tau("consecutive")
    ratio = study.ratio("global")
    with capsys.disabled():
        print(
            f"\nfaithfulness over {n} runs: Kendall tau {tau_g:.3f} (global), "
            f"{tau_l:.3f} (consecutive); "
            f"recovered/online global error ratio min {ratio.min():.2f}, median "
            f"{np.median(ratio):.2f}, max {ratio.max():.2f}"
        )
    assert n >= 20
    assert tau_g >= 0.8 and tau_l >= 0.8
    # the final map is at least as good as the map the filter had online: recovered errors
    # are not larger than online ones beyond a small margin, and never an order smaller
    assert ratio.max() < 1.25 and ratio.min() > 0.25


@pytest.mark.slow
def test_tuning_study_on_a_small_grid():
    """The grid's bookkeeping on 2 × 2 runs of a small world (fast; the full grid is slow)."""
    from slamrel.studies.faithfulness import tuning_study

    s = tuning_study("simple1", noise="a", seeds=(0,), process_noise_scales=(0.1, 1.0),
                     corruptions=(0.0, 0.05))  # fmt: skip
    assert [(c["process_noise_scale"], c["corrupt_fraction"]) for c in s.configs] == [
        (0.1, 0.0), (0.1, 0.05), (1.0, 0.0), (1.0, 0.05)
    ]  # fmt: skip
    assert s.broken.tolist() == [False, True, False, True]
    np.testing.assert_allclose(s.ratio("global"), s.recovered["global"] / s.online["global"])
    # separation oracle: count the pairs by hand
    b, h = s.recovered["global"][[1, 3]], s.recovered["global"][[0, 2]]
    assert s.separation() == pytest.approx(np.mean([x > y for x in b for y in h]))
    assert s.disagreement.shape == (4,) and ((s.disagreement >= 0) & (s.disagreement <= 1)).all()
    summ = s.summary()
    assert summ["runs"] == 4 and -1.0 <= summ["kendall_tau_global"] <= 1.0


# The full 5 × 5 grid (acceptance: broken runs ≥ 0.5× online, healthy ≤ 1.5×, τ ≥ 0.8 on
# far-apart relations, separation 1) is asserted in notebooks/validation.ipynb, which
# tests/test_notebooks.py executes: running it twice would add a minute to the suite.


def test_ate_at_reference_times_is_alignment_invariant():
    from relation_metric import se2
    from relation_metric.trajectory import Trajectory
    from slamrel.studies.faithfulness import ate_at_reference_times

    rng = np.random.default_rng(4)
    t = np.arange(0.0, 50.0, 0.1)
    ref = Trajectory(t, np.column_stack((np.cos(t / 5), np.sin(t / 7), t / 10)))
    moved = se2.compose(np.array([3.0, -1.0, 0.7]), ref.poses)  # a rigid motion: ATE 0
    # the estimate on a grid offset by 4 ms: each reference pose takes the nearest one
    t_est = np.sort(np.concatenate((t + 0.004, t + 0.05)))
    dense = np.zeros((t_est.size, 3))
    dense[0::2] = moved
    dense[1::2] = 1e3  # far poses 46 ms from every reference time: never picked
    assert ate_at_reference_times(t_est, dense, ref) == pytest.approx(0.0, abs=1e-9)
    # isotropic noise of σ = 0.05 m per axis: RMSE ≈ σ √2 (alignment absorbs ~3 dof)
    noisy = dense.copy()
    noisy[0::2, :2] += rng.normal(scale=0.05, size=(t.size, 2))
    assert ate_at_reference_times(t_est, noisy, ref) == pytest.approx(0.05 * np.sqrt(2), rel=0.1)


@pytest.mark.slow  # four recovery variants on robot 5's log: the full tier's
def test_robust_recovery_on_mrclam_robot5():
    """Real data (MRCLAM dataset 7, robot 5, surveyed map): the plain EKF is thrown off by
    outliers (and with re-entry the divergence is reported), the Cauchy M-estimator is as good
    as the gated EKF (≤ 1.05×) without gating anything, and its smoother is below its filter."""
    from conftest import require_data

    from slamrel.importers.mrclam import mrclam_bundle
    from slamrel.studies.faithfulness import RECOVERY_VARIANTS, recovery_variants_table

    d = require_data("mrclam", "MRCLAM_Dataset7")
    keep = {k: RECOVERY_VARIANTS[k] for k in ("plain", "gated", "reentry", "cauchy")}
    white = mrclam_bundle(d, 5, persisting=False, window=1.0)  # the variants' white model
    rows = {r["variant"]: r for r in recovery_variants_table({"r5": white}, keep)}
    assert rows["plain"]["filter_ratio"] > 2.0 and rows["reentry"]["stretches"] >= 1
    assert rows["cauchy"]["filter_ratio"] <= 1.05 and rows["cauchy"]["gated_fraction"] == 0.0
    assert rows["cauchy"]["smoother"] < rows["cauchy"]["filter"]
    assert 0.0 < rows["cauchy"]["downweight_loss"] < rows["cauchy"]["downweighted_fraction"]


# three recoveries per robot, ~5 s each robot: all five in the full tier
@pytest.mark.slow
@pytest.mark.parametrize("robot", [1, 2, 3, 4, 5])
def test_default_recovery_meets_issue_12_on_mrclam(robot: int) -> None:
    """The default's acceptance (MRCLAM dataset 7, fitted noise, surveyed map): the default
    filter's position ATE after SE(2) alignment at the Vicon times is ≤ 1.05 × min(plain EKF,
    99.9%-gated EKF), nothing gated, the down-weighted share reported; the smoother is below
    the filter on the 1 s relations and on the unaligned ATE (the map is in Vicon's frame).

    Robot 4's aligned ATE is the exception, measured in every variant (plain, gated, Cauchy,
    default: smoother 1.03–1.04 × filter): its measurements are biased (at the Vicon poses,
    bearing residual −0.011 rad on average and negative for all 15 landmarks, range −0.16 to
    −0.29 m on landmarks 3–7); the
    filter's error from that bias is largely a rigid offset that the alignment removes, the
    smoother's (which uses every biased measurement twice) is not.
    """
    from conftest import require_data

    from slamrel.importers.mrclam import mrclam_bundle
    from slamrel.studies.faithfulness import RECOVERY_VARIANTS, recovery_variants_table

    d = require_data("mrclam", "MRCLAM_Dataset7")
    keep = {k: RECOVERY_VARIANTS[k] for k in ("plain", "gated", "default")}
    rows = recovery_variants_table({f"r{robot}": mrclam_bundle(d, robot)}, keep)
    r = {row["variant"]: row for row in rows}["default"]
    assert r["filter_ratio"] <= 1.05 and r["filter_1s_ratio"] <= 1.05
    assert r["smoother_1s"] < r["filter_1s"] and r["smoother_raw"] < r["filter_raw"]
    # measured with relations too: 1 s and loop relations (revisits within 0.5 m, 30 s apart)
    assert r["filter_loops_ratio"] <= 1.05 and r["smoother_loops"] < r["filter_loops"]
    if robot != 4:
        assert r["smoother"] < r["filter"]
    else:
        assert r["smoother"] < 1.05 * r["filter"]
    assert r["gated_fraction"] == 0.0
    assert 0.0 < r["downweight_loss"] < r["downweighted_fraction"] < 1.0


@pytest.mark.slow
def test_robust_recovery_does_not_hide_a_broken_map():
    """docs/design.md pitfall: on an EKF-SLAM run with 1% wrong associations, a 99.9% gate without
    re-entry makes the map look much better than the run was; the M-estimators (scale from a
    plain pass) and the re-entering default stay near the online error.

    "Near": the smoother and the batch weigh the map by its joint covariance (issue 23), which
    makes them more accurate than the online filter on broken runs too (measured 0.87–0.88 ×
    online for the default, Cauchy and Huber; the filter 0.97–0.98 ×); hiding is 0.57 ×."""
    from recovery.recover import recover
    from relation_metric.evaluate import evaluate
    from relation_metric.relations import generate_relations
    from relation_metric.trajectory import Trajectory
    from slamrel.backends.ekf_slam import ekf_slam_bundle
    from slamrel.simulation.bundles import world_bundle
    from slamrel.simulation.worlds import make_world

    world = make_world("complex1", noise="a", seed=0)
    truth = world.truth
    rel = generate_relations(truth, "global", count=2000, seed=0)
    broken, slam = ekf_slam_bundle(world_bundle(world), corrupt_fraction=0.01, seed=1)

    def score(tr):  # type: ignore[no-untyped-def]
        k = np.searchsorted(tr.timestamps, truth.timestamps)
        return evaluate(rel, Trajectory(truth.timestamps, tr.poses[k])).translation.abs.mean

    online = score(slam.online)
    hidden = score(recover(broken, gate=0.999, max_outlier_run=None).trajectory)
    assert hidden < 0.7 * online  # the oracle can tell hiding from faithfulness
    for kw in ({}, {"robust": "cauchy"}, {"robust": "huber"}):
        r = recover(broken, **kw)
        assert score(r.trajectory) > 0.8 * online, kw
