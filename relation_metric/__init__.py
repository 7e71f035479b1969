"""relation_metric: the shared relation metric of slamrel (Kümmerle et al. 2009).

SE(2) and SE(3) algebra (:mod:`relation_metric.se2`, :mod:`relation_metric.se3`) behind one
pose-group interface (:mod:`relation_metric.groups`), trajectories, relation sets and their file
formats, timestamp association, relation errors and their statistics, alignment (ATE),
consistency (NEES). This package imports nothing else of slamrel.
"""

from relation_metric.errors import AssociationError, DivergenceError, InputError, SlamrelError

__all__ = ["SlamrelError", "InputError", "AssociationError", "DivergenceError"]
