"""Studies over many runs: the pose-only SLAM study, recovery faithfulness, resumable sweeps."""
