"""The pose group as a parameter: one interface over SE(2) and SE(3).

Association, relation errors, statistics and relation generation are written once against
:class:`PoseGroup` (the model is liegroups' shared ``_base``); :data:`SE2` and :data:`SE3` are
its two instances. A pose array says which group it belongs to by its last axis:

* SE(2): ``(..., 3)`` ``[x, y, θ]`` (:mod:`relation_metric.se2`);
* SE(3): ``(..., 7)`` ``[x, y, z, qx, qy, qz, qw]`` (:mod:`relation_metric.se3`).

Both groups give a relation error the same six components, so statistics, weights and
outputs need not know the group:

* :meth:`PoseGroup.error_components` of ``e = δ*⁻¹ ∘ δ`` (paper mode):
  ``[e_x, e_y, e_z, ω_x, ω_y, ω_z]`` — the translation of ``e`` and its rotation vector
  (SE(2): ``[e_x, e_y, 0, 0, 0, e_θ]``), so ``‖ω‖`` is the rotation angle;
* :meth:`PoseGroup.parameters` (metricEvaluator mode): ``[x, y, z, roll, pitch, yaw]``
  (SE(2): ``[x, y, 0, 0, 0, θ]``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from relation_metric import se2, se3
from relation_metric.arrays import Array

__all__ = ["PoseGroup", "SE2", "SE3", "group_of", "common_group"]


class PoseGroup:
    """A pose group: width of a pose row, its algebra, and the conversions the metric uses."""

    name = ""
    width = 0
    """Numbers per pose row (3 or 7)."""
    dof = 0
    """Degrees of freedom (3 or 6)."""
    position_dim = 0
    """Coordinates of a position (2 or 3)."""
    _alg: Any = None

    def __repr__(self) -> str:
        return self.name

    def compose(self, a: ArrayLike, b: ArrayLike) -> Array:
        """``a ∘ b``."""
        return self._alg.compose(a, b)

    def inverse(self, a: ArrayLike) -> Array:
        """``a⁻¹``."""
        return self._alg.inverse(a)

    def between(self, a: ArrayLike, b: ArrayLike) -> Array:
        """``a⁻¹ ∘ b`` (the relation ``δ_ij`` from ``a = x_i`` to ``b = x_j``)."""
        return self._alg.between(a, b)

    def ominus(self, a: ArrayLike, b: ArrayLike) -> Array:
        """``b⁻¹ ∘ a``: the error of ``a`` with respect to ``b``."""
        return self._alg.ominus(a, b)

    def exp(self, xi: ArrayLike) -> Array:
        """Exponential map, tangent ``(..., dof)`` → poses ``(..., width)``."""
        return self._alg.exp(xi)

    def log(self, p: ArrayLike) -> Array:
        """Logarithm map, poses ``(..., width)`` → tangent ``(..., dof)``."""
        return self._alg.log(p)

    def interpolate(self, a: ArrayLike, b: ArrayLike, s: ArrayLike) -> Array:
        """``a ∘ exp(s · log(a⁻¹ ∘ b))`` (constant-twist motion), ``s`` of shape (...)."""
        s = np.asarray(s, dtype=np.float64)[..., None]
        return self.compose(a, self.exp(s * self.log(self.between(a, b))))

    def identity(self, shape: tuple[int, ...] = ()) -> Array:
        """Identity poses, shape ``shape + (width,)``."""
        raise NotImplementedError

    def normalize(self, p: ArrayLike) -> Array:
        """The stored form of poses (SE(2): angle wrapped; SE(3): unit quaternion, qw ≥ 0)."""
        raise NotImplementedError

    def positions(self, p: ArrayLike) -> Array:
        """Positions ``(..., position_dim)``."""
        return np.asarray(p, dtype=np.float64)[..., : self.position_dim]

    def error_components(self, e: ArrayLike) -> Array:
        """``[e_x, e_y, e_z, ω_x, ω_y, ω_z]`` of group errors ``e`` (..., width) → (..., 6)."""
        raise NotImplementedError

    def parameters(self, d: ArrayLike) -> Array:
        """``[x, y, z, roll, pitch, yaw]`` of poses/relations (..., width) → (..., 6)."""
        raise NotImplementedError

    def translation_norm(self, e: ArrayLike) -> Array:
        """``‖t(e)‖``, shape (...)."""
        return np.linalg.norm(self.positions(e), axis=-1)

    def rotation_angle(self, e: ArrayLike) -> Array:
        """Rotation angle of ``e`` in ``[0, π]``, shape (...)."""
        raise NotImplementedError

    def to_se3(self, p: ArrayLike) -> Array:
        """The same poses as SE(3) rows ``(..., 7)``."""
        raise NotImplementedError


class _SE2(PoseGroup):
    name = "SE2"
    width = 3
    dof = 3
    position_dim = 2
    _alg = se2

    def identity(self, shape: tuple[int, ...] = ()) -> Array:
        return np.zeros(shape + (3,))

    def normalize(self, p: ArrayLike) -> Array:
        return se2.wrap_last(np.asarray(p, dtype=np.float64))

    def error_components(self, e: ArrayLike) -> Array:
        e = np.asarray(e, dtype=np.float64)
        out = np.zeros(e.shape[:-1] + (6,))
        out[..., 0:2] = e[..., 0:2]
        out[..., 5] = se2.wrap_angle(e[..., 2])
        return out

    def parameters(self, d: ArrayLike) -> Array:
        # SE(2): the parameters are the error components (x, y, 0, 0, 0, yaw).
        return self.error_components(d)

    def rotation_angle(self, e: ArrayLike) -> Array:
        return np.abs(se2.wrap_angle(np.asarray(e, dtype=np.float64)[..., 2]))

    def to_se3(self, p: ArrayLike) -> Array:
        return se3.from_planar(p)


class _SE3(PoseGroup):
    name = "SE3"
    width = 7
    dof = 6
    position_dim = 3
    _alg = se3

    def identity(self, shape: tuple[int, ...] = ()) -> Array:
        return se3.identity(shape)

    def normalize(self, p: ArrayLike) -> Array:
        return se3.normalize(p)

    def error_components(self, e: ArrayLike) -> Array:
        e = np.asarray(e, dtype=np.float64)
        out = np.empty(e.shape[:-1] + (6,))
        out[..., 0:3] = e[..., 0:3]
        out[..., 3:6] = se3.rotation_vector(e[..., 3:7])
        return out

    def parameters(self, d: ArrayLike) -> Array:
        d = np.asarray(d, dtype=np.float64)
        out = np.empty(d.shape[:-1] + (6,))
        out[..., 0:3] = d[..., 0:3]
        out[..., 3:6] = se3.euler_zyx(d[..., 3:7])
        return out

    def rotation_angle(self, e: ArrayLike) -> Array:
        return se3.rotation_angle(np.asarray(e, dtype=np.float64)[..., 3:7])

    def to_se3(self, p: ArrayLike) -> Array:
        return np.asarray(p, dtype=np.float64)


SE2: PoseGroup = _SE2()
SE3: PoseGroup = _SE3()
_BY_WIDTH = {3: SE2, 7: SE3}


def group_of(poses: ArrayLike) -> PoseGroup:
    """The group of a pose array by its last axis: 3 → :data:`SE2`, 7 → :data:`SE3`."""
    width = np.shape(poses)[-1] if np.ndim(poses) else 0
    try:
        return _BY_WIDTH[width]
    except KeyError:
        raise ValueError(
            f"poses must have 3 ([x, y, θ]) or 7 ([x, y, z, qx, qy, qz, qw]) columns, "
            f"got shape {np.shape(poses)}"
        ) from None


def common_group(*groups: PoseGroup | None) -> PoseGroup:
    """SE(3) if any of ``groups`` is SE(3), else SE(2) (planar data lifts, never projects)."""
    return SE3 if any(g is SE3 for g in groups) else SE2
