"""Option choices the sub-command parsers need, without importing the modules that own them.

``slamrel --help`` and ``slamrel CMD --help`` build every parser; importing the library
modules that define these names would pull numpy, scipy.stats and the pipeline into every
start-up. The values are copies; ``tests/test_cli_imports.py`` checks that each equals the
owner's constant (named in the comment), so a change there fails the tests, not the CLI.
"""

from __future__ import annotations

# slamrel.formats.trajectories.TRAJECTORY_FORMATS
TRAJECTORY_FORMATS = ("plain", "tum", "carmen", "g2o", "csv", "kitti", "euroc")
# relation_metric.metric.MODES
MODES = ("paper", "metricevaluator")
# relation_metric.relations.STRATEGIES
STRATEGIES = ("consecutive", "distance", "loops", "global", "random", "all-pairs")
# recovery.recover.METHODS, recovery.recover.MAP_MODES
METHODS = ("filter", "smoother", "batch")
MAP_MODES = ("joint", "marginal", "ignore")
# slamrel.simulation.worlds.WORLDS, .PAPER_WORLDS, sorted(slamrel.simulation.worlds.NOISE_TYPES)
WORLDS = ("simple1", "simple2", "complex1", "complex2")
PAPER_WORLDS = ("hu-simple1", "hu-simple2", "hu-complex1", "hu-complex2")
NOISE_TYPES = ("a", "b", "c")
# recovery.ekf.ROBUST (without None), recovery.ekf.DEFAULT_MAX_OUTLIER_RUN
ROBUST_CHOICES = ("huber", "cauchy", "redescending")
# recovery.recover.DEFAULT_ROBUST
DEFAULT_ROBUST = "redescending"
DEFAULT_MAX_OUTLIER_RUN = 10
# slamrel.studies.pose_only.METHODS
STUDY_METHODS = ("full", "m1", "m2", "toro")
