"""recovery: trajectory recovery from an EKF-SLAM result (offline EKF localisation + smoothing).

The main names are importable from the package (``from recovery import Bundle``); each is
imported from its module on first use (PEP 562), so ``import recovery`` imports no numpy.
The run function ``recover`` is not among them: ``recovery.recover`` is its module; use
``from recovery.recover import recover`` (or ``slamrel.recover``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from relation_metric.lazy import lazy_exports

#: Public name → the module that defines it (imported on first use).
_EXPORTS: dict[str, str] = {
    "Bundle": "recovery.bundle",
    "MotionModel": "recovery.models",
    "SensorModel": "recovery.models",
    "Recovery": "recovery.results",
    "Stretch": "recovery.results",
    "FilterInput": "recovery.ekf",
    "FilterResult": "recovery.ekf",
    "run_filter": "recovery.ekf",
    "SmootherResult": "recovery.smoother",
    "smooth": "recovery.smoother",
    "BatchResult": "recovery.batch_refinement",
    "refine": "recovery.batch_refinement",
}

__all__ = [
    "Bundle",
    "MotionModel",
    "SensorModel",
    "Recovery",
    "Stretch",
    "FilterInput",
    "FilterResult",
    "run_filter",
    "SmootherResult",
    "smooth",
    "BatchResult",
    "refine",
]

if TYPE_CHECKING:  # what mypy and IDEs see; at run time __getattr__ imports on first use
    from recovery.batch_refinement import BatchResult, refine
    from recovery.bundle import Bundle
    from recovery.ekf import FilterInput, FilterResult, run_filter
    from recovery.models import MotionModel, SensorModel
    from recovery.results import Recovery, Stretch
    from recovery.smoother import SmootherResult, smooth
else:
    __getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
