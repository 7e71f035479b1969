"""The named choices of landmark-map comparison, in a module without numpy.

Defined here once; :mod:`landmark_graph.map_compare` uses them, and the command-line parsers
offer them (``--associate``) without importing numpy (``slamrel --help`` stays light).
"""

from __future__ import annotations

__all__ = ["ASSOCIATE_MODES", "DEFAULT_ASSOCIATE"]

#: ``associate`` of :func:`landmark_graph.map_compare.compare_maps` by name (besides a ready
#: association, e.g. from a file): by id when most shared ids match within the cut-off after
#: the alignment, else automatically; by id; automatically (rigid alignment and optimal
#: assignment within the cut-off).
ASSOCIATE_MODES = ("id-or-auto", "id", "auto")
#: The default association.
DEFAULT_ASSOCIATE = "id-or-auto"
