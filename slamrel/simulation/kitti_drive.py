"""A seeded KITTI-like drive: ground truth and a drifting estimate (pure numpy, no I/O).

For the KITTI drift checks (``tests/test_drift.py``) and for trajectopy's cross-check, which
runs in trajectopy's side venv without slamrel and so loads this file by its path
(``benchmarks/trajectopy_reference.py``): it imports numpy only.

:func:`drive` makes a ground truth at 10 Hz in KITTI's camera convention (x right, y down,
z forward; the path lies in the x-z plane with small height changes) and an estimate that
integrates the true frame-to-frame motions with seeded noise (so it drifts). Poses are 4x4
matrices, shape (frames, 4, 4).
"""

from __future__ import annotations

import numpy as np

__all__ = ["drive"]


def _rot_y(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    r[..., 0, 0], r[..., 0, 2], r[..., 1, 1] = c, s, 1.0
    r[..., 2, 0], r[..., 2, 2] = -s, c
    return r


def _small_rotation(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrices of rotation vectors (..., 3)."""
    th = np.linalg.norm(w, axis=-1, keepdims=True)
    k = w / np.where(th > 0, th, 1.0)
    kx = np.zeros(w.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    t = th[..., None]
    return np.eye(3) + np.sin(t) * kx + (1 - np.cos(t)) * kx @ kx


def drive(seed: int = 7, frames: int = 1300, speed: float = 9.0) -> tuple[np.ndarray, np.ndarray]:
    """(ground truth, estimate): two (frames, 4, 4) pose arrays, seeded."""
    rng = np.random.default_rng(seed)
    yaw_rate = np.convolve(rng.normal(0.0, 0.02, frames), np.ones(25) / 25, mode="same")
    yaw = np.cumsum(yaw_rate)
    r = _rot_y(yaw)
    fwd = r[:, :, 2] * speed * 0.1
    fwd[:, 1] += 0.02 * np.sin(np.arange(frames) / 40.0)  # small height changes (y down)
    t = np.cumsum(fwd, axis=0) - fwd[0]
    gt = np.tile(np.eye(4), (frames, 1, 1))
    gt[:, :3, :3], gt[:, :3, 3] = r, t
    rel = np.linalg.inv(gt[:-1]) @ gt[1:]
    noise = np.tile(np.eye(4), (frames - 1, 1, 1))
    noise[:, :3, :3] = _small_rotation(rng.normal(0.0, 2e-4, (frames - 1, 3)))
    noise[:, :3, 3] = rng.normal(0.0, 0.01, (frames - 1, 3)) + [0.0, 0.0, 0.004]
    est = np.empty_like(gt)
    est[0] = gt[0]
    for k in range(frames - 1):  # integration is sequential by nature (test data only)
        est[k + 1] = est[k] @ rel[k] @ noise[k]
    return gt, est
