"""Compare an estimated landmark map with a reference map: one run function, no I/O.

The frame rule
--------------
Whatever the association's source (by id, automatic, or a user's file), the estimate is
moved onto the reference by the SE(2) least-squares fit on the associated pairs before
OSPA/GOSPA are computed and before anything is drawn: with ``K`` pairs ``(e_k, r_k)``,

    (R(dθ), [dx, dy]) = argmin Σ_k ‖r_k − (R e_k + d)‖²     (Umeyama 1991, closed form,
                                                             :func:`relation_metric.alignment.umeyama`)

for ``K ≥ 2``, the translation ``r − e`` of the one pair for ``K = 1``. The transform is the
reference ← estimate one: an estimated point ``e`` is ``R(dθ) e + [dx, dy]`` in the
reference frame (the convention of :class:`recovery.anchoring.Anchoring`, which the run's
report fits on the same pairs). The same pairs therefore give the same numbers under every
source. An unaligned comparison (the maps as given) is made only on request
(``align=False``); the fit is still reported. The mesh errors (edge lengths, corner angles,
displacements in local or fitted frames) do not depend on the frame at all.

Association choice
------------------
``associate`` is ``"id-or-auto"`` (the default), ``"id"``, ``"auto"`` or a ready
:class:`~landmark_graph.landmark_association.Association` (from a file). ``"id-or-auto"``
takes the pairs of equal ids when at least 2 ids are shared and more than half of those
pairs lie within the cut-off ``c`` of each other after the fit on them, or, when not, the
pairs keep the map's local shape (the distances to nearest paired neighbours agree to a
median :data:`SHAPE_TOLERANCE`: a large map bent by drift, e.g. Victoria Park's); otherwise
(ids that differ, or coincide by accident — a SLAM run's own ``0 … N−1``) it associates
automatically (:func:`~landmark_graph.landmark_association.associate_auto`) and says why
(``notes``). By
id or from a file, pairs mostly farther apart than ``c`` after the fit raise an
:class:`AssociationWarning` (kept as a caution) that suggests the automatic association.

Observable landmarks
--------------------
``observable`` marks the reference landmarks that were ever within the sensor's reach of the
true trajectory (:func:`landmark_graph.observability.within_reach`). A reference landmark is
*unobserved* when it is neither observable nor matched (a matched landmark was evidently
seen), *missed* when observable and unmatched. OSPA and GOSPA are computed on the observable
reference landmarks (observable or matched); the values on all reference landmarks are
reported beside them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.constants import ASSOCIATE_MODES, DEFAULT_ASSOCIATE
from landmark_graph.landmark_association import (
    Association,
    NoPairsFound,
    associate_auto,
    associate_by_id,
)
from landmark_graph.maps import LandmarkMap
from landmark_graph.mesh import Mesh, delaunay_mesh
from landmark_graph.mesh_relations import MeshErrors, mesh_errors
from landmark_graph.observability import SensorReach
from landmark_graph.set_distances import gospa, ospa
from relation_metric import se2
from relation_metric.alignment import Alignment, umeyama
from relation_metric.errors import InputError
from relation_metric.evaluate import error_summaries

__all__ = [
    "ASSOCIATE_MODES",
    "DEFAULT_ASSOCIATE",
    "AssociationChoice",
    "AssociationWarning",
    "MapAlignment",
    "MapComparison",
    "SOURCE_WORDS",
    "choose_association",
    "compare_maps",
    "fit_map_alignment",
]


class AssociationWarning(UserWarning):
    """Associated pairs that are mostly farther apart than the cut-off after the alignment."""


@dataclass(frozen=True)
class MapAlignment:
    """The reference ← estimate rigid transform of the frame rule (module docstring).

    Attributes
    ----------
    dx, dy : float
        Translation [m]: the estimate's origin in the reference frame.
    dtheta : float
        Rotation [rad] in ``[−π, π)``: ``e ↦ R(dθ) e + [dx, dy]``.
    pairs : int
        Associated pairs the transform was fitted on.
    rms_residual : float
        ``√(1/K Σ ‖r_k − (R e_k + d)‖²)`` [m] after the fit.
    method : str
        ``"SE(2) least squares"`` (K ≥ 2), ``"translation of the one pair"`` or ``"none"``
        (no pairs: the identity).
    applied : bool
        Whether the comparison moved the estimate by it (``False`` only on request).
    """

    dx: float
    dy: float
    dtheta: float
    pairs: int
    rms_residual: float
    method: str
    applied: bool = True

    @property
    def alignment(self) -> Alignment:
        """As a :class:`~relation_metric.alignment.Alignment` (scale 1)."""
        return Alignment(self.dtheta, np.array([self.dx, self.dy]), 1.0)

    def apply(self, xy: ArrayLike) -> NDArray[np.float64]:
        """Points ``(N, 2)`` of the estimate's frame in the reference frame."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return self.alignment.apply(np.column_stack((p, np.zeros(p.shape[0]))))[:, :2]

    @property
    def description(self) -> str:
        """The frame in words, e.g. ``"estimate moved onto the reference by the SE(2) least-
        squares fit on 15 associated pairs"``."""
        if not self.applied:
            return "as given (no alignment, on request)"
        if self.pairs >= 2:
            return (
                f"estimate moved onto the reference by the SE(2) least-squares fit on "
                f"{self.pairs} associated pairs"
            )
        if self.pairs == 1:
            return "estimate moved onto the reference by the translation of the one pair"
        return "as given (no pairs to align on)"

    def as_dict(self) -> dict[str, Any]:
        """The JSON ``alignment`` (``dtheta`` in rad, also in degrees)."""
        return {
            "applied": self.applied,
            "dx": self.dx,
            "dy": self.dy,
            "dtheta": self.dtheta,
            "dtheta_deg": float(np.degrees(self.dtheta)),
            "pairs": self.pairs,
            "rms_residual": self.rms_residual,
            "method": self.method,
            "convention": "reference = R(dtheta) estimate + [dx, dy]",
        }


