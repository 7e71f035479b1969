"""The law of a mean NEES whose poses share an error (relation_metric.nees_law).

Oracles: Monte Carlo of the quadratic form with a hand-made joint covariance; the dense
trace formulas against the shared-map form; hand-computed extremes (independent poses, one
error shared by all)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from relation_metric.consistency import effective_sample_size
from relation_metric.errors import InputError
from relation_metric.nees_law import quadratic_form_law, shared_error_law


def _hand_made(n: int, r: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local covariances D_k, loadings V_k, and the P_k = D_k + V_k V_kᵀ they give."""
    rng = np.random.default_rng(seed)
    m = rng.normal(size=(n, 3, 3))
    d = m @ m.transpose(0, 2, 1) + 0.2 * np.eye(3)
    v = rng.normal(size=(n, 3, r)) * np.linspace(0.3, 1.5, n)[:, None, None]
    return d, v, d + v @ v.transpose(0, 2, 1)


def _joint(d: np.ndarray, v: np.ndarray) -> np.ndarray:
    n = d.shape[0]
    s = v.reshape(3 * n, -1) @ v.reshape(3 * n, -1).T
    for k in range(n):
        s[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] += d[k]
    return s


def test_shared_form_equals_the_dense_traces():
    d, v, p = _hand_made(12, 4, 0)
    law, dense = shared_error_law(p, v), quadratic_form_law(p, _joint(d, v))
    assert law.mean == pytest.approx(3.0) and dense.mean == pytest.approx(3.0)
    assert law.variance == pytest.approx(dense.variance, rel=1e-10)


def test_moments_and_gate_match_monte_carlo():
    """100,000 draws of e ~ N(0, Σ), Σ with serial (AR(1)) and shared (rank-2) parts."""
    n = 15
    _, v, _ = _hand_made(n, 2, 1)
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    local = np.kron(0.7**lag, np.diag([0.5, 0.3, 0.1]))
    sigma = local + v.reshape(3 * n, -1) @ v.reshape(3 * n, -1).T
    p = np.stack([sigma[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] for k in range(n)])
    law = quadratic_form_law(p, sigma)
    rng = np.random.default_rng(7)
    e = rng.multivariate_normal(np.zeros(3 * n), sigma, size=100_000).reshape(-1, n, 3)
    q = np.einsum("mki,kij,mkj->m", e, np.linalg.inv(p), e) / n
    assert q.mean() == pytest.approx(law.mean, rel=0.01)
    assert q.var() == pytest.approx(law.variance, rel=0.03)
    # the moment-matched g χ²(h) puts the 99 % two-sided gate where the draws are
    lo, hi = law.scale * chi2.ppf([0.005, 0.995], law.chi2_dof)
    outside = np.mean((q < lo) | (q > hi))
    assert 0.005 < outside < 0.02
    # the independent-steps gate (n = 15) is far too narrow for these errors
    lo_i, hi_i = chi2.ppf([0.005, 0.995], 3 * n) / n
    assert np.mean((q < lo_i) | (q > hi_i)) > 0.2


def test_extremes_by_hand():
    n = 20
    p = np.broadcast_to(np.diag([1.0, 2.0, 0.5]), (n, 3, 3)).copy()
    # independent poses: n_eff = N
    assert shared_error_law(p, np.zeros((n, 3, 0))).n_eff == pytest.approx(n)
    # every pose carries the same error, whitened: Q = |ξ|² ~ χ²(3), n_eff = 1
    same = np.linalg.cholesky(p)
    assert shared_error_law(p, same).n_eff == pytest.approx(1.0)
    # half the variance shared: Var = 2/N² (N·3/4·... ) by hand, U_k = I/√2
    half = same / np.sqrt(2.0)
    by_hand = 2.0 * (n * 3 * 0.25 + 2 * n * 3 * 0.25 + (n * 0.5) ** 2 * 3) / n**2
    assert shared_error_law(p, half).variance == pytest.approx(by_hand)


