"""The named choices of slamrel's readers, worlds and studies, in a module without numpy.

Defined here once; the modules that own them (named at each constant) import them, and the
command-line parsers offer them as option choices without importing numpy (``slamrel
--help`` stays light).
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "BUNDLE_FORMAT",
    "EVALUATE_DEFAULTS",
    "TRAJECTORY_FORMATS",
    "COVARIANCE_LAYOUTS",
    "WORLDS",
    "PAPER_WORLDS",
    "NOISE_NAMES",
    "NOISE_HELP",
    "POSE_ONLY_METHODS",
    "PAIRS_FROM",
    "EVO_MAX_TIME_DIFF",
    "STRATEGY_OPTION_WORDS",
    "PLOT_MODES",
]

#: The format id of the SLAM result bundle (``bundle.json``'s ``format``; docs/bundle.md),
#: written by :func:`slamrel.formats.bundle.write_bundle` and required by its reader.
BUNDLE_FORMAT = "slamrel-bundle/1"
#: Trajectory file formats of :func:`slamrel.formats.trajectories.read_trajectory`.
TRAJECTORY_FORMATS = ("plain", "tum", "carmen", "g2o", "csv", "kitti", "euroc", "bag")
#: Layouts of a filter's poses with covariances (:mod:`slamrel.formats.covariances`).
COVARIANCE_LAYOUTS = ("tum-cov", "openvins", "se2-cov", "bag")
#: Built-in simulated worlds of :func:`slamrel.simulation.worlds.make_world` ...
WORLDS = ("simple1", "simple2", "complex1", "complex2")
#: ... and Hu et al.'s worlds as stated (82 / 420 poses; observation counts differ: see worlds.py).
PAPER_WORLDS = ("hu-simple1", "hu-simple2", "hu-complex1", "hu-complex2")
#: Hu et al.'s noise types (Table I), the keys of ``slamrel.simulation.worlds.NOISE_TYPES``.
NOISE_NAMES = ("a", "b", "c")
#: The help of a ``--noise`` option: Hu et al.'s noise types (Table I) as
#: ``slamrel.simulation.worlds.NOISE_TYPES`` holds them (tests/test_help.py checks the numbers).
NOISE_HELP = (
    "noise type of Hu et al. (Table I), standard deviations per step: a: dx, dy 0.1 m, "
    "dθ 0.05 rad, observation 0.1; b: 0.2 m, 0.2 rad, 0.1; c: 0.1 m, 0.05 rad, 0.3 "
    "(default: %(default)s)"
)
#: Methods of the pose-only study (:mod:`slamrel.studies.pose_only`, its ``METHODS``).
POSE_ONLY_METHODS = ("full", "m1", "m2", "toro")

#: The defaults of the scoring options of ``slamrel evaluate`` (the fields of
#: :class:`slamrel.evaluation_options.EvaluateOptions`, which documents each), defined once:
#: the dataclass's fields and the command's parser both read them from here.
EVALUATE_DEFAULTS: dict[str, Any] = {
    "format": None,
    "reference_format": None,
    "times": None,
    "reference_times": None,
    "odometry": None,
    "odometry_format": None,
    "max_time_diff": 0.1,
    "interpolate": False,
    "max_interpolation_gap": 1.0,
    "mode": "paper",
    "weights": None,
    "strict": False,
    "skip_invalid_poses": False,
    "planar": False,
    "sync": False,
    "strategy": None,
    "step": 1,
    "distance": 1.0,
    "radius": 1.0,
    "min_separation_time": 30.0,
    "min_separation_distance": None,
    "count": 1000,
    "min_distance": None,
    "seed": 0,
    "chained": False,
    "seconds": 1.0,
    "pairs_from": "reference",
    "t_offset": 0.0,
    "t_start": None,
    "t_end": None,
}
#: Where relations generated from a trajectory take their pose pairs (``--pairs-from``).
PAIRS_FROM = ("reference", "estimate")
#: The planes of ``slamrel evaluate --plot-mode``
#: (:func:`slamrel.plots.relation_errors.plot_plane`).
PLOT_MODES = ("auto", "xy", "xz", "yz", "yx", "zx", "zy", "xyz")
#: evo's default time tolerance of its pose-by-pose association (``t_max_diff``) [s].
EVO_MAX_TIME_DIFF = 0.01

#: The strategy parameters of :func:`relation_metric.relations.generate_relations` in the
#: words of the commands' options (:func:`slamrel.evaluation.in_option_words`); the pair
#: budget (``max_relations``) has no option.
STRATEGY_OPTION_WORDS = {
    " (max_relations; ": " (",
    ", or raise max_relations if the memory is there": "",
    "strategy 'random' with a count": "--strategy random with --count N",
    "strategy 'loops' or 'global'": "--strategy loops or global",
    "a smaller count": "a smaller --count",
    "a smaller radius": "a smaller --radius",
    "a larger min_separation_time (or min_separation_distance)": (
        "a larger --min-separation-time (or --min-separation-distance)"
    ),
}

#: ``relations from-graph``'s defaults, Cartographer's (``autogenerate_ground_truth_main.cc``):
#: the travel a loop closure must span [m] and its largest disagreement with the optimum
#: [m, rad]. Here (not in ``backends.graph_relations``) so that ``--help`` imports no numpy.
GRAPH_MIN_TRAVEL, GRAPH_MAX_ERROR_XY, GRAPH_MAX_ERROR_THETA = 100.0, 0.15, 0.02
