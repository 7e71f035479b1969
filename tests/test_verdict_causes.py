"""The verdict names the Gaussian assumptions a run's innovations break (heavy tails,
correlation in time) on simulated runs whose measurement noise is known to break them, and
names none on runs with the Gaussian white noise the models state."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from relation_metric import se2
from slamrel.pipeline import RunInput, score_bundle
from slamrel.report.verdict import RunFacts, gaussian_breaks, run_verdict
from slamrel.simulation.healthy import healthy_bundle


def _with_noise(noise: str, seed: int):
    """simple1's healthy bundle with its measurements redrawn from the truth: ``gauss``
    (the stated σ, white), ``t3`` (Student-t with 2.5 dof scaled to the stated variance: a
    narrower bulk and heavy tails) or ``ar1`` (Gaussian of the stated σ, each error 0.9 ×
    that of the landmark's previous sighting plus fresh noise: a persisting error)."""
    b = healthy_bundle("simple1", seed, "marginal", odometry=None)
    rng = np.random.default_rng([36, seed])
    ids, xy = b.landmarks_groundtruth
    rows = np.searchsorted(ids, b.measurement_landmarks)
    local = se2.inverse_transform_points(b.groundtruth.poses_at(b.measurement_times), xy[rows])
    sigma = np.array([b.sensor.sigma_range, b.sensor.sigma_bearing])
    n = local.shape[0]
    if noise == "gauss":
        e = rng.standard_normal((n, 2))
    elif noise == "t3":
        e = rng.standard_t(2.5, size=(n, 2)) / np.sqrt(5.0)
    else:  # along each landmark's sightings
        w = rng.standard_normal((n, 2)) * np.sqrt(1 - 0.9**2)
        e = rng.standard_normal((n, 2))
        order = np.lexsort((np.arange(n), b.measurement_landmarks))
        for prev, k in zip(order[:-1], order[1:]):  # the oracle's recursion, not a hot path
            if b.measurement_landmarks[prev] == b.measurement_landmarks[k]:
                e[k] = 0.9 * e[prev] + w[k]
    z = np.column_stack((np.hypot(local[:, 0], local[:, 1]), np.arctan2(local[:, 1], local[:, 0])))
    z += e * sigma
    z[:, 0] = np.abs(z[:, 0])
    z[:, 1] = se2.wrap_angle(z[:, 1])
    return replace(b, measurements=z)


def _facts(nis, landmarks=None):
    return RunFacts(main="recovered", translation_errors={}, relations=0, nis=nis,
                    nis_landmarks=landmarks)  # fmt: skip


def test_breaks_on_known_innovations(rng):
    """Oracles on NIS drawn from known laws (no filter): χ²(2) white → no cause; a squared
    t₃ of unit variance → heavy tails; squared AR(1) Gaussians of coefficient 0.9 per
    landmark → correlation (squares of Gaussians correlated ρ correlate ρ²: 0.81 between
    successive sightings, 0.9²⁰ = 0.12 ten apart), with the AR(1) factor (1 + ρ)/(1 − ρ)
    from ρ = √(difference)."""
    n = 4000
    ids = np.arange(n) % 4
    assert gaussian_breaks(_facts(rng.chisquare(2, n), ids)) == []
    t = rng.standard_t(3, size=(n, 2)) / np.sqrt(3.0)
    (heavy,) = gaussian_breaks(_facts(np.sum(t**2, axis=1), ids))
    assert heavy.startswith("heavy tails: ")
    e = rng.standard_normal((n, 2))
    for k in range(4, n):  # the oracle's recursion
        e[k] = 0.9 * e[k - 4] + np.sqrt(1 - 0.81) * e[k]
    (corr,) = gaussian_breaks(_facts(np.sum(e**2, axis=1), ids))
    near = float(corr.split("a landmark ")[1].split(",")[0])
    far = float(corr.split("10 apart ")[1].split(" ")[0])
    assert near == pytest.approx(0.81, abs=0.05)  # ρ² at lag 1
    assert far == pytest.approx(0.9**20, abs=0.08)  # ρ²⁰ at lag 10
    factor = float(corr.split("about ")[2].split("×")[0])
    rho = np.sqrt(near - far)
    assert factor == pytest.approx((1 + rho) / (1 - rho), rel=0.05)
    # without the landmarks, successive measurements are paired: interleaved, no correlation
    assert gaussian_breaks(_facts(np.sum(e**2, axis=1))) == []


def _judged(noise: str, seed: int):
    facts = RunFacts.of(score_bundle(RunInput(_with_noise(noise, seed), name=noise)))
    return gaussian_breaks(facts), run_verdict(facts)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_gaussian_white_noise_names_no_cause(seed):
    causes, verdict = _judged("gauss", seed)
    assert causes == []
    assert not any("cause:" in ln.value for ln in verdict.lines)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_student_t_noise_is_named_heavy_tails(seed):
    """t with 2.5 dof of the stated variance: 0.4 % beyond the 99.9 % bound, median NIS
    below 1.39; white, so no correlation is named."""
    causes, verdict = _judged("t3", seed)
    assert len(causes) == 1 and causes[0].startswith("heavy tails: ")
    line = next(ln for ln in verdict.lines if ln.key == "map_log")
    assert line.level != "green" and "cause: heavy tails" in line.value


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_persisting_noise_is_named_correlated(seed):
    """AR(1) errors along each landmark's sightings (0.9): the correlation is named (the
    healthy runs with white noise above stay below the threshold)."""
    causes, _ = _judged("ar1", seed)
    assert [c for c in causes if c.startswith("innovations correlated in time")]
