"""The relation metric as one run function: relations + estimate → :class:`Evaluation`.

No I/O here (readers live in :mod:`slamrel.formats.trajectories` and
:mod:`relation_metric.relations`, writers in :mod:`slamrel.formats.results`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import AssociationError, InputError
from relation_metric.groups import SE3
from relation_metric.metric import Mode, RelationErrors, relation_errors
from relation_metric.relations import RelationSet
from relation_metric.stats import ErrorStats, summarize_with_squares
from relation_metric.time_association import REASONS, SAME_POSE, Association, associate
from relation_metric.trajectory import Trajectory

__all__ = [
    "Evaluation",
    "PoseErrors",
    "evaluate",
    "pose_errors",
    "UnassociatedRelationsWarning",
    "SamePoseWarning",
    "error_summaries",
    "on_common_group",
]


class UnassociatedRelationsWarning(UserWarning):
    """Some relations could not be associated and were left out of the statistics."""


class SamePoseWarning(UserWarning):
    """Some relations had both ends at one estimate pose and were scored as zero motion
    (``mode="metricevaluator"``, as the C++ metricEvaluator scores them)."""


@dataclass(frozen=True)
class Evaluation:
    """Result of :func:`evaluate`.

    Attributes
    ----------
    relations : RelationSet
        All reference relations given.
    association : Association
        Estimate poses of both ends of every relation.
    errors : RelationErrors
        Per-relation errors over all relations (NaN where unassociated).
    translation, rotation, combined : ErrorStats
        Statistics over the associated relations (``.abs``, ``.sqr``); rotation in radians.
    """

    relations: RelationSet
    association: Association
    errors: RelationErrors
    translation: ErrorStats
    rotation: ErrorStats
    combined: ErrorStats

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Mask of the relations that were scored, shape (M,)."""
        return self.association.valid

    @property
    def epsilon(self) -> float:
        """Kümmerle et al. Eq. 2: ε = 1/N Σ trans(e)² + rot(e)² (m² + rad²)."""
        return self.translation.sqr.mean + self.rotation.sqr.mean

    def as_dict(self, *, degrees: bool = False) -> dict[str, Any]:
        """The JSON structure of ``slamrel evaluate --json`` (NaN written as ``null``)."""
        if degrees:
            rot = error_summaries(np.degrees(self.errors.rotation[self.valid]))
        else:
            rot = self.rotation
        return {
            "relations": len(self.relations),
            "associated_by_odometry": int(self.association.via_odometry.sum()),
            "interpolated": int(self.association.interpolated.sum()),
            "unassociated": int((~self.valid).sum()),
            "same_estimate_pose": self._same_pose_dict(),
            "rotation_unit": "deg" if degrees else "rad",
            "mode": self.errors.mode,
            "weights": list(self.errors.weights),
            "translation": self.translation.as_dict(),
            "rotation": rot.as_dict(),
            "combined": self.combined.as_dict(),
            "epsilon": _json_float(self.epsilon),
        }

    def _same_pose_dict(self) -> dict[str, Any]:
        """Relations whose two times found one estimate pose, and what was done with them."""
        a = self.association
        same = a.same_pose if a.same_pose is not None else np.zeros(len(self.relations), bool)
        count = int(np.count_nonzero(same))
        if self.errors.mode == "metricevaluator":
            return {
                "count": count,
                "interpolated": 0,
                "unassociated": 0,
                "zero_motion": count,
                "rule": "scored as zero estimated motion, as the C++ metricEvaluator scores "
                "them (mode metricevaluator)",
            }
        interpolated = int(np.count_nonzero(same & a.interpolated))
        return {
            "count": count,
            "interpolated": interpolated,
            "unassociated": int(np.count_nonzero(same & ~a.valid)),
            "rule": "both ends interpolated (interpolate=True) where the poses around them allow, "
            "otherwise unassociated; never scored as zero motion",
        }


@dataclass(frozen=True)
class PoseErrors:
    """The errors of an evaluation gathered at the estimate's poses (:func:`pose_errors`).

    Attributes
    ----------
    index : ndarray of int64, shape (K,)
        The estimate poses at least one scored relation ends at (nearest pose), ascending.
    mean : ndarray, shape (K,)
        Mean error of the scored relations with an end at each of them.
    relations : ndarray of int64, shape (K,)
        How many scored relation ends lie there (a relation with both ends at one pose counts
        twice).
    """

    index: NDArray[np.int64]
    mean: NDArray[np.float64]
    relations: NDArray[np.int64]

    def quantile(self, q: float) -> float:
        """The ``q`` quantile of ``mean`` (NaN when no pose is touched)."""
        return float(np.quantile(self.mean, q)) if self.mean.size else math.nan


