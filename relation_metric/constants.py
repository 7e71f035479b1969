"""The named choices of the metric's parameters, in a module without numpy.

Defined here once; :mod:`relation_metric.metric`, :mod:`relation_metric.relations` and
:mod:`relation_metric.significance` use them, and the command-line parsers offer them as
option choices and defaults without importing numpy (``slamrel --help`` stays light).
"""

from __future__ import annotations

__all__ = [
    "MODES",
    "STRATEGIES",
    "ERROR_FRAMES",
    "BOOTSTRAP_RESAMPLES",
    "MIN_BLOCKS",
    "OVERLAP_FACTOR",
    "POSE_RELATIONS",
    "DELTA_UNITS",
    "PLANES",
]

#: Error definitions of :func:`relation_metric.metric.relation_errors` (``mode``).
MODES = ("paper", "metricevaluator")
#: Selection strategies of :func:`relation_metric.relations.generate_relations`.
STRATEGIES = ("consecutive", "distance", "loops", "global", "random", "all-pairs", "time")
#: Error definitions of a pose covariance (:func:`relation_metric.consistency.pose_errors`).
ERROR_FRAMES = ("parent", "body", "openvins")
#: Bootstrap resamples B of :func:`relation_metric.significance.paired_difference`: the
#: p-value's resolution is 1/(B + 1) = 10⁻⁴.
BOOTSTRAP_RESAMPLES = 9999
#: Fewest blocks (relations / block length) for a block-bootstrap test: with fewer, the
#: bootstrap variance rests on too few independent stretches of the run.
MIN_BLOCKS = 20
#: Blocks are at least this many times the overlap range of the relations (1 + the mean
#: number of later relations a relation overlaps in time).
OVERLAP_FACTOR = 3
#: evo's pose relations (``--pose_relation``) of :mod:`relation_metric.pose_error`.
POSE_RELATIONS = ("full", "trans_part", "rot_part", "angle_deg", "angle_rad", "point_distance")
#: evo's RPE delta units (``--delta_unit``): frames, degrees, radians, metres.
DELTA_UNITS = ("f", "d", "r", "m")
#: evo's projection planes (``--project_to_plane``).
PLANES = ("xy", "xz", "yz")
