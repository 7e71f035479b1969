"""The planar pose graph with point landmarks: the record that solvers take and readers build.

A :class:`PoseGraph` holds the initial guess of every pose ``[x, y, θ]`` and landmark
``[x, y]`` and the factors between them:

* pose–pose ``z_ij ≈ x_i⁻¹ ∘ x_j`` with its information (inverse covariance) ``Ω_ij``,
* pose–landmark ``z_kl ≈ x_k⁻¹ · l`` (the landmark in the pose's frame) with ``Ω_kl``.

It is a record on its own, apart from any solver, so that the graph file readers
(:mod:`slamrel.formats.g2o`, :mod:`~slamrel.formats.toro`, :mod:`~slamrel.formats.isam`) and
the importers build it without importing an optimiser, and every estimator
(:mod:`~slamrel.backends.least_squares`, :mod:`~slamrel.backends.toro_optimiser`,
:mod:`~slamrel.backends.lever_sgd`, :mod:`~slamrel.backends.pose_only`) takes the same
checked record.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly

__all__ = ["PoseGraph", "initial_landmarks", "first_of_each"]


@dataclass(frozen=True)
class PoseGraph:
    """A planar pose graph with landmarks.

    Parameters
    ----------
    poses : array_like, shape (N, 3)
        Initial guess of the poses.
    landmarks : array_like, shape (L, 2)
        Initial guess of the landmarks (see :func:`initial_landmarks`).
    pp_i, pp_j : array_like of int, shape (E,)
        Pose–pose factors ``x_i⁻¹ ∘ x_j``.
    pp_z : array_like, shape (E, 3)
    pp_info : array_like, shape (E, 3, 3)
        Information (inverse covariance) of each pose–pose measurement.
    pl_k, pl_l : array_like of int, shape (F,)
        Pose–landmark factors: pose index, landmark index.
    pl_z : array_like, shape (F, 2)
        The landmark in the pose frame, ``x_k⁻¹ · l``.
    pl_info : array_like, shape (F, 2, 2)
    """

    poses: Array
    landmarks: Array
    pp_i: NDArray[np.int64]
    pp_j: NDArray[np.int64]
    pp_z: Array
    pp_info: Array
    pl_k: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    pl_l: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    pl_z: Array = field(default_factory=lambda: np.empty((0, 2)))
    pl_info: Array = field(default_factory=lambda: np.empty((0, 2, 2)))

    def __post_init__(self) -> None:
        n = np.asarray(self.poses).shape[0]
        m = np.asarray(self.landmarks).reshape(-1, 2).shape[0]
        conv = {
            "poses": ((n, 3), np.float64),
            "landmarks": ((m, 2), np.float64),
            "pp_i": (None, np.int64),
            "pp_j": (None, np.int64),
            "pp_z": (None, np.float64),
            "pp_info": (None, np.float64),
            "pl_k": (None, np.int64),
            "pl_l": (None, np.int64),
            "pl_z": (None, np.float64),
            "pl_info": (None, np.float64),
        }
        for name, (_, dtype) in conv.items():
            arr = np.asarray(getattr(self, name), dtype=dtype)
            if name == "landmarks":
                arr = arr.reshape(-1, 2)
            object.__setattr__(self, name, readonly(arr, dtype))
        e = self.pp_i.shape[0]
        f = self.pl_k.shape[0]
        shapes = {
            "pp_j": (e,),
            "pp_z": (e, 3),
            "pp_info": (e, 3, 3),
            "pl_l": (f,),
            "pl_z": (f, 2),
            "pl_info": (f, 2, 2),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise InputError(f"{name} must have shape {shape}, got {getattr(self, name).shape}")
        for name, idx, size in (
            ("pose-pose i", self.pp_i, n),
            ("pose-pose j", self.pp_j, n),
            ("pose-landmark pose", self.pl_k, n),
            ("pose-landmark landmark", self.pl_l, m),
        ):
            if idx.size and (idx.min() < 0 or idx.max() >= size):
                raise InputError(f"{name} index out of range 0..{size - 1}")
        for name in ("poses", "landmarks", "pp_z", "pp_info", "pl_z", "pl_info"):
            if not np.isfinite(getattr(self, name)).all():
                raise InputError(f"{name} contains non-finite values")

    @property
    def n_poses(self) -> int:
        return int(self.poses.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.landmarks.shape[0])


def initial_landmarks(
    poses: ArrayLike, pl_k: ArrayLike, pl_l: ArrayLike, pl_z: ArrayLike, n_landmarks: int
) -> Array:
    """Landmark guesses from their first observation: ``x_k · z`` (vectorised)."""
    k = np.asarray(pl_k, dtype=np.int64)
    lm = np.asarray(pl_l, dtype=np.int64)
    out = np.full((n_landmarks, 2), np.nan)
    first = first_of_each(lm, np.arange(lm.size))
    out[lm[first]] = se2.transform_points(np.asarray(poses)[k[first]], np.asarray(pl_z)[first])
    missing = np.flatnonzero(~np.isfinite(out[:, 0]))
    if missing.size:
        raise InputError(f"landmark {int(missing[0])} is never observed; cannot initialise it")
    return out


def first_of_each(group: NDArray[np.int64], rank: NDArray[np.int64]) -> NDArray[np.int64]:
    """Index of the lowest-``rank`` element of each distinct ``group`` (ties: first index).

    With ``group`` the landmark of each pose–landmark factor: its first sighting, in factor
    order (``rank = arange``) or by the observing pose (``rank = pl_k``).
    """
    order = np.lexsort((np.arange(group.size), rank, group))
    return order[np.concatenate(([True], np.diff(group[order]) != 0))] if group.size else order
