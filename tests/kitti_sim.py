"""The seeded KITTI-like drive of :mod:`slamrel.simulation.kitti_drive`, and a writer of
the devkit's pose files for the tests."""

from __future__ import annotations

import numpy as np

from slamrel.simulation.kitti_drive import drive

__all__ = ["drive", "write_kitti"]


def write_kitti(path: str, poses: np.ndarray) -> None:
    """KITTI odometry poses: the row-major 3x4 [R | t], 12 numbers a line."""
    np.savetxt(path, poses[:, :3, :4].reshape(len(poses), 12), fmt="%.12e")
