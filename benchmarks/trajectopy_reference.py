"""trajectopy's relative drift on the seeded KITTI-like drive of ``slamrel/simulation/kitti_drive.py``.

Run in trajectopy's side venv (``benchmarks/.venv-trajectopy``: ``python -m venv`` it and
``pip install trajectopy``; never a project dependency)::

    benchmarks/.venv-trajectopy/bin/python benchmarks/trajectopy_reference.py

trajectopy's RPE in metres (``pair_min_distance=100 .. pair_max_distance=800``, every pose
a start: ``use_all_pose_pairs``) is the KITTI devkit's segment error with three differences:
every frame starts a segment (the devkit: every 10th), a segment ends at the first pose at
least ``L`` further (the devkit: strictly further; the same on continuous data) and each error
is divided by the segment's actual length (the devkit: by ``L``). So the comparable numbers,
printed per length as JSON, are the segment count and the mean unnormalised errors
``mean ‖t(E)‖`` [m] and ``mean angle(R(E))`` [rad] (``pos_dev · distance``); the test
``tests/test_drift.py`` stores them and checks slamrel's ``kitti_drift(step=1)`` against them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trajectopy  # noqa: E402
from trajectopy.core.settings import (  # noqa: E402
    PairDistanceUnit,
    ProcessingSettings,
    RelativeComparisonSettings,
)
from trajectopy.processing.evaluation import _compare_trajectories_relative  # noqa: E402


def _load_drive():  # type: ignore[no-untyped-def]
    """The drive generator by its file path: this side venv has numpy, not slamrel."""
    import importlib.util

    path = Path(__file__).resolve().parent.parent / "slamrel" / "simulation" / "kitti_drive.py"
    spec = importlib.util.spec_from_file_location("kitti_drive", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


kitti_drive = _load_drive()


def _trajectory(poses: np.ndarray, name: str) -> object:

    from trajectopy.core.positions import Positions
    from trajectopy.core.rotations import Rotations

    t = np.arange(len(poses)) * 0.1
    return trajectopy.Trajectory(
        positions=Positions(poses[:, :3, 3].copy()),
        rotations=Rotations.from_matrix(poses[:, :3, :3].copy()),
        timestamps=t,
        name=name,
    )


def main() -> None:
    gt, est = kitti_drive.drive()
    settings = RelativeComparisonSettings(
        pair_min_distance=100.0,
        pair_max_distance=800.0,
        pair_distance_step=100.0,
        pair_distance_unit=PairDistanceUnit.METER,
        use_all_pose_pairs=True,
    )
    res = _compare_trajectories_relative(
        trajectory=_trajectory(est, "est"),
        other=_trajectory(gt, "gt"),
        relative_comparison_settings=settings,
    )
    dev = res.rpe_dev
    out = {"trajectopy": trajectopy.__version__, "per_length": []}
    for length in sorted(dev.pos_dev):
        dist = np.asarray(dev.pair_distance[length])
        t = np.asarray(dev.pos_dev[length]) * dist
        r = np.asarray(dev.rot_dev[length]) * dist
        out["per_length"].append(
            {
                "length": float(length),
                "count": int(dist.size),
                "mean_t": float(t.mean()) if t.size else None,
                "mean_r": float(r.mean()) if r.size else None,
            }
        )
    out["pos_rpe_percent"] = res.pos_rpe
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    _ = ProcessingSettings  # the settings family used above
    main()
