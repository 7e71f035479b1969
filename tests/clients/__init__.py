"""Independent SLAM clients for testing slamrel's recovery on filters it was not tuned to."""
