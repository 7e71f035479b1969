"""recovery: trajectory recovery from an EKF-SLAM result (offline EKF localisation + smoothing)."""
