"""The reference EKF-SLAM with observability-constrained Jacobians (OC-EKF, after Huang,
Mourikis & Roumeliotis 2010; ``jacobians="oc"``).

Oracles: the null space of the linearised system (a rotation of the whole scene about the
origin gains no information: its information ``nᵀ P⁻¹ n`` is unchanged by every update and
landmark initialisation and only shrinks through the process noise; the standard EKF's grows),
the χ² law of the online and map NEES on a run where the standard EKF is overconfident, and the
standard filter itself in the linear limit.
"""

from __future__ import annotations

import numpy as np
import pytest

import slamrel.backends.ekf_slam as ekf
from relation_metric.consistency import pose_nees
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world


def _rotation_information(f: ekf._Filter) -> float:
    """``nᵀ P⁻¹ n`` of the filter's rotation null vector ``[J r; 1; J λ_1; …]``, with the
    virtual robot ``r = prior`` and the landmarks' ``λ_i`` (OC's linearisation points)."""
    n = f.n
    pts = np.vstack((f.prior[None, :2], f.first[3:n].reshape(-1, 2)))
    jp = np.column_stack((-pts[:, 1], pts[:, 0]))  # J p, J the 90° rotation
    vec = np.concatenate((jp[0], [1.0], jp[1:].ravel()))
    return float(vec @ np.linalg.solve(f.cov[:n, :n], vec))


def _information_trace(
    jacobians: str, monkeypatch: pytest.MonkeyPatch
) -> list[tuple[float, float]]:
    """``(before, after)`` the rotation information around every prediction of a run."""
    trace: list[tuple[float, float]] = []

    class Recorder(ekf._Filter):
        def predict(self, u: np.ndarray, sigma: np.ndarray) -> None:
            before = _rotation_information(self)
            super().predict(u, sigma)
            trace.append((before, _rotation_information(self)))

    monkeypatch.setattr(ekf, "_Filter", Recorder)
    w = make_world("simple1", noise="c", seed=15)
    ekf_slam_bundle(world_bundle(w), jacobians=jacobians)  # type: ignore[arg-type]
    return trace


@pytest.mark.slow  # two runs with a 450 × 450 solve per step: ~10 s
def test_oc_gains_no_information_on_the_unobservable_rotation(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Updates and initialisations keep ``nᵀ P⁻¹ n`` (from one prediction's end to the next
    one's start), predictions only lower it; the standard EKF raises it (its spurious heading
    information, Huang et al.)."""
    oc = np.array(_information_trace("oc", monkeypatch))
    # between predictions: the step's updates and new landmarks, information unchanged
    assert np.allclose(oc[1:, 0], oc[:-1, 1], rtol=1e-6, atol=0.0)
    assert np.all(oc[:, 1] <= oc[:, 0] * (1 + 1e-9))  # process noise only removes information
    std = np.array(_information_trace("standard", monkeypatch))
    gain = std[1:, 0] / std[:-1, 1]  # the standard EKF learns the unobservable rotation:
    assert np.mean(gain > 1.001) > 0.5 and gain.max() > 1.05, gain  # most steps, up to 11 %


def test_oc_keeps_pose_and_map_consistent_where_the_standard_filter_is_not() -> None:
    """simple1, noise c, seed 15: online NEES over its dof, standard 13.9, OC 1.0; the map's
    NEES over its dof, standard 2.28, OC 1.35."""
    w = make_world("simple1", noise="c", seed=15)
    q, map_q = {}, {}
    for jac in ("standard", "oc"):
        _, res = ekf_slam_bundle(world_bundle(w), jacobians=jac)  # type: ignore[arg-type]
        e = pose_nees(res.online.poses[1:], w.truth.poses[1:], res.online_covariance[1:])
        q[jac] = float(np.mean(e)) / 3
        err = (w.landmarks[res.landmark_ids] - res.map_xy).ravel()
        map_q[jac] = float(err @ np.linalg.solve(res.map_covariance, err)) / err.size
    assert q["standard"] > 3.0 and 0.5 < q["oc"] < 1.5, q
    # the map's NEES is correlated across landmarks (shared pose errors): judged as the map
    # consistency lamp's green allowance judges it, and against the standard filter's
    assert 0.5 < map_q["oc"] < min(1.5, map_q["standard"]), map_q


# The linear limit and the refusal of nn association: tests/test_ekfslam_fej.py.