def test_without_shared_error_the_local_factor_is_the_old_n_eff():
    """r = 0 with τ = N / n_eff(values): the law's n_eff is the sequence's own (the lamp's
    rule before the shared map was known)."""
    rng = np.random.default_rng(3)
    values = np.convolve(rng.chisquare(3, 300), np.ones(5) / 5, mode="same")
    ess = effective_sample_size(values)
    p = np.broadcast_to(np.eye(3), (300, 3, 3))
    law = shared_error_law(p, np.zeros((300, 3, 0)), local_factor=300 / ess)
    assert law.n_eff == pytest.approx(ess)


def test_bad_shapes_and_covariances_are_one_error():
    p = np.broadcast_to(np.eye(3), (4, 3, 3)).copy()
    with pytest.raises(InputError, match="loadings"):
        shared_error_law(p, np.zeros((5, 3, 1)))
    p[2] = -np.eye(3)
    with pytest.raises(InputError, match="positive definite"):
        shared_error_law(p, np.zeros((4, 3, 1)))
    with pytest.raises(InputError, match="sigma"):
        quadratic_form_law(np.eye(3)[None], np.eye(4))


def test_the_quick_start_lamp_counts_the_shared_map(quickstart_run):
    """``slamrel run simple1``: the smoother's poses all carry its EKF-SLAM map's error, so the
    recovered mean NEES is worth a few poses, not the 84 the sequence's n_eff sees."""
    from slamrel.report.verdict import RunFacts, run_verdict

    r = quickstart_run.result
    rec = r.recovery_result
    local = rec.covariances - rec.map_loadings @ rec.map_loadings.transpose(0, 2, 1)
    assert np.linalg.eigvalsh(local).min() > -1e-12  # the log's share is a covariance
    facts = RunFacts.of(r)
    assert facts.nees_law is not None and facts.nees_values is not None
    assert facts.nees_law.n_eff < effective_sample_size(facts.nees_values) / 5
    line = next(j for j in run_verdict(facts).lines if j.key == "consistency")
    assert "shared by every pose" in line.value and line.level == "green"


def test_loadings_follow_the_pose_into_the_robot_frame():
    """``x = s ∘ m⁻¹``: the robot poses' loadings are the finite-difference derivative of the
    robot pose along each sensor-pose loading."""
    from recovery.mount import loadings_to_robot_frame, to_robot_frame

    rng = np.random.default_rng(5)
    s = rng.normal(size=(6, 3))
    v = rng.normal(size=(6, 3, 2))
    mount = np.array([0.3, 0.1, 0.2])
    got = loadings_to_robot_frame(s, v, mount)
    eye = np.broadcast_to(np.eye(3), (6, 3, 3))
    h = 1e-6
    for j in range(2):
        up = to_robot_frame(s + h * v[:, :, j], eye, mount)[0]
        down = to_robot_frame(s - h * v[:, :, j], eye, mount)[0]
        np.testing.assert_allclose((up - down) / (2 * h), got[:, :, j], atol=1e-7)


@pytest.mark.parametrize("mean", [0.0, 0.004, 0.7, 3.0, 12.5, 480.0])
@pytest.mark.parametrize("probability", [0.5, 0.99, 0.9999])
def test_poisson_quantile_equals_scipy_stats(mean: float, probability: float) -> None:
    """The start-up-light Poisson quantile equals scipy.stats.poisson.ppf (the oracle)."""
    from scipy.stats import poisson

    from relation_metric.consistency import poisson_quantile

    assert poisson_quantile(probability, mean) == int(poisson.ppf(probability, mean))


def test_nis_tail_level_is_the_poisson_rule_written_with_scipy() -> None:
    """The shared NIS tail rule against the rule written out with scipy.stats (the oracle):
    red above the 99.99 % Poisson quantile and 0.5 %, amber above 99.9 % and 0.2 %."""
    from scipy.stats import poisson

    from relation_metric.consistency import nis_tail_level

    for n in (0, 50, 400, 2183, 10_000):
        lam = 0.001 * n
        for tail in range(0, max(3, n // 40)):
            share = tail / n if n else 0.0
            want = (
                "red"
                if tail > poisson.ppf(0.9999, lam) and share > 0.005
                else "amber"
                if tail > poisson.ppf(0.999, lam) and share > 0.002
                else "green"
            )
            assert nis_tail_level(tail, n) == want, (tail, n)
