"""Factor + solve of real normal matrices with every installed sparse Cholesky back-end.

The matrices: ``H + 1e-4 diag(H)`` at the initial guess (Levenberg–Marquardt's first trial
step) of Victoria Park (``/work/shared/data/victoria_park``, 2.1·10⁴ unknowns) and of the
generated Manhattan pose graphs of ``bench_least_squares.py`` (10³, 3.5·10³, 10⁴ poses).
For each back-end of :mod:`slamrel.backends.sparse_cholesky` that is installed: the first
factorisation (QDLDL, supernodal, CHOLMOD: ordering + analysis + numeric) and the best of
``--repeat`` later ones (numeric only, the analysis reused), each with one solve, in wall
and CPU milliseconds, and the
relative difference of the solution to SuperLU's (SuperLU as the fallback runs it: on the
block minimum-degree pre-permutation). Also the expected work ``27 Σ c²`` from
the block graph, which :func:`~slamrel.backends.sparse_cholesky.choose_backend` uses.

Run: ``python benchmarks/bench_sparse_cholesky.py`` (``--sizes 1000 10000`` to choose).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from bench_least_squares import VP, manhattan  # noqa: E402

from slamrel.backends import sparse_cholesky  # noqa: E402
from slamrel.backends.least_squares import (  # noqa: E402
    PoseGraph,
    _linearise,
    _NormalEquations,
    _upper_sqrt,
)
from slamrel.formats.isam import read_isam  # noqa: E402


def first_trial_matrix(g: PoseGraph) -> tuple[_NormalEquations, np.ndarray, np.ndarray]:
    """The pattern, ``H + 1e-4 diag(H)`` values and ``-Jᵀr`` at the initial guess."""
    w_pl = _upper_sqrt(g.pl_info) if g.pl_k.size else np.empty((0, 2, 2))
    prior = (g.poses[0].copy(), np.eye(3) / 1e-6)
    normal = _NormalEquations(g, g.n_poses, g.n_landmarks)
    x, lm = np.array(g.poses), np.array(g.landmarks)
    h, grad = normal.assemble(_linearise(g, x, lm, _upper_sqrt(g.pp_info), w_pl, prior))
    h[normal.diag] *= 1.0 + 1e-4
    return normal, h, -grad


def measure(name: str, g: PoseGraph, args: argparse.Namespace) -> None:
    normal, data, rhs = first_trial_matrix(g)
    rows = np.repeat(np.arange(normal.size), np.diff(normal.indptr))
    pattern = sp.csc_matrix((np.ones(data.size), (normal.indices, rows)))
    print(
        f"{name}: {normal.size} unknowns, {data.size} entries in H; expected work "
        f"{sparse_cholesky.factor_flops(pattern):.3g} flops; default back-end "
        f"{normal.cholesky.backend}"
    )
    installed = sparse_cholesky.BACKENDS
    sparse_cholesky.BACKENDS = ("superlu",)  # the fallback: its block pre-permutation too
    try:
        fallback = first_trial_matrix(g)
    finally:
        sparse_cholesky.BACKENDS = installed
    reference = None
    for backend in ("superlu", "qdldl", "supernodal", "cholmod"):
        if backend not in installed:
            print(f"  {backend:8s} not installed")
            continue
        ne, values, b = fallback if backend == "superlu" else (normal, data, rhs)
        chol = sparse_cholesky.SparseCholesky(ne.indptr, ne.indices, ne.size, backend=backend)
        times, cpus = [], []
        for _ in range(args.repeat + 1):
            start, cpu = time.perf_counter(), time.process_time()
            chol.factor(values)
            x = chol.solve(b)[ne.perm]  # in the natural order
            times.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        reference = x if reference is None else reference
        rel = float(np.linalg.norm(x - reference) / np.linalg.norm(reference))
        print(
            f"  {backend:10s} first {times[0] * 1e3:7.1f} ms ({cpus[0] * 1e3:7.1f} CPU)  then "
            f"{min(times[1:]) * 1e3:7.1f} ms ({min(cpus[1:]) * 1e3:7.1f} CPU)"
            f"  relative difference to SuperLU {rel:.1e}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[1000, 3500, 10_000])
    parser.add_argument(
        "--repeat", type=int, default=3, help="later factorisations (analysis reused), best kept"
    )
    args = parser.parse_args()
    if VP.is_file():
        measure("Victoria Park", read_isam(VP, noise="covariance").graph, args)
    for n in args.sizes:
        measure(f"Manhattan {n}", manhattan(n), args)


if __name__ == "__main__":
    main()
