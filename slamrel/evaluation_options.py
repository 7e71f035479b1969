"""The scoring options of a files-level evaluation, in a module without numpy.

:class:`EvaluateOptions` holds them; :mod:`slamrel.evaluation` scores with it. Their defaults
are defined once, in :data:`slamrel.constants.EVALUATE_DEFAULTS`, which the fields and the
``slamrel evaluate`` parser both read, so ``slamrel --help`` imports neither numpy nor
:mod:`dataclasses` (whose import costs several milliseconds of start-up). The values are checked
when an instance is made (:class:`ValueError` naming the parameter); the parser checks the
command line's text first, in its own words.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

from relation_metric.constants import MODES, STRATEGIES
from slamrel.constants import DUPLICATE_STAMPS, PAIRS_FROM, TRAJECTORY_FORMATS
from slamrel.constants import EVALUATE_DEFAULTS as _DEFAULT

__all__ = ["EvaluateOptions", "SCORING_OPTIONS"]

_MAX_SEED = 2**63 - 1


@dataclasses.dataclass(frozen=True)
class EvaluateOptions:
    """What changes the score of ``slamrel evaluate REFERENCE ESTIMATE``, by Python names.

    Each field is the option of the command with ``-`` as ``_`` (``--max-time-diff`` is
    ``max_time_diff``) and the command's default. The options that only choose outputs
    (``--json``, ``--degrees``, ``--ate``, ...) are not here.
    """

    #: Format of ESTIMATE (one of ``TRAJECTORY_FORMATS``); None: recognised from the file.
    format: str | None = _DEFAULT["format"]
    #: Format of a reference trajectory; None: recognised from the file.
    reference_format: str | None = _DEFAULT["reference_format"]
    #: KITTI ESTIMATE: a file of timestamps [s], one a line.
    times: str | None = _DEFAULT["times"]
    #: KITTI REFERENCE: a file of timestamps [s], one a line.
    reference_times: str | None = _DEFAULT["reference_times"]
    #: An odometry log that corrects far timestamps (a trajectory file), or None.
    odometry: str | None = _DEFAULT["odometry"]
    #: Format of the odometry log; None: recognised from the file.
    odometry_format: str | None = _DEFAULT["odometry_format"]
    #: Nearest-pose tolerance of the timestamp association [s], ≥ 0.
    max_time_diff: float = _DEFAULT["max_time_diff"]
    #: Interpolate on SE(2)/SE(3) beyond ``max_time_diff``.
    interpolate: bool = _DEFAULT["interpolate"]
    #: Longest gap interpolated over [s], > 0.
    max_interpolation_gap: float = _DEFAULT["max_interpolation_gap"]
    #: Error definition (one of ``MODES``: ``"paper"`` or ``"metricevaluator"``).
    mode: str = _DEFAULT["mode"]
    #: The metricEvaluator's six weights wx,wy,wz,wroll,wpitch,wyaw (1/m, 1/rad; a string
    #: ``"1,1,0,0,0,0"`` or six numbers, kept as a tuple); None: all 1.
    weights: Sequence[float] | str | None = _DEFAULT["weights"]
    #: Unassociated relations, and trajectories not in time order, are an error.
    strict: bool = _DEFAULT["strict"]
    #: Skip CARMEN pose records with non-finite values (counted; always in metricevaluator
    #: mode).
    skip_invalid_poses: bool = _DEFAULT["skip_invalid_poses"]
    #: Score 3-D inputs in 2-D: z, roll and pitch are discarded, with a warning.
    planar: bool = _DEFAULT["planar"]
    #: Associate reference and estimate pose by pose first (as evo does), then generate the
    #: relations on the matched poses (needs a reference trajectory).
    sync: bool = _DEFAULT["sync"]
    #: How relations are generated from a reference trajectory (one of ``STRATEGIES``);
    #: None: ``"consecutive"`` for a trajectory (and none for a .relations file).
    strategy: str | None = _DEFAULT["strategy"]
    #: consecutive: pose k with pose k + step [poses], ≥ 1.
    step: int = _DEFAULT["step"]
    #: distance: metres of travel between the two poses [m], > 0.
    distance: float = _DEFAULT["distance"]
    #: loops: largest distance between the two poses [m], > 0.
    radius: float = _DEFAULT["radius"]
    #: loops: least time between the two poses [s], ≥ 0.
    min_separation_time: float = _DEFAULT["min_separation_time"]
    #: loops: or least travel between the two poses [m], ≥ 0; None: time only.
    min_separation_distance: float | None = _DEFAULT["min_separation_distance"]
    #: global/random: number of pairs [relations], 1 .. ``MAX_SAMPLED_RELATIONS``.
    count: int = _DEFAULT["count"]
    #: global: least distance between the two poses [m], ≥ 0; None: a quarter of the extent.
    min_distance: float | None = _DEFAULT["min_distance"]
    #: global/random: seed of the draw, in [0, 2**63 - 1].
    seed: int = _DEFAULT["seed"]
    #: consecutive/distance: one chain of relations from pose 0, each starting where the
    #: previous ended (evo's RPE pairs) instead of one relation from every pose.
    chained: bool = _DEFAULT["chained"]
    #: time: seconds between the two poses (TUM's RPE by seconds) [s], > 0.
    seconds: float = _DEFAULT["seconds"]
    #: Which trajectory generated relations take their pose pairs from (one of
    #: ``PAIRS_FROM``): ``"reference"`` (slamrel's default: the relation metric's reference
    #: relations) or ``"estimate"`` (evo's default; needs ``sync``: the pair indices are chosen
    #: on the synchronised estimate, ``δ*`` taken from the matched reference poses).
    pairs_from: str = _DEFAULT["pairs_from"]
    #: Added to every ESTIMATE timestamp before anything else [s] (evo's ``--t_offset``).
    t_offset: float = _DEFAULT["t_offset"]
    #: Keep only poses (and relations) with ``t_start ≤ t`` [s], on both trajectories, after
    #: ``t_offset`` (evo's ``--t_start``); None: no bound.
    t_start: float | None = _DEFAULT["t_start"]
    #: ... and ``t ≤ t_end`` [s] (evo's ``--t_end``); None: no bound.
    t_end: float | None = _DEFAULT["t_end"]
    #: Poses of REFERENCE and ESTIMATE that share a timestamp (one of ``DUPLICATE_STAMPS``):
    #: ``"keep"`` all (evo's reading), ``"first"`` of each, or ``"refuse"``: a reference keeps
    #: the first of each, an estimate with two different poses at one time is refused.
    duplicate_stamps: str = _DEFAULT["duplicate_stamps"]

    def __post_init__(self) -> None:
        for name in ("format", "reference_format", "odometry_format"):
            _choice(name, getattr(self, name), TRAJECTORY_FORMATS, optional=True)
        for name in ("times", "reference_times", "odometry"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                object.__setattr__(self, name, _path(name, value))
        _number(self, "max_time_diff", lambda v: v >= 0.0, "a finite non-negative number")
        _number(self, "max_interpolation_gap", lambda v: v > 0.0, "a finite positive number")
        _choice("mode", self.mode, MODES)
        if self.weights is not None:
            from relation_metric.metric import parse_weights  # numpy, only when given

            try:
                object.__setattr__(self, "weights", parse_weights(self.weights))
            except ValueError as exc:
                raise ValueError(str(exc)) from None  # "weights '1,1': expected ..."
        _choice("strategy", self.strategy, STRATEGIES, optional=True)
        _integer(self, "step", 1, None, "a positive integer")
        _number(self, "distance", lambda v: v > 0.0, "a finite positive number")
        _number(self, "radius", lambda v: v > 0.0, "a finite positive number")
        _number(self, "min_separation_time", lambda v: v >= 0.0, "a finite non-negative number")
        for name in ("min_separation_distance", "min_distance"):
            if getattr(self, name) is not None:
                _number(self, name, lambda v: v >= 0.0, "a finite non-negative number")
        if self.count != _DEFAULT["count"]:
            from relation_metric.relations import MAX_SAMPLED_RELATIONS  # numpy, only when set

            top = MAX_SAMPLED_RELATIONS
            _integer(self, "count", 1, top, f"an integer in 1..{top}")
        _integer(self, "seed", 0, _MAX_SEED, "a seed in [0, 2**63 - 1]")
        _number(self, "seconds", lambda v: v > 0.0, "a finite positive number")
        _choice("pairs_from", self.pairs_from, PAIRS_FROM)
        _choice("duplicate_stamps", self.duplicate_stamps, DUPLICATE_STAMPS)
        _number(self, "t_offset", lambda v: True, "a finite number")
        for name in ("t_start", "t_end"):
            if getattr(self, name) is not None:
                _number(self, name, lambda v: True, "a finite number")
        if self.t_start is not None and self.t_end is not None and self.t_end < self.t_start:
            raise ValueError(f"t_end: expected >= t_start ({self.t_start}), got {self.t_end}")
        for name in ("interpolate", "strict", "skip_invalid_poses", "planar", "sync", "chained"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")


#: The names of :class:`EvaluateOptions`' fields: the options that change what is scored.
SCORING_OPTIONS = tuple(f.name for f in dataclasses.fields(EvaluateOptions))


def _choice(name: str, value: Any, choices: Sequence[str], *, optional: bool = False) -> None:
    if (value is None and optional) or (isinstance(value, str) and value in choices):
        return
    raise ValueError(f"{name}: expected one of {', '.join(choices)}, got {value!r}")


def _path(name: str, value: Any) -> str:
    import os

    try:
        return os.fspath(value)
    except TypeError:
        raise ValueError(f"{name}: expected a file name, got {value!r}") from None


def _number(options: EvaluateOptions, name: str, ok: Any, what: str) -> None:
    import numbers  # here, not at import: the parser's start-up stays light

    value = getattr(options, name)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name}: expected {what}, got {value!r}")
    if not math.isfinite(value) or not ok(value):
        raise ValueError(f"{name}: expected {what}, got {value!r}")
    object.__setattr__(options, name, float(value))


def _integer(options: EvaluateOptions, name: str, low: int, high: int | None, what: str) -> None:
    import numbers

    value = getattr(options, name)
    ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if not ok or value < low or (high is not None and value > high):
        raise ValueError(f"{name}: expected {what}, got {value!r}")
    object.__setattr__(options, name, int(value))
