"""Compare an estimated landmark map with a reference map: one run function, no I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from landmark_graph.association import Association, associate_auto, associate_by_id, gospa, ospa
from landmark_graph.maps import LandmarkMap
from landmark_graph.mesh import Mesh, delaunay_mesh
from landmark_graph.relations import MeshErrors, mesh_errors
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

    def as_dict(self) -> dict[str, Any]:
        """The JSON of ``slamrel map-compare`` (keys as ``slamrel evaluate``, plus extras)."""
        e = self.errors
        disp_t = e.edge_displacement_triangle[np.isfinite(e.edge_displacement_triangle)]
        return {
            "relations": int(e.edge_length.size),
            "corners": int(e.corner_angle.size),
            "rotation_unit": "rad",
            "translation": {k: v.as_dict() for k, v in error_summaries(e.edge_length).items()},
            "rotation": {
                k: v.as_dict() for k, v in error_summaries(e.corner_angle.ravel()).items()
            },
            "displacement_triangle_frame": {
                k: v.as_dict() for k, v in error_summaries(disp_t).items()
            },
            "displacement_aligned_global": {
                k: v.as_dict() for k, v in error_summaries(e.edge_displacement_aligned).items()
            },
            "association": self.association.as_dict(self.estimate, self.reference),
            "ospa": {"value": self.ospa, "c": self.cutoff, "p": self.order},
            "gospa": {"value": self.gospa, "c": self.cutoff, "p": self.order, "alpha": 2},
            "mesh": {
                "edges": int(self.mesh.edges.shape[0]),
                "triangles": int(self.mesh.triangles.shape[0]),
                "thin_triangles": int(self.mesh.thin.sum()),
                "duplicates": int(self.mesh.duplicates.shape[0]),
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
) -> MapComparison:
    """Associate, mesh the matched reference landmarks, and score the estimate on the mesh.

    ``associate`` is ``"id"``, ``"auto"`` or a ready :class:`Association` (from a user CSV).
    OSPA and GOSPA are computed on the whole maps (after the automatic alignment, when used).
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
        raise InputError("no landmark of the estimate matches the reference")
    est_xy = estimate.xy[assoc.estimate_rows]
    ref_xy = reference.xy[assoc.reference_rows]
    mesh = delaunay_mesh(ref_xy)
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
    )
