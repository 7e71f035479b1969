"""Reference SLAM back-ends (least squares on pose graphs, EKF-SLAM)."""
