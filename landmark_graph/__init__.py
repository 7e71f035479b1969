"""landmark_graph: relations for landmark maps (Delaunay mesh, pose-landmark links).

The main names are importable from the package (``from landmark_graph import compare_maps``);
each is imported from its module on first use (PEP 562), so ``import landmark_graph`` imports
no numpy or scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from relation_metric.lazy import lazy_exports

#: Public name → the module that defines it (imported on first use).
_EXPORTS: dict[str, str] = {
    "LandmarkMap": "landmark_graph.maps",
    "compare_maps": "landmark_graph.map_compare",
    "MapComparison": "landmark_graph.map_compare",
    "MapAlignment": "landmark_graph.map_compare",
    "choose_association": "landmark_graph.map_compare",
    "fit_map_alignment": "landmark_graph.map_compare",
    "SensorReach": "landmark_graph.observability",
    "within_reach": "landmark_graph.observability",
    "Association": "landmark_graph.landmark_association",
    "associate_by_id": "landmark_graph.landmark_association",
    "associate_auto": "landmark_graph.landmark_association",
    "ospa": "landmark_graph.set_distances",
    "gospa": "landmark_graph.set_distances",
    "Mesh": "landmark_graph.mesh",
    "delaunay_mesh": "landmark_graph.mesh",
    "MeshErrors": "landmark_graph.mesh_relations",
    "mesh_errors": "landmark_graph.mesh_relations",
    "PoseLandmarkErrors": "landmark_graph.pose_landmark",
    "pose_landmark_errors": "landmark_graph.pose_landmark",
    "pose_landmark_relations": "landmark_graph.pose_landmark",
}

__all__ = [
    "LandmarkMap",
    "compare_maps",
    "MapComparison",
    "MapAlignment",
    "choose_association",
    "fit_map_alignment",
    "SensorReach",
    "within_reach",
    "Association",
    "associate_by_id",
    "associate_auto",
    "ospa",
    "gospa",
    "Mesh",
    "delaunay_mesh",
    "MeshErrors",
    "mesh_errors",
    "PoseLandmarkErrors",
    "pose_landmark_errors",
    "pose_landmark_relations",
]

if TYPE_CHECKING:  # what mypy and IDEs see; at run time __getattr__ imports on first use
    from landmark_graph.landmark_association import (
        Association,
        associate_auto,
        associate_by_id,
    )
    from landmark_graph.map_compare import (
        MapAlignment,
        MapComparison,
        choose_association,
        compare_maps,
        fit_map_alignment,
    )
    from landmark_graph.maps import LandmarkMap
    from landmark_graph.mesh import Mesh, delaunay_mesh
    from landmark_graph.mesh_relations import MeshErrors, mesh_errors
    from landmark_graph.observability import SensorReach, within_reach
    from landmark_graph.pose_landmark import (
        PoseLandmarkErrors,
        pose_landmark_errors,
        pose_landmark_relations,
    )
    from landmark_graph.set_distances import gospa, ospa
else:
    __getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
