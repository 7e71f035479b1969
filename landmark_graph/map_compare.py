"""Compare an estimated landmark map with a reference map: one run function, no I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from landmark_graph.landmark_association import (
    Association,
    associate_auto,
    associate_by_id,
    gospa,
    ospa,
)
from landmark_graph.maps import LandmarkMap
from landmark_graph.mesh import Mesh, delaunay_mesh
from landmark_graph.mesh_relations import MeshErrors, mesh_errors
from relation_metric.errors import InputError
from relation_metric.evaluate import error_summaries

__all__ = ["MapComparison", "compare_maps"]


@dataclass(frozen=True)
class MapComparison:
    """Result of :func:`compare_maps`."""

    estimate: LandmarkMap
    reference: LandmarkMap
    association: Association
    mesh: Mesh
    errors: MeshErrors
    ospa: float
    gospa: float
    cutoff: float
    order: float
    thin_angle: float

    def as_dict(self) -> dict[str, Any]:
        """The JSON of ``slamrel map-compare`` (keys as ``slamrel evaluate``, plus extras).

        ``translation`` summarises the edge-length errors [m], ``rotation`` the corner-angle
        errors [rad] of all triangles, ``rotation_excluding_thin`` those of the triangles not
        flagged thin (their angles are ill-conditioned: a millimetre can flip one), the two
        ``displacement_*`` entries the optional displacement errors (see
        :mod:`landmark_graph.mesh_relations`). OSPA and GOSPA state their frame.
        """
        e = self.errors
        disp_t = e.edge_displacement_triangle[np.isfinite(e.edge_displacement_triangle)]
        disp_a = e.edge_displacement_aligned[np.isfinite(e.edge_displacement_aligned)]
        well = e.corner_angle[~self.mesh.thin].ravel()

        def summ(v: Any) -> dict[str, Any]:
            return {k: s.as_dict() for k, s in error_summaries(v).items()}

        frame = (
            "estimate moved by the automatic rigid alignment"
            if self.association.alignment is not None
            else "as given (no alignment)"
        )
        return {
            "relations": int(e.edge_length.size),
            "corners": int(e.corner_angle.size),
            "rotation_unit": "rad",
            "translation": summ(e.edge_length),
            "rotation": summ(e.corner_angle.ravel()),
            "rotation_excluding_thin": summ(well),
            "displacement_triangle_frame": summ(disp_t),
            "displacement_aligned_global": summ(disp_a),
            "association": self.association.as_dict(self.estimate, self.reference),
            "ospa": {"value": self.ospa, "c": self.cutoff, "p": self.order, "frame": frame},
            "gospa": {
                "value": self.gospa,
                "c": self.cutoff,
                "p": self.order,
                "alpha": 2,
                "frame": frame,
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
            },
        }


def compare_maps(
    estimate: LandmarkMap,
    reference: LandmarkMap,
    *,
    associate: str | Association = "id",
    cutoff: float = 1.0,
    order: float = 2.0,
    seed: int = 0,
    thin_angle: float = np.deg2rad(5.0),
) -> MapComparison:
    """Associate, mesh the matched reference landmarks, and score the estimate on the mesh.

    Parameters
    ----------
    estimate, reference : LandmarkMap
    associate : {"id", "auto"} or Association
        By id, automatic (:func:`~landmark_graph.landmark_association.associate_auto`), or a ready
        association (from a user CSV, :func:`~slamrel.formats.associations.read_association_csv`).
    cutoff : float
        OSPA/GOSPA cut-off ``c`` [m], also the automatic association's match distance.
    order : float
        OSPA/GOSPA order ``p``.
    seed : int
        Seed of the automatic association.
    thin_angle : float
        Triangles whose smallest angle is below this [rad] are flagged thin.

    OSPA and GOSPA are computed on the whole maps: after the automatic alignment when that
    is used, otherwise in the frames as given.
    """
    if len(estimate) == 0 or len(reference) == 0:
        raise InputError("empty map: both maps need landmarks")
    if isinstance(associate, Association):
        assoc = associate
    elif associate == "id":
        assoc = associate_by_id(estimate, reference)
    elif associate == "auto":
        assoc = associate_auto(estimate, reference, cutoff=cutoff, seed=seed)
    else:
        raise InputError(
            f"associate must be 'id', 'auto' or an association file, got {associate!r}"
        )
    if assoc.estimate_rows.size == 0:
        how = (
            ' by id; associate="auto" matches them by position, an association of your own by hand'
            if associate == "id"
            else "; check the association or the cut-off"
        )
        raise InputError(f"no landmark of the estimate matches the reference{how}")
    est_xy = estimate.xy[assoc.estimate_rows]
    ref_xy = reference.xy[assoc.reference_rows]
    mesh = delaunay_mesh(ref_xy, thin_angle=thin_angle)
    errors = mesh_errors(est_xy, ref_xy, mesh)
    moved = estimate.xy
    if assoc.alignment is not None:
        moved = assoc.alignment.apply(np.column_stack((estimate.xy, np.zeros(len(estimate)))))[
            :, :2
        ]
    return MapComparison(
        estimate=estimate,
        reference=reference,
        association=assoc,
        mesh=mesh,
        errors=errors,
        ospa=ospa(moved, reference.xy, c=cutoff, p=order),
        gospa=gospa(moved, reference.xy, c=cutoff, p=order),
        cutoff=cutoff,
        order=order,
        thin_angle=float(thin_angle),
    )
