"""Relation errors (Kümmerle et al. 2009) in two definitions.

``paper`` (default) — the paper's Eq. 2: the error of a relation is the SE(2) difference
``e_ij = δ_ij ⊖ δ*_ij = δ*_ij⁻¹ ∘ δ_ij`` (in the frame of the reference relation's end pose),
with ``δ_ij = x_i⁻¹ ∘ x_j`` of the estimate; translational part ``trans(e) = ‖[e_x, e_y]‖``,
rotational part ``rot(e) = |e_θ|``, ``e_θ`` wrapped to ``[−π, π)``. ε = 1/N Σ trans² + rot²
is the sum of the two ``sqr`` means.

``metricevaluator`` — the definition of the authors' C++ tool: the difference of the
parameter vectors ``p(δ) − p(δ*)`` with ``p = [x, y, z, roll, pitch, yaw]`` (angles of the
difference wrapped), weighted, ``sqrt(Σ_k w_k e_k²)`` (or its square). For a planar estimate
``z = roll = pitch = 0``; the reference's out-of-plane parts enter as they are.

How they differ: in SE(2) ``trans(δ ⊖ δ*) = ‖R*ᵀ (t − t*)‖ = ‖t − t*‖`` because rotation
keeps lengths, and the angle difference is the same, so on planar data both definitions give
the same translational and rotational errors. They differ (i) when weights mix translation and
rotation into one number (the C++ tool's single weighted error), (ii) for relations with
out-of-plane parts, where the parameter-vector difference is not a group error, and (iii) for
per-axis weights (``wx ≠ wy``): the paper's components are in the reference frame, the C++
tool's in the frame of the first pose of the estimate.

On SE(3) (relations as ``(M, 7)`` ``[x, y, z, qx, qy, qz, qw]``, see
:mod:`relation_metric.groups`) the same two definitions hold: ``paper`` takes
``e = δ*⁻¹ ∘ δ`` on SE(3), whose translation ``[e_x, e_y, e_z]`` and rotation vector
``ω = θ n`` are the six components (``‖ω‖`` is the rotation angle of ``e``; with unit weights
the translational and rotational errors are evo's RPE ``translation_part`` and
``rotation_angle``); ``metricevaluator`` takes the difference of the ZYX parameter vectors
``[x, y, z, roll, pitch, yaw]`` (angles wrapped). One array is lifted to SE(3) when the
other is 3-D.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.constants import MODES
from relation_metric.errors import InputError
from relation_metric.groups import SE2, common_group, group_of

__all__ = ["RelationErrors", "relation_errors", "MODES", "parse_weights"]

Mode = Literal["paper", "metricevaluator"]
_UNIT_WEIGHTS = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)


@dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors.

    Attributes
    ----------
    translation : ndarray, shape (M,)
        Absolute translational error, metres: ``sqrt(wx e_x² + wy e_y² + wz e_z²)``.
    rotation : ndarray, shape (M,)
        Absolute rotational error, radians: ``sqrt(w_roll e_r² + w_pitch e_p² + w_yaw e_θ²)``.
    combined : ndarray, shape (M,)
        ``sqrt(translation² + rotation²)``: the single weighted number the C++
        metricEvaluator prints (with its ``-w`` weights).
    vector : ndarray, shape (M, 6)
        The unweighted error components ``[e_x, e_y, e_z, e_roll, e_pitch, e_yaw]``.
    mode : str
    weights : tuple of 6 floats
    """

    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    combined: NDArray[np.float64]
    _components: NDArray[np.float64] = field(repr=False, compare=False)
    """``vector``, or for planar errors only ``[e_x, e_y, e_yaw]`` (M, 3): the (M, 6) array is
    built on first use, not on the hot path."""
    mode: str
    weights: tuple[float, ...]

    @cached_property
    def vector(self) -> NDArray[np.float64]:
        """The unweighted components ``[e_x, e_y, e_z, e_roll, e_pitch, e_yaw]``, (M, 6)."""
        c = self._components
        if c.shape[1] == 6:
            return c
        vec = np.zeros((c.shape[0], 6))
        vec[:, 0:2] = c[:, 0:2]
        vec[:, 5] = c[:, 2]
        return vec


def parse_weights(text: str | ArrayLike | None) -> tuple[float, ...]:
    """Weights ``{wx,wy,wz,wroll,wpitch,wyaw}`` from ``"1,1,0,0,0,0"`` (braces optional)."""
    if text is None:
        return _UNIT_WEIGHTS
    if isinstance(text, str):
        parts = [p for p in text.strip().strip("{}").replace(",", " ").split() if p]
        try:
            values = tuple(float(p) for p in parts)
        except ValueError:
            raise InputError(
                f"weights {text!r}: expected six numbers wx,wy,wz,wroll,wpitch,wyaw"
            ) from None
    else:
        values = tuple(float(v) for v in np.asarray(text, dtype=np.float64).ravel())
    if len(values) != 6 or not all(np.isfinite(values)) or min(values) < 0:
        raise InputError(
            f"weights {text!r}: expected six finite non-negative numbers wx,wy,wz,wroll,wpitch,wyaw"
        )
    return values