def fit_map_alignment(estimate_xy: ArrayLike, reference_xy: ArrayLike) -> MapAlignment:
    """The frame rule's transform of ``K`` associated pairs, rows of ``(K, 2)`` each.

    ``K ≥ 2``: Umeyama's SE(2) least squares; ``K = 1``: the translation of the pair;
    ``K = 0``: the identity.
    """
    e = np.asarray(estimate_xy, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(reference_xy, dtype=np.float64).reshape(-1, 2)
    if e.shape != r.shape:
        raise InputError(f"alignment needs pairs of equal shape, got {e.shape} and {r.shape}")
    k = e.shape[0]
    if k >= 2:
        al, method = umeyama(e, r), "SE(2) least squares"
    elif k == 1:
        al, method = Alignment(0.0, r[0] - e[0], 1.0), "translation of the one pair"
    else:
        al, method = Alignment(0.0, np.zeros(2), 1.0), "none"
    res = r - al.apply(np.column_stack((e, np.zeros(k))))[:, :2]
    rms = float(np.sqrt(np.mean(np.sum(res * res, axis=1)))) if k else 0.0
    return MapAlignment(
        dx=float(al.translation[0]),
        dy=float(al.translation[1]),
        dtheta=float(se2.wrap_angle(al.angle)),
        pairs=int(k),
        rms_residual=rms,
        method=method,
    )


def _pairs_within(
    estimate: LandmarkMap, reference: LandmarkMap, assoc: Association, cutoff: float
) -> int:
    """How many of the association's pairs lie within ``cutoff`` after the fit on them."""
    e, r = estimate.xy[assoc.estimate_rows], reference.xy[assoc.reference_rows]
    moved = fit_map_alignment(e, r).apply(e)
    return int((np.hypot(*(moved - r).T) <= cutoff).sum())


#: Largest median relative error of the distances from each paired landmark to its nearest
#: paired neighbour (:func:`_local_shape_error`) at which pairs are taken as the same
#: landmarks even when a rigid fit leaves most of them beyond ``c``: a large map bent by its
#: drift keeps its local shape; ids that coincide by accident pair unrelated landmarks,
#: whose local distances differ by the order of themselves (median ≈ 0.5 and more).
SHAPE_TOLERANCE = 0.25


def _local_shape_error(estimate: LandmarkMap, reference: LandmarkMap, assoc: Association) -> float:
    """Median over the pairs of ``|d̂ − d| / d``: ``d`` the distance from a paired reference
    landmark to its nearest paired neighbour, ``d̂`` the distance between their partners in
    the estimate (frame-free). ``inf`` for fewer than 2 pairs."""
    from scipy.spatial import cKDTree

    e, r = estimate.xy[assoc.estimate_rows], reference.xy[assoc.reference_rows]
    if r.shape[0] < 2:
        return float("inf")
    d, j = cKDTree(r).query(r, k=2)
    d_ref, nb = d[:, 1], j[:, 1]
    ok = d_ref > 0
    if not ok.any():
        return float("inf")
    d_est = np.hypot(*(e[ok] - e[nb[ok]]).T)
    return float(np.median(np.abs(d_est - d_ref[ok]) / d_ref[ok]))


#: ``source`` of an association in words.
SOURCE_WORDS = {"id": "by id", "auto": "automatically", "file": "from a file"}


@dataclass(frozen=True)
class AssociationChoice:
    """What :func:`choose_association` chose.

    Attributes
    ----------
    association : Association
    source : str
        ``"id"``, ``"auto"`` or ``"file"`` (a ready association).
    requested : str
        One of :data:`~landmark_graph.constants.ASSOCIATE_MODES`, or ``"file"``.
    notes : tuple of str
        Why ``source`` differs from the request.
    cautions : tuple of str
        Pairs by id or from a file that mostly lie farther apart than the cut-off after the
        alignment (each also raised as an :class:`AssociationWarning`).
    """

    association: Association
    source: str
    requested: str
    notes: tuple[str, ...] = ()
    cautions: tuple[str, ...] = ()


def choose_association(
    estimate: LandmarkMap,
    reference: LandmarkMap,
    associate: str | Association = DEFAULT_ASSOCIATE,
    *,
    cutoff: float = 1.0,
    seed: int = 0,
    fallback: bool = False,
    allow_empty: bool = False,
) -> AssociationChoice:
    """The association by the rule of the module docstring.

    ``fallback``: with ``associate="id"`` and no shared id, associate automatically (and say
    so) instead of raising. Raises :class:`~landmark_graph.landmark_association.NoPairsFound`
    when no pair is found — unless ``allow_empty`` and the pairs were to be found by
    position (``"auto"``, ``"id-or-auto"``; ``"id"`` and a file are the user's own pairs):
    then the choice holds no pair (every reference landmark missed, every estimated one
    spurious) and says why in a caution (warned), so that a page can still be made to pair
    the landmarks by hand.
    """
    if allow_empty and associate in ("auto", "id-or-auto"):
        try:
            return choose_association(
                estimate, reference, associate, cutoff=cutoff, seed=seed, fallback=fallback
            )
        except NoPairsFound as exc:
            return _no_pairs(estimate, reference, str(associate), exc.message)
    notes: list[str] = []
    requested = associate if isinstance(associate, str) else "file"
    if isinstance(associate, Association):
        assoc, source = associate, "file"
    elif associate == "auto":
        assoc, source = associate_auto(estimate, reference, cutoff=cutoff, seed=seed), "auto"
    elif associate in ("id", "id-or-auto"):
        assoc, source = associate_by_id(estimate, reference), "id"
        k = int(assoc.estimate_rows.size)
        within = _pairs_within(estimate, reference, assoc, cutoff) if k >= 2 else k
        shape = _local_shape_error(estimate, reference, assoc) if 2 * within <= k else 0.0
        by_accident = k >= 2 and 2 * within <= k and not shape <= SHAPE_TOLERANCE
        if associate == "id-or-auto" and k >= 2 and 2 * within <= k and not by_accident:
            notes.append(
                f"of the {k} landmarks the maps share by id only {within} lie within "
                f"c = {cutoff:g} m of each other after the alignment, but their local shape "
                f"agrees (median relative error of nearest-neighbour distances {shape:.2g} ≤ "
                f"{SHAPE_TOLERANCE:g}): a map bent by drift, associated by id"
            )
        if associate == "id-or-auto" and (k < 2 or by_accident):
            why = (
                f"of the {k} landmarks the maps share by id only {within} lie within "
                f"c = {cutoff:g} m of each other after the alignment and their local shape "
                f"differs (median relative error of nearest-neighbour distances {shape:.2g}): "
                "ids that coincide by accident"
                if by_accident
                else f"the maps share {k} landmark id(s)"
            )
            try:
                auto = associate_auto(estimate, reference, cutoff=cutoff, seed=seed)
            except InputError as exc:
                if k == 0:
                    raise
                notes.append(f"{why}, and the automatic association failed ({exc.message}): "
                             "associated by id")  # fmt: skip
            else:
                assoc, source = auto, "auto"
                notes.append(f"{why}: associated automatically by position")
        elif k == 0 and fallback:
            assoc, source = associate_auto(estimate, reference, cutoff=cutoff, seed=seed), "auto"
            notes.append(
                "no landmark of the estimate shares an id with the reference: associated "
                "automatically by position"
            )
    else:
        raise InputError(
            f"associate must be one of {', '.join(ASSOCIATE_MODES)} or an association file, "
            f"got {associate!r}"
        )
    k = int(assoc.estimate_rows.size)
    if k == 0:
        how = (
            ' by id; associate="auto" matches them by position, an association of your own by hand'
            if associate == "id"
            else "; check the association or the cut-off"
        )
        raise NoPairsFound(f"no landmark of the estimate matches the reference{how}")
    cautions: list[str] = []
    if (source == "file" or requested == "id") and source != "auto" and k >= 2:
        within = _pairs_within(estimate, reference, assoc, cutoff)
        if (
            2 * within <= k
            and not _local_shape_error(estimate, reference, assoc) <= SHAPE_TOLERANCE
        ):
            what = "by id" if source == "id" else "in the association file"
            cautions.append(
                f"only {within} of the {k} pairs {what} lie within c = {cutoff:g} m of each "
                'other after the alignment (ids that coincide by accident?); associate="auto" '
                "matches the maps by position"
            )
            warnings.warn(cautions[-1], AssociationWarning, stacklevel=3)
    return AssociationChoice(assoc, source, requested, tuple(notes), tuple(cautions))


def _no_pairs(
    estimate: LandmarkMap, reference: LandmarkMap, requested: str, why: str
) -> AssociationChoice:
    """The choice of no pair at all, with the reason as its caution (warned)."""
    none = np.empty(0, dtype=np.int64)
    assoc = Association(
        none,
        none,
        np.arange(len(reference), dtype=np.int64),
        np.arange(len(estimate), dtype=np.int64),
    )
    said = (
        f"{why}: 0 pairs, so no mesh and no edge errors (every landmark counts as missed or "
        "spurious); pair the landmarks by hand on a review page and pass the saved CSV as the "
        "association"
    )
    warnings.warn(said, AssociationWarning, stacklevel=4)
    return AssociationChoice(assoc, "auto", requested, (), (said,))


@dataclass(frozen=True)
class MapComparison:
    """Result of :func:`compare_maps` (M estimated, N reference landmarks, K pairs).

    Attributes
    ----------
    estimate, reference : LandmarkMap
        As given.
    choice : AssociationChoice
        The pairs, where they came from, notes and cautions about them.
    alignment : MapAlignment
        The frame rule's transform (fitted on the K pairs; ``applied`` unless on request).
    estimate_xy : ndarray, shape (M, 2)
        The estimate in the frame of the comparison (moved by ``alignment`` when applied).
    mesh : Mesh
        Delaunay mesh of the K matched reference landmarks.
    errors : MeshErrors
    observable : ndarray of bool, shape (N,)
        Reference landmarks within the sensor's reach, or matched (all when no reach given).
    missed, unobserved : ndarray of int
        Reference rows unmatched and observable / unmatched and never within reach.
    reach : SensorReach or None
        The reach ``observable`` was computed with (``None``: every landmark observable).
    ospa, gospa : float
        On the observable reference landmarks [m].
    ospa_all, gospa_all : float
        On all reference landmarks [m].
    cutoff, order, thin_angle : float
    """

    estimate: LandmarkMap
    reference: LandmarkMap
    choice: AssociationChoice
    alignment: MapAlignment
    estimate_xy: NDArray[np.float64]
    mesh: Mesh
    errors: MeshErrors
    observable: NDArray[np.bool_]
    missed: NDArray[np.int64]
    unobserved: NDArray[np.int64]
    reach: SensorReach | None
    ospa: float
    gospa: float
    ospa_all: float
    gospa_all: float
    cutoff: float
    order: float
    thin_angle: float

    @property
    def association(self) -> Association:
        """The pairs (``association.missed``: every unmatched reference row, unobserved or
        not; :attr:`missed` the observable ones)."""
        return self.choice.association

    @property
    def association_source(self) -> str:
        """``"id"``, ``"auto"`` or ``"file"``: where the pairs came from."""
        return self.choice.source

    @property
    def notes(self) -> tuple[str, ...]:
        """The choice's notes and cautions."""
        return self.choice.notes + self.choice.cautions

    @property
    def frame(self) -> str:
        """The frame of OSPA, GOSPA and the figures, in words."""
        return self.alignment.description

    @property
    def observable_set(self) -> str:
        """Which reference landmarks OSPA and GOSPA are computed on, in words."""
        n, k = len(self.reference), int(self.observable.sum())
        if self.reach is None:
            if k == n:
                return f"all {n} reference landmarks"
            return f"the {k} of {n} reference landmarks marked observable or matched"
        return (
            f"the {k} of {n} reference landmarks ever within the sensor's reach of the true "
            f"trajectory or matched (reach: {self.reach.description})"
        )

    def association_dict(self) -> dict[str, Any]:
        """The JSON ``association``: counts, ids, where the pairs came from."""
        est, ref, a = self.estimate, self.reference, self.association
        return {
            "matched": int(a.estimate_rows.size),
            "missed": int(self.missed.size),
            "unobserved": int(self.unobserved.size),
            "spurious": int(a.spurious.size),
            "missed_ids": ref.ids[self.missed].tolist(),
            "unobserved_ids": ref.ids[self.unobserved].tolist(),
            "spurious_ids": est.ids[a.spurious].tolist(),
            "source": self.choice.source,
            "requested": self.choice.requested,
            "notes": list(self.choice.notes),
            "cautions": list(self.choice.cautions),
        }

    def as_dict(self) -> dict[str, Any]:
        """The JSON of ``slamrel map-compare`` (keys as ``slamrel evaluate``, plus extras).

        ``translation`` summarises the edge-length errors [m], ``rotation`` the corner-angle
        errors [rad] of all triangles, ``rotation_excluding_thin`` those of the triangles not
        flagged thin (their angles are ill-conditioned: a millimetre can flip one), the two
        ``displacement_*`` entries the optional displacement errors (see
        :mod:`landmark_graph.mesh_relations`). ``alignment`` is the frame rule's transform;
        OSPA and GOSPA state their frame and the reference landmarks they are computed on
        (``value``), with the value on all reference landmarks (``all_landmarks``).
        """
        e = self.errors
        disp_t = e.edge_displacement_triangle[np.isfinite(e.edge_displacement_triangle)]
        disp_a = e.edge_displacement_aligned[np.isfinite(e.edge_displacement_aligned)]
        well = e.corner_angle[~self.mesh.thin].ravel()

        def summ(v: Any) -> dict[str, Any]:
            return error_summaries(v).as_dict()

        on = self.observable_set
        k_obs = int(self.observable.sum())
        return {
            "relations": int(e.edge_length.size),
            "corners": int(e.corner_angle.size),
            "rotation_unit": "rad",
            "translation": summ(e.edge_length),
            "rotation": summ(e.corner_angle.ravel()),
            "rotation_excluding_thin": summ(well),
            "displacement_triangle_frame": summ(disp_t),
            "displacement_aligned_global": summ(disp_a),
            "association": self.association_dict(),
            "alignment": self.alignment.as_dict(),
            "observability": {
                "reach": None if self.reach is None else self.reach.as_dict(),
                "observable": k_obs,
                "reference_landmarks": len(self.reference),
                "description": on,
            },
            "ospa": {
                "value": self.ospa,
                "c": self.cutoff,
                "p": self.order,
                "frame": self.frame,
                "landmarks": on,
                "all_landmarks": self.ospa_all,
            },
            "gospa": {
                "value": self.gospa,
                "c": self.cutoff,
                "p": self.order,
                "alpha": 2,
                "frame": self.frame,
                "landmarks": on,
                "all_landmarks": self.gospa_all,
            },
            "mesh": {
                "edges": int(self.mesh.edges.shape[0]),
                "triangles": int(self.mesh.triangles.shape[0]),
                "thin_triangles": int(self.mesh.thin.sum()),
                "thin_angle_deg": float(np.degrees(self.thin_angle)),
                "edges_in_no_triangle": int(e.edge_length.size - disp_t.size),
                "duplicates": int(self.mesh.duplicates.shape[0]),
                "duplicate_ids": self.reference.ids[
                    self.association.reference_rows[self.mesh.duplicates]
                ].tolist(),
                "collinear": self.mesh.collinear,
                "not_computed": self.mesh_gap,
            },
        }

    @property
    def mesh_gap(self) -> str | None:
        """What of the mesh comparison is not computed and why (None when it has triangles):
        the Delaunay mesh needs 3 matched landmarks not on one line; OSPA and GOSPA need none
        of it and are always computed."""
        if self.mesh.triangles.shape[0]:
            return None
        k = int(self.association.reference_rows.size)
        if k < 3:
            edges = "one edge" if k == 2 else "no edge"
            why = f"only {k} landmark(s) matched (a triangle needs 3): {edges}"
        else:
            why = f"the {k} matched landmarks lie on one line: edges only"
        rest = "" if k == 2 or self.mesh.edges.shape[0] else ", no edge-length errors"
        return (
            f"no mesh triangles: {why}, so no corner-angle errors{rest} (OSPA and GOSPA are "
            "computed on the landmarks themselves)"
        )


def compare_maps(
    estimate: LandmarkMap,
    reference: LandmarkMap,
    *,
    associate: str | Association = DEFAULT_ASSOCIATE,
    cutoff: float = 1.0,
    order: float = 2.0,
    seed: int = 0,
    thin_angle: float = np.deg2rad(5.0),
    align: bool = True,
    observable: ArrayLike | None = None,
    reach: SensorReach | None = None,
    fallback: bool = False,
    allow_empty: bool = False,
) -> MapComparison:
    """Associate, align, mesh the matched reference landmarks, score the estimate on the mesh.

    Parameters
    ----------
    estimate, reference : LandmarkMap
        M and N landmarks.
    associate : {"id-or-auto", "id", "auto"} or Association
        See :func:`choose_association` (a ready association: from a user CSV,
        :func:`~slamrel.formats.associations.read_association_csv`).
    cutoff : float
        OSPA/GOSPA cut-off ``c`` [m], also the automatic association's match distance and
        the distance by-id pairs are expected within.
    order : float
        OSPA/GOSPA order ``p``.
    seed : int
        Seed of the automatic association.
    thin_angle : float
        Triangles whose smallest angle is below this [rad] are flagged thin.
    align : bool
        Move the estimate onto the reference by the fit on the pairs (the frame rule of the
        module docstring); ``False``: compare the maps as given.
    observable : array_like of bool, shape (N,), optional
        Reference landmarks within the sensor's reach of the true trajectory
        (:func:`~landmark_graph.observability.within_reach` with ``reach``); ``None``: all.
    reach : SensorReach, optional
        The reach ``observable`` was computed with (reported).
    fallback, allow_empty : bool
        See :func:`choose_association` (with ``allow_empty``, no pair gives a comparison of
        0 pairs: no mesh, OSPA/GOSPA on the maps as given).
    """
    if len(estimate) == 0 or len(reference) == 0:
        raise InputError("empty map: both maps need landmarks")
    choice = choose_association(
        estimate,
        reference,
        associate,
        cutoff=cutoff,
        seed=seed,
        fallback=fallback,
        allow_empty=allow_empty,
    )
    assoc = choice.association
    er, rr = assoc.estimate_rows, assoc.reference_rows
    fit = fit_map_alignment(estimate.xy[er], reference.xy[rr])
    if align:
        moved = fit.apply(estimate.xy)
    else:
        moved = np.array(estimate.xy)
        fit = MapAlignment(fit.dx, fit.dy, fit.dtheta, fit.pairs, fit.rms_residual,
                           fit.method, applied=False)  # fmt: skip
    ref_xy = reference.xy[rr]
    mesh = delaunay_mesh(ref_xy, thin_angle=thin_angle)
    errors = mesh_errors(moved[er], ref_xy, mesh)
    n = len(reference)
    if observable is None:
        reachable = np.ones(n, dtype=bool)
    else:
        reachable = np.asarray(observable, dtype=bool).reshape(-1)
        if reachable.shape != (n,):
            raise InputError(
                f"observable: expected one flag per reference landmark ({n}), "
                f"got {reachable.shape[0]}"
            )
    matched = np.zeros(n, dtype=bool)
    matched[rr] = True
    seen = reachable | matched
    moved.setflags(write=False)
    return MapComparison(
        estimate=estimate,
        reference=reference,
        choice=choice,
        alignment=fit,
        estimate_xy=moved,
        mesh=mesh,
        errors=errors,
        observable=seen,
        missed=np.flatnonzero(~matched & reachable).astype(np.int64),
        unobserved=np.flatnonzero(~seen).astype(np.int64),
        reach=None if observable is None else reach,  # a reach without flags: not used
        ospa=ospa(moved, reference.xy[seen], c=cutoff, p=order),
        gospa=gospa(moved, reference.xy[seen], c=cutoff, p=order),
        ospa_all=ospa(moved, reference.xy, c=cutoff, p=order),
        gospa_all=gospa(moved, reference.xy, c=cutoff, p=order),
        cutoff=cutoff,
        order=order,
        thin_angle=float(thin_angle),
    )
