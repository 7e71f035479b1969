"""Pose-graph file formats: g2o (``g2o``) and TORO (``toro``), read into and written from
:class:`recovery.estimation.graph.PoseGraph`."""
