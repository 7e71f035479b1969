"""The named choices of the metric's parameters, in a module without numpy.

Defined here once; :mod:`relation_metric.metric` and :mod:`relation_metric.relations` use
them, and the command-line parsers offer them as option choices without importing numpy
(``slamrel --help`` stays light).
"""

from __future__ import annotations

__all__ = ["MODES", "STRATEGIES"]

#: Error definitions of :func:`relation_metric.metric.relation_errors` (``mode``).
MODES = ("paper", "metricevaluator")
#: Selection strategies of :func:`relation_metric.relations.generate_relations`.
STRATEGIES = ("consecutive", "distance", "loops", "global", "random", "all-pairs")
