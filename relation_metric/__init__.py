"""relation_metric: the shared relation metric of slamrel (Kümmerle et al. 2009).

SE(2) and SE(3) algebra (:mod:`relation_metric.se2`, :mod:`relation_metric.se3`) behind one
pose-group interface (:mod:`relation_metric.groups`), trajectories, relation sets and their
generation, timestamp association, relation errors and their statistics, alignment (ATE),
consistency (NEES). This package imports nothing else of slamrel.

The main names are importable from the package (``from relation_metric import Trajectory``);
each is imported from its module on first use (PEP 562), so ``import relation_metric`` stays
light. The error types are imported at once. The run function ``evaluate`` is not among them:
``relation_metric.evaluate`` is its module; use ``from relation_metric.evaluate import
evaluate`` (or ``slamrel.evaluate``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from relation_metric.errors import AssociationError, DivergenceError, InputError, SlamrelError
from relation_metric.lazy import lazy_exports

#: Public name → the module that defines it (imported on first use).
_EXPORTS: dict[str, str] = {
    "Trajectory": "relation_metric.trajectory",
    "RelationSet": "relation_metric.relations",
    "generate_relations": "relation_metric.relations",
    "Evaluation": "relation_metric.evaluate",
    "RelationErrors": "relation_metric.metric",
    "relation_errors": "relation_metric.metric",
    "Summary": "relation_metric.stats",
    "summarize": "relation_metric.stats",
    "associate": "relation_metric.time_association",
    "absolute_trajectory_error": "relation_metric.alignment",
    "ATEResult": "relation_metric.alignment",
    "Alignment": "relation_metric.alignment",
    "umeyama": "relation_metric.alignment",
    "SE2": "relation_metric.groups",
    "SE3": "relation_metric.groups",
}

__all__ = [
    "SlamrelError",
    "InputError",
    "AssociationError",
    "DivergenceError",
    "Trajectory",
    "RelationSet",
    "generate_relations",
    "Evaluation",
    "RelationErrors",
    "relation_errors",
    "Summary",
    "summarize",
    "associate",
    "absolute_trajectory_error",
    "ATEResult",
    "Alignment",
    "umeyama",
    "SE2",
    "SE3",
]

if TYPE_CHECKING:  # what mypy and IDEs see; at run time __getattr__ imports on first use
    from relation_metric.alignment import Alignment, ATEResult, absolute_trajectory_error, umeyama
    from relation_metric.evaluate import Evaluation
    from relation_metric.groups import SE2, SE3
    from relation_metric.metric import RelationErrors, relation_errors
    from relation_metric.relations import RelationSet, generate_relations
    from relation_metric.stats import Summary, summarize
    from relation_metric.time_association import associate
    from relation_metric.trajectory import Trajectory
else:
    __getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