def pose_errors(evaluation: Evaluation, n: int, *, part: str = "translation") -> PoseErrors:
    """Per estimate pose (of ``n``), the mean ``part`` error (``"translation"`` [m] or
    ``"rotation"`` [rad]) of the scored relations that have an end there: where along the
    trajectory the errors of one relation set are."""
    if part not in ("translation", "rotation"):
        raise InputError(f"part must be 'translation' or 'rotation', got {part!r}")
    ev = evaluation
    valid = ev.valid
    a = ev.association
    err = getattr(ev.errors, part)[valid]
    idx = np.concatenate((a.index_first[valid], a.index_second[valid]))
    total = np.bincount(idx, weights=np.concatenate((err, err)), minlength=n)
    count = np.bincount(idx, minlength=n)
    touched = np.flatnonzero(count)
    return PoseErrors(touched.astype(np.int64), total[touched] / count[touched], count[touched])


def _json_float(x: float) -> float | None:
    return x if math.isfinite(x) else None


def error_summaries(values: ArrayLike) -> ErrorStats:
    """``ErrorStats(abs=summarize(|e|), sqr=summarize(e²))`` of non-negative errors ``e``."""
    return ErrorStats(*summarize_with_squares(values))


def evaluate(
    relations: RelationSet,
    estimate: Trajectory,
    *,
    odometry: Trajectory | None = None,
    mode: Mode = "paper",
    weights: ArrayLike | str | None = None,
    max_time_diff: float = 0.1,
    interpolate: bool = False,
    max_interpolation_gap: float = 1.0,
    strict: bool = False,
    estimate_name: str | None = None,
    relations_name: str | None = None,
    allow_empty: bool = False,
) -> Evaluation:
    """Score an estimate with the relation metric (Kümmerle et al. 2009).

    Parameters
    ----------
    relations : RelationSet
        Reference relations ``(first, second, δ*)``.
    estimate : Trajectory
        The evaluated trajectory.
    odometry, max_time_diff, interpolate, max_interpolation_gap :
        Timestamp association, see :func:`relation_metric.time_association.associate`.
    mode, weights :
        Error definition, see :func:`relation_metric.metric.relation_errors`. The
        ``metricevaluator`` mode also associates as the C++ tool does: a relation whose two
        times find one estimate pose is scored as zero estimated motion (counted, and said in
        a :class:`SamePoseWarning`), where the ``paper`` mode interpolates or leaves it out.
    strict : bool
        Raise :class:`AssociationError` when any relation is unassociated (otherwise they
        are excluded, counted and named in an :class:`UnassociatedRelationsWarning`).
    estimate_name, relations_name : str, optional
        Where the estimate and the relations come from (file names), for messages.
    allow_empty : bool
        Score an empty ``relations`` as an :class:`Evaluation` of no relations (count 0, every
        statistic NaN) instead of raising: for callers that report an empty set as such
        (``slamrel run``'s per-set tables). By default no relations is an error.

    Returns
    -------
    Evaluation

    Raises
    ------
    AssociationError
        When no relation can be associated (the message shows both time spans), or with
        ``strict`` when any cannot.
    InputError
        When ``relations`` is empty (without ``allow_empty``): the statistics of no relation
        would be NaN, not a score.
        When the estimate has two different poses for one timestamp (relations by time);
        when the errors overflow float64 (coordinates near 1e150 and beyond): such poses
        cannot be scored, and statistics of ``inf`` would be no score either.
    """
    of_relations = f" of {relations_name}" if relations_name else ""
    if len(relations) == 0 and not allow_empty:
        raise InputError(
            f"no relations to score{of_relations}: the relation set is empty; expected at "
            "least one relation (the statistics of none would be NaN, not a score)",
            path=relations_name,
        )
    relations, estimate = on_common_group(relations, estimate, mode=mode)
    if relations.key == "time":
        _refuse_two_poses_at_one_time(estimate, estimate_name)
    with np.errstate(over="ignore", invalid="ignore"):
        assoc = associate(
            relations,
            estimate,
            odometry=odometry,
            max_time_diff=max_time_diff,
            interpolate=interpolate,
            max_interpolation_gap=max_interpolation_gap,
            same_pose="zero_motion" if mode == "metricevaluator" else "separate",
        )
    if mode == "metricevaluator" and assoc.same_pose is not None and assoc.same_pose.any():
        where = f"{estimate_name}: " if estimate_name else ""
        warnings.warn(
            f"{where}{int(assoc.same_pose.sum())} of {len(relations)} relations{of_relations} "
            "have both ends at one estimate pose and are scored as zero estimated motion, as "
            "the C++ metricEvaluator scores them (the default mode interpolates or leaves "
            "them out)",
            SamePoseWarning,
            stacklevel=2,
        )
    valid = assoc.valid
    n_bad = int((~valid).sum())
    if len(relations) and n_bad == len(relations):
        r0, r1 = relations.span()
        e0, e1 = estimate.span()
        unit = "s" if relations.key == "time" else "(pose index)"
        raise AssociationError(
            f"none of the {len(relations)} relations{of_relations} can be associated with the "
            f"estimate: the relations span {r0:.6f} .. {r1:.6f} {unit}, the estimate "
            f"{e0:.6f} .. {e1:.6f} s ({len(estimate)} poses); " + _why_none(assoc),
            path=estimate_name,
        )
    if n_bad:
        message = _describe_unassociated(relations, assoc, max_time_diff, of_relations)
        if strict:
            raise AssociationError(message + " (strict=True)", path=estimate_name)
        where = f"{estimate_name}: " if estimate_name else ""
        warnings.warn(where + message, UnassociatedRelationsWarning, stacklevel=2)
    with np.errstate(over="ignore", invalid="ignore"):
        errors = relation_errors(
            assoc.estimated_delta,
            relations.delta,
            mode=mode,
            weights=weights,
            out_of_plane=relations.out_of_plane,
        )
    _check_representable(errors, valid, relations, estimate_name)

    def scored(part: NDArray[np.float64]) -> NDArray[np.float64]:
        return part if n_bad == 0 else part[valid]

    return Evaluation(
        relations=relations,
        association=assoc,
        errors=errors,
        translation=error_summaries(scored(errors.translation)),
        rotation=error_summaries(scored(errors.rotation)),
        combined=error_summaries(scored(errors.combined)),
    )


