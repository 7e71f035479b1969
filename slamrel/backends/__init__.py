"""Estimation back-ends: the reference SLAM solvers the pipelines run and score.

``lm``         the one Levenberg–Marquardt (full LS, pose-only LS and batch recovery run on it),
``graph``      pose graphs and full least squares (poses and landmarks),
``pose_only``  pose-only SLAM (Hu, Huang & Dissanayake): pairwise relative poses, then a pose graph,
``toro``       TORO (Grisetti et al. 2007) written from the paper; ``lever_sgd`` an earlier variant,
``ekfslam``    EKF-SLAM over range–bearing observations.

Libraries only: no command-line code, no file output except through ``recovery.graph_formats``.
"""
