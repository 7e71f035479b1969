"""The named choices and defaults of trajectory recovery, in a module without numpy.

Defined here once; :mod:`recovery.ekf` and :mod:`recovery.recover` use them, and the
command-line parsers offer them as option choices and defaults without importing numpy
(``slamrel --help`` stays light).
"""

from __future__ import annotations

__all__ = [
    "METHODS",
    "MAP_MODES",
    "MAP_PRIORS",
    "DEFAULT_MAP_PRIOR",
    "MAP_PRIOR_CHOICES",
    "MAP_SOURCES",
    "BATCH_MAX_ITERATIONS",
    "SMOOTHER_CHI2_RESOLUTION",
    "SMOOTHER_MAX_ITERATIONS",
    "ROBUST",
    "DEFAULT_ROBUST",
    "DEFAULT_MAX_OUTLIER_RUN",
    "MAX_SIGMA",
    "MAX_VARIANCE",
    "MIN_SENSOR_SIGMA",
    "INITIAL_COVARIANCE_FLOOR",
]

#: ``method`` of :func:`recovery.recover.recover`: EKF only, EKF + RTS smoother, smoother
#: followed by a batch refinement.
METHODS = ("filter", "smoother", "batch")
#: ``map_mode`` of :func:`recovery.recover.recover`: the form of the map's uncertainty
#: (:mod:`recovery.map_uncertainty`).
MAP_MODES = ("joint", "marginal", "ignore")
#: ``map_prior`` of :func:`recovery.recover.recover`: where the map's error comes from. An
#: ``independent`` map (surveyed, or drawn apart from the log) is a prior the log's
#: measurements add to; a ``deconditioned`` map was made from this very log (an EKF-SLAM's
#: final map), so its covariance already holds the log's information and the poses'
#: covariance is the law of total covariance over it (docs/recovery.md).
MAP_PRIORS = ("independent", "deconditioned")
#: ``map_source`` of a bundle (``bundle.json``): where its map came from. ``log``: estimated
#: from this very log (an EKF-SLAM's final map); ``independent``: made apart from it (surveyed,
#: or drawn apart from the log's noise). A bundle that does not say is read as ``independent``.
MAP_SOURCES = ("log", "independent")
#: What ``map_prior`` may ask for: a prior of :data:`MAP_PRIORS`, or ``auto`` — ``deconditioned``
#: when the bundle states ``map_source: log`` and the method is the smoother or the batch, else
#: ``independent`` (:func:`recovery.recover.resolve_map_prior` says which and why).
MAP_PRIOR_CHOICES = ("auto", *MAP_PRIORS)
#: The map prior of :func:`recovery.recover.recover` when none is asked for.
DEFAULT_MAP_PRIOR = "auto"
#: Iterations of ``method="batch"`` (to numerical convergence; the smoother stops earlier).
BATCH_MAX_ITERATIONS = 50
#: The smoother's Gauss–Newton steps stop after one that lowers χ² (twice the cost) by less
#: than this: a change of the fit below one unit of χ², the statistical resolution of the
#: data. One step is exact for a linear model; on hu-complex1 (391 poses) the second step still
#: removed tens of χ² units and took the smoother's mean NEES from 3.52 ± 0.16 to 3.006 ± 0.11
#: (12 healthy seeds, marginal form; the batch: 3.006), the third changed nothing.
SMOOTHER_CHI2_RESOLUTION = 1.0
#: At most this many smoother steps (measured: 2–3 on the healthy bundles).
SMOOTHER_MAX_ITERATIONS = 10
#: Robust weights of :func:`recovery.ekf.run_filter` (``None``: the plain EKF).
ROBUST = (None, "huber", "cauchy", "redescending")
#: The default robust update of :func:`recovery.recover.recover` (its ``c`` is
#: ``recovery.ekf.ROBUST_DEFAULTS[kind]``).
DEFAULT_ROBUST = "redescending"
#: Consecutive outlying innovations after which the filter is re-entered (and a stretch of
#: disagreement between map and log is reported).
DEFAULT_MAX_OUTLIER_RUN = 10
#: The largest standard deviation (and α) a motion or sensor model accepts. Its square, the
#: variance, is at most 1e60, so the filter's products of covariances (``P Hᵀ S⁻¹ H P``, about
#: 1e120) stay far inside float64; a σ of 1e200 squares to 1e400 = ``inf`` (``sigma_v`` 1e308
#: in a bundle was an OverflowError, exit 1). Far beyond any physical noise in metres,
#: radians or m/s.
MAX_SIGMA = 1e30
#: The largest covariance entry a model or an initial covariance accepts: ``MAX_SIGMA²``.
MAX_VARIANCE = MAX_SIGMA**2
#: The smallest sensor standard deviation a bundle accepts. The sensor noise enters every
#: method as the variance σ², and the smoother and batch weigh each measurement by its
#: inverse: from σ = 1e-150 the variance (1e-300) and the information (1e300) are doubles
#: with room to spare, while σ = 1e-300 squares to 1e-600, which float64 holds only as 0 —
#: the noise-free sensor that σ = 0 states, whose information is infinite (the smoother's
#: and batch's LinAlgError). Far below any physical noise in metres or radians.
MIN_SENSOR_SIGMA = 1e-150
#: Added to the diagonal of an ``initial_covariance`` that is positive semi-definite but not
#: definite (an exactly zero one: the start pose known exactly, as two third-party EKF-SLAMs
#: write it): the filter, the smoother and the batch need its inverse. The bundle's default
#: ``1e-9 I`` says the same thing ("the start pose is known: it defines the map frame").
INITIAL_COVARIANCE_FLOOR = 1e-9
