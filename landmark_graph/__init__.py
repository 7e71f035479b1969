"""landmark_graph: relations for landmark maps (Delaunay mesh, pose-landmark links)."""
