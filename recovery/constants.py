"""The named choices and defaults of trajectory recovery, in a module without numpy.

Defined here once; :mod:`recovery.ekf` and :mod:`recovery.recover` use them, and the
command-line parsers offer them as option choices and defaults without importing numpy
(``slamrel --help`` stays light).
"""

from __future__ import annotations

__all__ = [
    "METHODS",
    "MAP_MODES",
    "BATCH_MAX_ITERATIONS",
    "ROBUST",
    "DEFAULT_ROBUST",
    "DEFAULT_MAX_OUTLIER_RUN",
]

#: ``method`` of :func:`recovery.recover.recover`: EKF only, EKF + RTS smoother, smoother
#: followed by a batch refinement.
METHODS = ("filter", "smoother", "batch")
#: ``map_mode`` of :func:`recovery.recover.recover`: the form of the map's uncertainty
#: (:mod:`recovery.map_uncertainty`).
MAP_MODES = ("joint", "marginal", "ignore")
#: Iterations of ``method="batch"`` (the smoother is its first).
BATCH_MAX_ITERATIONS = 50
#: Robust weights of :func:`recovery.ekf.run_filter` (``None``: the plain EKF).
ROBUST = (None, "huber", "cauchy", "redescending")
#: The default robust update of :func:`recovery.recover.recover` (its ``c`` is
#: ``recovery.ekf.ROBUST_DEFAULTS[kind]``).
DEFAULT_ROBUST = "redescending"
#: Consecutive outlying innovations after which the filter is re-entered (and a stretch of
#: disagreement between map and log is reported).
DEFAULT_MAX_OUTLIER_RUN = 10
