"""Option value types for argparse: a bad value is a usage error (exit 2), never a traceback.

Each function here is an argparse ``type=``: it turns the string given on the command line
into a value or raises :class:`argparse.ArgumentTypeError` with what was expected, which
argparse reports as ``slamrel CMD: error: argument --NAME: ...`` with exit code 2. Range
checks live here, once, so that a mistyped option is caught before any work starts (a
negative seed, a probability of 2, ``nan`` seconds, a thin-triangle angle of 200°).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

__all__ = [
    "seed",
    "count",
    "positive_int",
    "nonnegative_int",
    "positive_float",
    "nonnegative_float",
    "finite_float",
    "probability",
    "fraction",
    "triangle_angle",
    "int_range",
    "float_at_least",
    "weights",
    "figure_file",
    "noise_scale",
    "length",
    "NOISE_SCALE_RANGE",
]

_MAX_SEED = 2**63 - 1


def _float(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _int(text: str) -> int | None:
    try:
        return int(text, 10)
    except ValueError:
        return None


def _option_type(
    convert: Callable[[str], Any], ok: Callable[[Any], bool], what: str, name: str
) -> Callable[[str], Any]:
    """An argparse type: ``convert`` the text, accept it when ``ok``, else say ``what``."""

    def parse(text: str) -> Any:
        value = convert(text)
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    parse.__name__ = name  # argparse names the type in some messages
    return parse


seed = _option_type(_int, lambda v: 0 <= v <= _MAX_SEED, "a seed in [0, 2**63 - 1]", "seed")
positive_int = _option_type(_int, lambda v: v >= 1, "a positive integer", "positive_int")


def count(text: str) -> int:
    """A number of relations to draw: 1 .. ``relations.MAX_SAMPLED_RELATIONS``."""
    from relation_metric.relations import MAX_SAMPLED_RELATIONS

    return int_range(1, MAX_SAMPLED_RELATIONS)(text)


nonnegative_int = _option_type(_int, lambda v: v >= 0, "a non-negative integer", "nonnegative_int")
positive_float = _option_type(_float, lambda v: v > 0.0, "a finite positive number", "positive")
nonnegative_float = _option_type(
    _float, lambda v: v >= 0.0, "a finite non-negative number", "nonnegative"
)
finite_float = _option_type(_float, lambda v: True, "a finite number", "finite")
probability = _option_type(
    _float, lambda v: 0.0 < v < 1.0, "a probability in (0, 1)", "probability"
)
fraction = _option_type(_float, lambda v: 0.0 <= v < 1.0, "a fraction in [0, 1)", "fraction")
triangle_angle = _option_type(
    _float,
    lambda v: 0.0 < v <= 60.0,
    "an angle in degrees in (0, 60] (the smallest corner of a triangle is at most 60°)",
    "triangle_angle",
)


#: ``--noise-scale``: the covariances the filter assumes are scaled by its square, so the
#: range keeps that square, and the filter's products of such covariances, inside float64
#: and well conditioned (1e300 squared is ``inf``: an OverflowError, exit 1, before the limit).
NOISE_SCALE_RANGE = (1e-6, 1e6)
noise_scale = _option_type(
    _float,
    lambda v: NOISE_SCALE_RANGE[0] <= v <= NOISE_SCALE_RANGE[1],
    f"a noise scale in [{NOISE_SCALE_RANGE[0]:g}, {NOISE_SCALE_RANGE[1]:g}] (the filter's "
    "covariances are scaled by its square)",
    "noise_scale",
)


def length(text: str) -> float:
    """A positive length in metres, at most ``relation_metric.trajectory.MAX_COORDINATE``
    (beyond it squared distances leave float64)."""
    from relation_metric.trajectory import MAX_COORDINATE

    return _option_type(
        _float,
        lambda v: 0.0 < v <= MAX_COORDINATE,
        f"a finite positive number (a length of at most {MAX_COORDINATE:.0e} m)",
        "length",
    )(text)


def int_range(low: int, high: int) -> Callable[[str], int]:
    """An integer in ``[low, high]``."""
    return _option_type(_int, lambda v: low <= v <= high, f"an integer in {low}..{high}", "int")


def float_at_least(low: float) -> Callable[[str], float]:
    """A finite number ≥ ``low``."""
    return _option_type(_float, lambda v: v >= low, f"a finite number >= {low:g}", "float")


def weights(text: str) -> tuple[float, ...]:
    """The metricEvaluator's six weights ``wx,wy,wz,wroll,wpitch,wyaw``."""
    from relation_metric.metric import parse_weights

    try:
        return parse_weights(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


FIGURE_FORMATS = (".png", ".svg", ".pdf")


def figure_file(text: str) -> str:
    """A figure's file name; its extension picks the format: .png, .svg or .pdf."""
    import os

    ext = os.path.splitext(text)[1].lower()
    if ext not in FIGURE_FORMATS:
        raise argparse.ArgumentTypeError(
            f"expected a file name ending in {', '.join(FIGURE_FORMATS)} (the format), got {text!r}"
        )
    return text
