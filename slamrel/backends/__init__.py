"""Estimation back-ends: the reference SLAM solvers the pipelines run and score.

``graph``            the :class:`~slamrel.backends.graph.PoseGraph` record (poses, landmarks,
                     factors) that the solvers take and the graph file readers build,
``least_squares``    full least squares over poses and landmarks (on :mod:`recovery.lm`),
``pose_only``        pose-only SLAM (Hu, Huang & Dissanayake): pairwise relative poses, then a
                     pose graph,
``toro_optimiser``   TORO (Grisetti et al. 2007) written from the paper; ``lever_sgd`` an
                     earlier variant,
``ekf_slam``         EKF-SLAM over range–bearing observations,
``sparse_cholesky``  the sparse Cholesky factorisations least squares runs on (with
                     ``supernodal``, the numpy-only one),
``graph_relations``  reference relations from an optimised graph's loop closures
                     (Cartographer's ``autogenerate_ground_truth``).

Maths on records only: no command-line code and no file I/O (the graph files are
:mod:`slamrel.formats`' ``g2o``, ``toro`` and ``isam``).
"""
