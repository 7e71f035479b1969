"""evo's ``--downsample``, ``--motion_filter`` and ``--change_unit`` in ``slamrel ape``/``rpe``.

Oracles: evo's own loops written out pose by pose (``PosePath3D.downsample``,
``filters.filter_by_motion`` with 3×3 matrices and scipy's rotation vector, as evo computes
the angle), independent of the vectorised search of :mod:`relation_metric.pose_filters`; and
for ``--change_unit`` the numbers evo 1.38.1 printed in metres (``test_evo_cli.EVO``) scaled by
hand. The command lines are compared with evo live in ``test_evo_cli.py`` (slow tier).
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import require_data
from scipy.spatial.transform import Rotation

from relation_metric.errors import InputError
from relation_metric.pose_filters import downsample_ids, motion_filter_ids
from relation_metric.trajectory import Trajectory
from slamrel.cli import main


def _evo_motion_filter(poses: np.ndarray, distance: float, angle_deg: float) -> list[int]:
    """``evo.core.filters.filter_by_motion`` as evo 1.38.1 writes it (``poses`` N×7)."""
    rot = Rotation.from_quat(poses[:, 3:]).as_matrix()
    steps = np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1)
    dist = np.concatenate(([0.0], np.cumsum(steps)))
    threshold = np.deg2rad(angle_deg)
    kept, last, last_dist = [0], 0, 0.0
    for i in range(1, len(poses)):
        if dist[i] - last_dist >= distance:
            kept.append(i)
            last, last_dist = i, dist[i]
            continue
        angle = np.linalg.norm(Rotation.from_matrix(rot[last].T @ rot[i]).as_rotvec())
        if angle >= threshold:
            kept.append(i)
            last, last_dist = i, dist[i]
    return kept


def _walk(n: int, seed: int) -> Trajectory:
    """A seeded 3-D walk with stops (repeated positions) and slow and fast turns."""
    rng = np.random.default_rng(seed)
    step = rng.normal(0.0, 0.02, (n, 3)) * (rng.random((n, 1)) > 0.2)
    rotvec = np.cumsum(rng.normal(0.0, 0.03, (n, 3)) * (rng.random((n, 1)) > 0.5), axis=0)
    poses = np.column_stack((np.cumsum(step, axis=0), Rotation.from_rotvec(rotvec).as_quat()))
    return Trajectory(np.arange(n, dtype=np.float64), poses)


@pytest.mark.parametrize(
    ("distance", "angle_deg"),
    [(0.05, 5.0), (0.0, 5.0), (1.0, 0.0), (10.0, 2.0), (0.1, 180.0), (1e9, 1e9)],
)
def test_motion_filter_keeps_what_evos_loop_keeps(distance: float, angle_deg: float) -> None:
    traj = _walk(1200, seed=7)
    ours = motion_filter_ids(traj, distance, float(np.radians(angle_deg)))
    assert ours.tolist() == _evo_motion_filter(traj.poses, distance, angle_deg)


def test_motion_filter_refuses_what_evo_refuses() -> None:
    with pytest.raises(InputError, match="at least two poses"):
        motion_filter_ids(_walk(1, seed=1), 0.1, 0.1)
    with pytest.raises(InputError, match=">= 0"):
        motion_filter_ids(_walk(5, seed=1), -0.1, 0.1)


@pytest.mark.parametrize(("n", "k"), [(10, 3), (10, 10), (5, 9), (2874, 500), (7, 1)])
def test_downsample_is_evos_linspace(n: int, k: int) -> None:
    want = np.arange(n) if n <= k else np.linspace(0, n - 1, k, dtype=int)
    np.testing.assert_array_equal(downsample_ids(n, k), want)
    with pytest.raises(InputError):
        downsample_ids(n, 0)


def _zip(path: Path) -> tuple[dict, dict, np.ndarray]:
    with zipfile.ZipFile(path) as z:
        stats, info = json.loads(z.read("stats.json")), json.loads(z.read("info.json"))
        return stats, info, np.load(io.BytesIO(z.read("error_array.npy")))


def test_change_unit_scales_evos_numbers(tmp_path: Path) -> None:
    """evo's fr2_desk ``-as`` rmse 0.006123163030157291 m (test_evo_cli.EVO) is 6.123… mm;
    the title and the label name the new unit, as evo's."""
    tum = require_data("tum_rgbd")
    files = [str(tum / "fr2_desk_groundtruth.txt"), str(tum / "fr2_desk_ORB.txt")]
    out = tmp_path / "mm.zip"
    argv = ["ape", "tum", *files, "-as", "--change_unit", "mm", "--save_results", str(out)]
    assert main([*argv, "--silent"]) == 0
    stats, info, errors = _zip(out)
    assert stats["rmse"] == pytest.approx(0.006123163030157291 * 1000, rel=1e-12)
    assert errors.size == 2174
    assert info["title"].startswith("APE w.r.t. translation part (mm)")
    assert info["label"] == "APE (mm)"


@pytest.mark.parametrize(
    ("relation", "unit", "message"),
    [("full", "mm", "unit-less errors do not convert"), ("trans_part", "deg", "convert m to deg")],
)
def test_change_unit_refuses_what_evo_refuses(
    relation: str, unit: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    tum = require_data("tum_rgbd")
    files = [str(tum / "freiburg1_xyz-groundtruth.txt"), str(tum / "freiburg1_xyz-rgbdslam.txt")]
    assert main(["ape", "tum", *files, "-r", relation, "--change_unit", unit]) == 2
    err = capsys.readouterr().err
    assert message in err and "--change_unit" in err and "Traceback" not in err


def test_motion_filter_needs_times(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = np.tile(np.eye(3, 4).ravel(), (5, 1))
    rows[:, 3] = np.arange(5.0)
    ref = tmp_path / "a.kitti"
    np.savetxt(ref, rows)
    assert main(["rpe", "kitti", str(ref), str(ref), "--motion_filter", "0.1", "1"]) == 2
    assert "KITTI files have none" in capsys.readouterr().err
