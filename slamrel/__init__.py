"""slamrel: the front door — the Python API, file formats, back-ends, simulator, reports, CLI.

For Python users ``import slamrel`` gives what a session needs, from one place::

    slamrel.Trajectory, slamrel.RelationSet, slamrel.generate_relations, slamrel.evaluate
    slamrel.read_trajectory, slamrel.read_relations, slamrel.read_bundle, slamrel.recover
    slamrel.read_map, slamrel.compare_maps, slamrel.InputError, ...

(:data:`__all__` lists them, each with the module that defines it in :data:`_EXPORTS`.)
Each name is imported from its module the first time it is used (PEP 562), so
``import slamrel`` imports no numpy and ``slamrel --help`` stays fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from relation_metric.lazy import lazy_exports

__version__ = "0.1.0"

#: Public name → the module that defines it.
_EXPORTS: dict[str, str] = {
    # trajectories, relations and the relation metric (Kümmerle et al. 2009)
    "Trajectory": "relation_metric.trajectory",
    "RelationSet": "relation_metric.relations",
    "generate_relations": "relation_metric.relations",
    "evaluate": "relation_metric.evaluate",
    "Evaluation": "relation_metric.evaluate",
    "evaluate_files": "slamrel.evaluation",
    "EvaluateOptions": "slamrel.evaluation_options",
    "absolute_trajectory_error": "relation_metric.alignment",
    "ATEResult": "relation_metric.alignment",
    "Alignment": "relation_metric.alignment",
    "umeyama": "relation_metric.alignment",
    # trajectory and relation files
    "read_trajectory": "slamrel.formats.trajectories",
    "write_trajectory": "slamrel.formats.trajectories",
    "LoadedTrajectory": "slamrel.formats.trajectories",
    "read_relations": "slamrel.formats.relations",
    "write_relations": "slamrel.formats.relations",
    # trajectory recovery from a SLAM result bundle
    "Bundle": "recovery.bundle",
    "read_bundle": "slamrel.formats.bundle",
    "write_bundle": "slamrel.formats.bundle",
    "BundleRecorder": "slamrel.formats.recorder",
    "MotionModel": "recovery.models",
    "SensorModel": "recovery.models",
    "recover": "recovery.recover",
    "Recovery": "recovery.results",
    # landmark maps
    "LandmarkMap": "landmark_graph.maps",
    "read_map": "slamrel.formats.landmark_maps",
    "write_map": "slamrel.formats.landmark_maps",
    "compare_maps": "landmark_graph.map_compare",
    "MapComparison": "landmark_graph.map_compare",
    # the exception family
    "SlamrelError": "relation_metric.errors",
    "InputError": "relation_metric.errors",
    "AssociationError": "relation_metric.errors",
    "DivergenceError": "relation_metric.errors",
}

__all__ = [
    "__version__",
    "Trajectory",
    "RelationSet",
    "generate_relations",
    "evaluate",
    "Evaluation",
    "evaluate_files",
    "EvaluateOptions",
    "absolute_trajectory_error",
    "ATEResult",
    "Alignment",
    "umeyama",
    "read_trajectory",
    "write_trajectory",
    "LoadedTrajectory",
    "read_relations",
    "write_relations",
    "Bundle",
    "read_bundle",
    "write_bundle",
    "BundleRecorder",
    "MotionModel",
    "SensorModel",
    "recover",
    "Recovery",
    "LandmarkMap",
    "read_map",
    "write_map",
    "compare_maps",
    "MapComparison",
    "SlamrelError",
    "InputError",
    "AssociationError",
    "DivergenceError",
]

if TYPE_CHECKING:  # what mypy and IDEs see; at run time __getattr__ imports on first use
    from landmark_graph.map_compare import MapComparison, compare_maps
    from landmark_graph.maps import LandmarkMap
    from recovery.bundle import Bundle
    from recovery.models import MotionModel, SensorModel
    from recovery.recover import recover
    from recovery.results import Recovery
    from relation_metric.alignment import Alignment, ATEResult, absolute_trajectory_error, umeyama
    from relation_metric.errors import AssociationError, DivergenceError, InputError, SlamrelError
    from relation_metric.evaluate import Evaluation, evaluate
    from relation_metric.relations import RelationSet, generate_relations
    from relation_metric.trajectory import Trajectory
    from slamrel.evaluation import evaluate_files
    from slamrel.evaluation_options import EvaluateOptions
    from slamrel.formats.bundle import read_bundle, write_bundle
    from slamrel.formats.landmark_maps import read_map, write_map
    from slamrel.formats.recorder import BundleRecorder
    from slamrel.formats.relations import read_relations, write_relations
    from slamrel.formats.trajectories import LoadedTrajectory, read_trajectory, write_trajectory
else:
    __getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