def relation_errors(
    estimated: ArrayLike,
    reference: ArrayLike,
    *,
    mode: Mode = "paper",
    weights: ArrayLike | str | None = None,
    out_of_plane: ArrayLike | None = None,
) -> RelationErrors:
    """Errors of estimated relations against reference relations.

    Parameters
    ----------
    estimated : array_like, shape (M, 3) or (M, 7)
        ``δ_ij = x_i⁻¹ ∘ x_j`` of the estimate (SE(2) or SE(3) rows).
    reference : array_like, shape (M, 3) or (M, 7)
        ``δ*_ij``.
    mode : {"paper", "metricevaluator"}
        See the module docstring.
    weights : six floats or str, optional
        ``{wx, wy, wz, wroll, wpitch, wyaw}``; all ones by default.
    out_of_plane : array_like, shape (M, 3), optional
        SE(2) only: ``[z, roll, pitch]`` of the reference relations (``metricevaluator``
        mode only; in ``paper`` mode they must be zero, since a planar group error cannot
        hold them — lift such relations to SE(3) instead).

    Returns
    -------
    RelationErrors
    """
    d = np.asarray(estimated, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    ok = d.ndim == 2 and r.ndim == 2 and d.shape[0] == r.shape[0]
    if not ok or d.shape[1] not in (3, 7) or r.shape[1] not in (3, 7):
        raise InputError(
            f"relation arrays must both be (M, 3) or (M, 7); got {d.shape} and {r.shape}"
        )
    group = common_group(group_of(d), group_of(r))
    d = d if d.shape[1] == group.width else group.to_se3(d)
    r = r if r.shape[1] == group.width else group.to_se3(r)
    w = np.asarray(parse_weights(weights))
    oop = None if out_of_plane is None else np.asarray(out_of_plane, dtype=np.float64)
    if oop is not None and group is not SE2:
        if np.any(oop != 0.0):
            raise InputError("SE(3) relations hold z, roll and pitch in delta, not out_of_plane")
        oop = None
    if mode == "paper":
        if oop is not None and np.any(oop != 0.0):
            raise InputError(
                "relations with out-of-plane parts (z, roll, pitch) cannot be scored with "
                "the planar paper definition; lift them to SE(3) (RelationSet.lifted) or use "
                "mode 'metricevaluator'"
            )
        if group is SE2:
            return _weighted_planar(se2.ominus(d, r), w, mode)
        vec = group.error_components(group.ominus(d, r))
    elif mode == "metricevaluator" and group is SE2 and oop is None:
        diff = d - r
        diff[:, 2] = se2.wrap_angle(d[:, 2]) - se2.wrap_angle(r[:, 2])
        return _weighted_planar(diff, w, mode)
    elif mode == "metricevaluator":
        vec = group.parameters(d) - group.parameters(r)
        if oop is not None:
            vec[:, 2:5] -= oop
        vec[:, 3:6] = se2.wrap_angle(vec[:, 3:6])
    else:
        raise InputError(f"unknown mode {mode!r}; expected one of {', '.join(MODES)}")
    return _weighted(vec, w, mode)


def _weighted_planar(e: NDArray[np.float64], w: NDArray[np.float64], mode: str) -> RelationErrors:
    """:func:`_weighted` of ``[e_x, e_y, 0, 0, 0, wrap(e_θ)]`` from ``e`` (M, 3), same bits.

    ``e`` must be a fresh array (its angle column is wrapped in place and it is kept).

    The three zero components add exact zeros to the sums, so they are left out of them;
    the (M, 6) ``vector`` is built only when asked for.
    """
    ex, ey = e[:, 0], e[:, 1]
    eth = se2.wrap_angle(e[:, 2])
    e[:, 2] = eth  # e is the caller's scratch array: it becomes the stored components
    return _from_squares(ex * ex * w[0] + ey * ey * w[1], eth * eth * w[5], e, w, mode)


def _weighted(vec: NDArray[np.float64], w: NDArray[np.float64], mode: str) -> RelationErrors:
    sq = vec * vec * w
    return _from_squares(sq[:, 0:3].sum(axis=1), sq[:, 3:6].sum(axis=1), vec, w, mode)


def _from_squares(
    trans2: NDArray[np.float64],
    rot2: NDArray[np.float64],
    components: NDArray[np.float64],
    w: NDArray[np.float64],
    mode: str,
) -> RelationErrors:
    """The errors from the weighted squared translational and rotational parts, (M,) each."""
    return RelationErrors(
        translation=np.sqrt(trans2),
        rotation=np.sqrt(rot2),
        combined=np.sqrt(trans2 + rot2),
        _components=components,
        mode=mode,
        weights=tuple(float(x) for x in w),
    )
