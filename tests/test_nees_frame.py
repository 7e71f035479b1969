"""NEES in the frame where it means something: the map frame anchored to the truth on the
landmarks (recovery.anchoring), so that the frame a SLAM run happened to choose does not
count as pose error."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from recovery.anchoring import NeesFrame, anchor_on_landmarks, anchor_on_start, start_frame
from recovery.bundle import Bundle
from recovery.recover import recover
from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.formats.bundle import read_bundle
from slamrel.pipeline import RunInput, landmark_frame, score_bundle
from slamrel.runs.nees import frame_by_id, recovery_nees

SIM = Path(__file__).resolve().parents[1] / "data" / "sim-bundle"
# the pose of the shifted map frame in the truth frame: (2.5 m, -1.0 m, 20 deg)
SHIFT = np.array([2.5, -1.0, np.deg2rad(20.0)])


def _rot3(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def in_shifted_frame(b: Bundle, shift: np.ndarray = SHIFT) -> Bundle:
    """The bundle with its map, initial pose and their covariances expressed in the frame whose
    pose in the bundle's own frame is ``shift``; ground truth left as it is."""
    inv = se2.inverse(shift)
    j = _rot3(float(inv[2]))
    r = j[:2, :2]
    m = b.map_xy.shape[0]
    big = np.kron(np.eye(m), r)
    xy = b.map_xy @ r.T + inv[:2]
    return replace(
        b,
        map_xy=xy,
        map_marginals=r @ b.map_marginals @ r.T,
        map_covariance=None if b.map_covariance is None else big @ b.map_covariance @ big.T,
        initial_pose=se2.compose(inv, b.initial_pose),
        initial_covariance=j @ b.initial_covariance @ j.T,
        path=None,
    )


def test_anchoring_recovers_a_known_transform_and_rotates_covariances() -> None:
    rng = np.random.default_rng(0)
    truth = rng.uniform(-10, 10, (12, 2))
    inv = se2.inverse(SHIFT)
    c, s = np.cos(inv[2]), np.sin(inv[2])
    in_map = truth @ np.array([[c, -s], [s, c]]).T + inv[:2]
    a = anchor_on_landmarks(in_map, truth)
    assert (a.dx, a.dy, a.dtheta) == pytest.approx(tuple(SHIFT), abs=1e-12)
    assert a.landmarks == 12 and a.rms_residual < 1e-12 and a.association == "id"
    poses = rng.normal(size=(5, 3))
    a_ = rng.normal(size=(5, 3, 3))
    covs = a_ @ a_.transpose(0, 2, 1)
    p, cv = a.apply(poses, covs)
    assert p == pytest.approx(se2.compose(SHIFT, poses))
    assert cv[:, 2, 2] == pytest.approx(covs[:, 2, 2])  # the heading's variance is unchanged
    assert np.linalg.eigvalsh(cv) == pytest.approx(np.linalg.eigvalsh(covs))
    with pytest.raises(InputError):
        anchor_on_landmarks(in_map[:1], truth[:1])


def test_without_shared_landmarks_there_is_no_landmark_fit() -> None:
    f = NeesFrame.by_id([1, 2, 3], np.zeros((3, 2)), None)
    assert not f.aligned and f.description.startswith("truth frame (no landmark ground truth")
    f = NeesFrame.by_id([1, 2, 3], np.zeros((3, 2)), (np.array([3, 4]), np.zeros((2, 2))))
    assert f.anchoring is None and "1 map landmark(s)" in f.description
    assert f.as_dict() == {
        "frame": f.description, "aligned": False, "anchoring": None, "map_anchoring": None
    }  # fmt: skip


def test_a_run_started_at_the_true_pose_is_in_the_truth_frame() -> None:
    x0, p0 = np.array([1.0, 2.0, 0.3]), 1e-6 * np.eye(3)
    assert anchor_on_start(x0, p0, x0 + [1e-4, 0.0, 0.0]) is None  # within its covariance
    a = anchor_on_start(x0, p0, se2.compose(SHIFT, x0))
    assert a is not None and a.association == "start"
    assert (a.dx, a.dy, a.dtheta) == pytest.approx(tuple(SHIFT))
    f = start_frame(x0, p0, x0)
    assert not f.aligned and "start pose is the ground truth's" in f.description


@pytest.mark.filterwarnings("ignore:only .* distinct pose pairs")
def test_shifted_map_frame_gives_the_same_nees() -> None:
    base = read_bundle(SIM)
    shifted = in_shifted_frame(base)
    r0, r1 = recover(base), recover(shifted)
    f0, f1 = frame_by_id(base), frame_by_id(shifted)
    assert f0.anchoring is None and f1.anchoring is not None  # sim-bundle starts at the truth
    assert f1.description == "map frame placed in the truth frame by the run's start pose"
    # the reported anchoring is the applied shift, exactly
    a1 = f1.anchoring
    assert (a1.dx, a1.dy, a1.dtheta) == pytest.approx(tuple(SHIFT), abs=1e-12)
    # the landmark fit (the map's own offset) is reported, the same in both frames
    m0, m1 = f0.map_anchoring, f1.map_anchoring
    assert m0 is not None and m1 is not None and m1.rms_residual == pytest.approx(m0.rms_residual)
    # the NEES does not depend on the frame the run chose (pose 0, the prior, left out) ...
    g0, g1 = recovery_nees(base, r0, f0), recovery_nees(shifted, r1, f1)
    assert g0 is not None and g1 is not None
    (c0, u0), (c1, u1) = g0, g1
    assert c1.values == pytest.approx(c0.values, rel=1e-4)  # rounding of the rotation
    # ... while the unplaced one blows up
    assert u1.mean > 1000 * c0.summary.mean and u0 == c0.summary
    # slamrel run's NEES (the same computation, its frame fitted on the map comparison's
    # pairs) and metrics.json say the same
    res0 = score_bundle(RunInput(base, "base"))
    res1 = score_bundle(RunInput(shifted, "shifted"))
    n0, n1 = res0.nees["recovered"].summary, res1.nees["recovered"].summary
    assert n1.mean == pytest.approx(n0.mean, rel=1e-3)
    assert n0 == c0.summary and n1.mean == pytest.approx(c1.summary.mean, rel=1e-12)
    m = res1.metrics()
    assert m["nees_frame"]["frame"] == f1.description
    assert m["nees_frame"]["anchoring"]["dtheta_deg"] == pytest.approx(20.0)
    assert any(n.startswith("NEES is computed in the map frame placed") for n in m["notes"])


def test_landmarks_without_shared_ids_are_associated_automatically() -> None:
    b = read_bundle(SIM)
    shifted = in_shifted_frame(b)
    renamed = replace(
        shifted,
        map_ids=shifted.map_ids + 1000,
        measurement_landmarks=shifted.measurement_landmarks + 1000,
    )
    f_id, _ = landmark_frame(shifted)
    f_auto, assoc = landmark_frame(renamed)
    assert assoc is not None and f_auto.map_anchoring is not None
    assert f_id.map_anchoring is not None
    got, want = f_auto.map_anchoring, f_id.map_anchoring
    assert got.association == "auto" and got.landmarks == 8
    assert (got.dx, got.dy, got.dtheta) == pytest.approx((want.dx, want.dy, want.dtheta))