def _refuse_two_poses_at_one_time(estimate: Trajectory, name: str | None) -> None:
    """Two different estimate poses for one timestamp: the association would pick one."""
    from relation_metric.timeorder import repeated_times

    _, rep = repeated_times(estimate.timestamps, estimate.poses)
    if rep.differing:
        raise InputError(
            f"the estimate has {rep.differing} timestamp(s) with two different poses (first "
            f"at t = {rep.time:.9g} s); expected one pose per timestamp (the nearest-time "
            "association would take whichever comes first)",
            path=name,
        )


def on_common_group(
    relations: RelationSet, estimate: Trajectory, *, mode: str = "paper"
) -> tuple[RelationSet, Trajectory]:
    """Relations and estimate on one group: planar data is lifted to SE(3), never projected.

    SE(3) when the estimate is 3-D, when the relations are, or when SE(2) relations carry
    out-of-plane parts (Freiburg 6-DoF lines) in ``paper`` mode (the ``metricevaluator``
    mode scores those with the parameter-vector difference on SE(2), as the C++ tool does).
    Projecting 3-D data onto the plane is the caller's explicit choice
    (:meth:`Trajectory.planar`, ``--planar``).
    """
    three_d = (
        estimate.group is SE3
        or relations.group is SE3
        or (relations.has_out_of_plane and mode == "paper")
    )
    if three_d:
        return relations.lifted(), estimate.lifted()
    return relations, estimate


def _check_representable(
    errors: RelationErrors, valid: NDArray[np.bool_], relations: RelationSet, name: str | None
) -> None:
    """Refuse errors whose squares (hence ε and the rmse) overflow float64."""
    limit = 1e150  # (1e150)² · 1e6 relations stays below float64's 1.8e308
    for part in (errors.translation, errors.rotation, errors.combined):
        if part.size and np.abs(part).max() < limit:  # NaN (unassociated or not) fails here
            continue
        v = part[valid]
        bad = np.flatnonzero(~(np.abs(v) < limit))
        if bad.size:
            k = int(np.flatnonzero(valid)[bad[0]])
            raise InputError(
                f"relation #{k} ({float(relations.first[k]):.6f} -> "
                f"{float(relations.second[k]):.6f}) has an error of {float(part[k]):.3g}, "
                f"beyond what float64 statistics can hold (|error| < {limit:.0e}); "
                "are the coordinates in metres?",
                path=name,
            )


def _why_none(assoc: Association) -> str:
    """The reasons no relation could be associated, most frequent first."""
    codes, counts = np.unique(assoc.reason, return_counts=True)
    parts = [f"{n} {REASONS[int(c)]}" for c, n in sorted(zip(codes, counts), key=lambda x: -x[1])]
    hint = ""
    if (assoc.reason == SAME_POSE).all():
        hint = "; pass interpolate=True to score them between the estimate's poses"
    elif not (assoc.reason == SAME_POSE).any():
        hint = "; are they in the same time base?"
    return "reasons: " + ", ".join(parts) + hint


def _describe_unassociated(
    relations: RelationSet, assoc: Association, tol: float, of_relations: str = ""
) -> str:
    bad = np.flatnonzero(~assoc.valid)
    parts = []
    for k in bad[:5]:
        parts.append(
            f"#{k} ({relations.first[k]:.6f} -> {relations.second[k]:.6f}: "
            f"{REASONS[int(assoc.reason[k])]})"
        )
    more = "" if bad.size <= 5 else f" and {bad.size - 5} more"
    return (
        f"{bad.size} of {len(relations)} relations{of_relations} could not be associated "
        f"(tolerance {tol:g} s) "
        f"and are left out of the statistics: {', '.join(parts)}{more}"
    )
