"""Repeated solves of sparse symmetric positive definite systems with one fixed pattern.

Least squares (Levenberg–Marquardt, :mod:`slamrel.backends.least_squares`) factorises
``H + λ D`` many times with the same sparsity pattern and new numbers. This module hides
which library does it behind :class:`SparseCholesky` (``factor(data)``, ``solve(rhs)``).
Back-ends, chosen when the object is built:

``"qdldl"`` (core dependency, Apache-2.0)
    QDLDL's LDLᵀ with an AMD ordering. The ordering and the symbolic factorisation are
    computed on the first :meth:`SparseCholesky.factor` and *reused* by every later one
    (``Solver.update``: numeric factorisation only). No supernodes, so its time grows with
    the flops: the right choice for graphs with little fill (a pose chain with landmarks,
    such as Victoria Park, where it is much faster than SuperLU).
``"supernodal"`` (core: numpy + scipy, and QDLDL's AMD for the ordering)
    slamrel's own supernodal multifrontal Cholesky (:mod:`slamrel.backends.supernodal`):
    supervariables, elimination tree, fundamental and relaxed supernodes and every index
    map computed once per pattern; per factorisation, dense ``dpotrf``/``dtrsm``/``dsyrk``
    on each supernode's front (scipy's LAPACK/BLAS) and a vectorised extend-add. For
    graphs with much fill, where QDLDL's scalar up-looking factorisation is much slower;
    CHOLMOD, when installed, is faster still (its work around the dense calls is C, and it
    stores fewer explicit zeros).
``"cholmod"`` (optional extra ``fast``: the ``cvxopt`` wheel)
    CHOLMOD's supernodal Cholesky (BLAS-3 on dense supernodes) through ``cvxopt.cholmod``:
    the ordering (CHOLMOD's AMD) and the symbolic analysis once per pattern
    (``cholmod.symbolic``), then a numeric factorisation only per call (``cholmod.numeric``).
    On graphs with much fill (2-D loop structure, such as a 10⁴-pose Manhattan grid) it is
    much faster than QDLDL; on low-fill graphs QDLDL is as fast or faster (Victoria Park).
    cvxopt is GPL-3.0 and bundles CHOLMOD's GPL-2.0+ Supernodal module, so it is an extra,
    not a core dependency of this BSD-3 package. (Before: the ``cholespy`` wheel, which
    re-ran the analysis at every factorisation and took no ordering: slower there.)
    Timings of all four: benchmarks/README.md.
``"superlu"`` (fallback: scipy only)
    scipy's SuperLU in symmetric mode, no pivoting, minimum-degree ordering on ``A + Aᵀ``
    (an LU with a Cholesky's fill); no reuse between factorisations. Used when neither
    library imports.

:func:`choose_backend` picks ``"cholmod"`` when it is installed and the expected
factorisation work (``flops``, e.g. from a symbolic factorisation of the block graph) is
above :data:`CHOLMOD_MIN_FLOPS`, else ``"supernodal"`` above :data:`SUPERNODAL_MIN_FLOPS`,
else ``"qdldl"``, else ``"superlu"``. Every back-end solves
to working precision (their solutions agree to rounding on both problems above:
benchmarks/README.md), so the choice moves results by rounding only.
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError
from slamrel.backends.supernodal import SupernodalCholesky, symbolic_factor

__all__ = [
    "SparseCholesky",
    "available_backends",
    "choose_backend",
    "factor_flops",
    "BACKENDS",
    "CHOLMOD_MIN_FLOPS",
    "SUPERNODAL_MIN_FLOPS",
]

#: Expected flops (``Σ_j c_j²`` over the columns of the Cholesky factor) above which CHOLMOD's
#: supernodal numeric factorisation beats QDLDL's (both reuse their analysis). Measured per
#: factorisation + solve (``benchmarks/bench_sparse_cholesky.py``, timings in
#: benchmarks/README.md; flops as :mod:`~slamrel.backends.least_squares` estimates them from
#: the block graph) on Manhattan graphs of 10³–10⁴ poses (6.7·10⁵–1.35·10⁹ flops) and
#: Victoria Park (4.9·10⁶): the crossover lies near 5·10⁶; above 10⁷ CHOLMOD is clearly
#: ahead (below, QDLDL keeps Victoria Park's results as they were).
CHOLMOD_MIN_FLOPS = 1e7

#: Expected flops (as for :data:`CHOLMOD_MIN_FLOPS`) above which the core ``"supernodal"``
#: back-end beats QDLDL, when CHOLMOD is not installed: for its analysis (once per pattern)
#: and about seven factorisations + solves, as one LM solve does. Measured
#: (``benchmarks/bench_sparse_cholesky.py``, CPU ms, analysis + first / each later, supernodal
#: vs QDLDL, 2026-12-02): Manhattan 3.5·10³ (2.7·10⁷ flops) 69 / 11.6 vs 32 / 9.2 — QDLDL
#: ahead; 5·10³ (10⁸) 118 / 21 vs 68 / 29 — even over seven; 7·10³ (2.8·10⁸) 115 / 36 vs
#: 106 / 78; 10⁴ (1.36·10⁹) 83 per factorisation vs 480. Victoria Park (3.4·10⁶): 18.5 vs 3.6.
SUPERNODAL_MIN_FLOPS = 1e8

_SINGULAR = "the normal equations are singular (unobserved states?)"


def available_backends() -> tuple[str, ...]:
    """The back-ends whose libraries are installed, fastest first (``"superlu"`` always)."""
    found = [
        name
        for name, module in (("cholmod", "cvxopt"), ("qdldl", "qdldl"))
        if importlib.util.find_spec(module) is not None
    ]
    if "qdldl" in found:  # the supernodal back-end takes QDLDL's AMD ordering
        found.insert(found.index("qdldl"), "supernodal")
    return (*found, "superlu")


#: The back-ends installed, found when this module is imported (tests patch it).
BACKENDS: tuple[str, ...] = available_backends()


#: Every back-end this module knows, fastest first.
ALL_BACKENDS: tuple[str, ...] = ("cholmod", "supernodal", "qdldl", "superlu")


def choose_backend(flops: float | None = None, *, have: tuple[str, ...] | None = None) -> str:
    """The back-end for a factorisation of about ``flops`` work (see the module docstring).

    Parameters
    ----------
    flops : float, optional
        Expected factorisation work; ``None``: unknown (neither CHOLMOD nor the supernodal
        back-end is then chosen).
    have : tuple of str, optional
        The back-ends to choose from; default: those installed (:data:`BACKENDS`).
        ``have=ALL_BACKENDS`` tells which one would be chosen if every library were installed.

    Returns
    -------
    str
        ``"cholmod"``, ``"supernodal"``, ``"qdldl"`` or ``"superlu"``.
    """
    have = BACKENDS if have is None else have
    if "cholmod" in have and flops is not None and flops >= CHOLMOD_MIN_FLOPS:
        return "cholmod"
    if "supernodal" in have and flops is not None and flops >= SUPERNODAL_MIN_FLOPS:
        return "supernodal"
    return "qdldl" if "qdldl" in have else "superlu"


def factor_flops(pattern: sp.spmatrix) -> float:
    """Expected work ``Σ_j c_j²`` of a Cholesky factorisation of the symmetric ``pattern``.

    Parameters
    ----------
    pattern : sparse matrix, shape (n, n)
        Symmetric pattern (values ignored; the diagonal need not be stored).

    Returns
    -------
    float
        ``c_j``: entries in column ``j`` of ``L`` (diagonal included) in a fill-reducing
        order: QDLDL's AMD when installed (no pivot test needed: the values used are
        diagonally dominant), else SuperLU's symmetric minimum degree.
    """
    if "qdldl" in BACKENDS:  # kept: the supernodal analysis of the same graph reuses it
        lower = symbolic_factor(pattern)[0]
        counts = np.diff(lower.indptr) + 1.0  # QDLDL's L is unit lower: diagonal not stored
    else:
        a = sp.csc_matrix(pattern, dtype=np.float64, copy=True)
        a.data[:] = 1.0
        a = (a + sp.diags(np.asarray(abs(a).sum(axis=0)).ravel() + 1.0)).tocsc()
        lu = spla.splu(
            a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
        counts = np.diff(lu.L.indptr).astype(np.float64)
    return float(counts @ counts)


def _sorted_rows(indptr: NDArray[np.integer], indices: NDArray[np.integer]) -> bool:
    """Whether every column of the CSC pattern lists its rows strictly increasing."""
    rising = np.diff(indices) > 0
    ends = indptr[1:-1]  # a column's first entry: the pair before it spans two columns
    rising[ends[(ends > 0) & (ends < indices.size)] - 1] = True
    return bool(rising.all())


class SparseCholesky:
    """Factorise and solve ``A x = b``, ``A`` SPD with a fixed CSC pattern.

    Parameters
    ----------
    indptr : array_like of int, shape (n + 1,)
    indices : array_like of int, shape (nnz,)
        CSC pattern of the *whole* symmetric matrix (both triangles, sorted row indices,
        every diagonal entry stored).
    size : int
        ``n``.
    backend : {"qdldl", "supernodal", "cholmod", "superlu"}, optional
        Default: :func:`choose_backend` of ``flops``.
    flops : float, optional
        Expected factorisation work, for the default back-end.
    blocks : array_like of int, optional
        Widths of consecutive groups of variables (3 per pose, 2 per landmark), for the
        supernodal back-end's ordering (:class:`~slamrel.backends.supernodal.SupernodalCholesky`).

    Notes
    -----
    Call :meth:`factor` with ``data`` (shape ``(nnz,)``, the values in the pattern's order),
    then :meth:`solve` any number of times. An exactly zero pivot raises
    :class:`~relation_metric.errors.DivergenceError` (QDLDL: its factorisation, or a solve
    whose residual ``‖Ax − b‖₁`` exceeds ``1e-8 (max|A| ‖x‖₁ + ‖b‖₁)``, which catches its
    refactorisation stopping silently; SuperLU: its factorisation); CHOLMOD and the
    supernodal back-end raise it for any matrix that is not numerically positive
    definite. QDLDL and SuperLU (no pivoting) solve symmetric indefinite systems with
    nonzero pivots as they are.
    """

    def __init__(
        self,
        indptr: NDArray[np.integer],
        indices: NDArray[np.integer],
        size: int,
        *,
        backend: str | None = None,
        flops: float | None = None,
        blocks: NDArray[np.integer] | None = None,
    ) -> None:
        self.size = int(size)
        self._blocks = blocks
        self.indptr = np.asarray(indptr, dtype=np.int32)
        indices = np.asarray(indices, dtype=np.int32)
        self.backend = choose_backend(flops) if backend is None else backend
        if self.backend not in ALL_BACKENDS:
            raise ValueError(f"unknown sparse Cholesky back-end {self.backend}")
        col = np.repeat(np.arange(self.size, dtype=np.int32), np.diff(self.indptr))
        # valid CSC may list a column's rows in any order; SuperLU and cvxopt's spmatrix.V
        # assume them sorted, so the pattern is sorted once and factor() permutes the values
        # (unless it is sorted already, as least squares builds it: an O(nnz) check, not
        # the sort, 0.5 against 18 ms on Manhattan 10⁴)
        self._order = None if _sorted_rows(self.indptr, indices) else np.lexsort((indices, col))
        self.indices = indices if self._order is None else indices[self._order]
        upper = self.indices <= col
        self._upper = np.flatnonzero(upper)  # slots of the upper triangle, in CSC order
        upper_indptr = np.concatenate(([0], np.cumsum(np.bincount(col[upper], minlength=size))))
        shape = (self.size, self.size)
        # both matrices built (and checked by scipy) once; factor() overwrites their values
        self._full = sp.csc_matrix((np.zeros(self.indices.size), self.indices, self.indptr), shape)
        self._upper_matrix = sp.csc_matrix(
            (np.zeros(self._upper.size), self.indices[upper], upper_indptr.astype(np.int32)), shape
        )
        self._lower = np.flatnonzero(self.indices >= col)  # CHOLMOD reads the lower triangle
        self._matrix: Any = None  # CHOLMOD: the cvxopt matrix whose values factor() replaces
        self._factor: Any = None

    def factor(self, data: Array) -> None:
        """Factorise the matrix with values ``data`` (shape ``(nnz,)``) in the stored pattern."""
        data = np.ascontiguousarray(data, dtype=np.float64)
        if self._order is not None:
            data = data[self._order]
        if self.backend == "qdldl":
            import qdldl

            np.take(data, self._upper, out=self._upper_matrix.data)
            a = self._upper_matrix
            try:
                if self._factor is None:  # ordering + symbolic + numeric, once per pattern
                    self._factor = qdldl.Solver(a, upper=True)
                else:  # numeric only, the symbolic factorisation reused
                    self._factor.update(a, upper=True)
            except RuntimeError:  # an exactly zero pivot ("not quasi-definite")
                raise DivergenceError(_SINGULAR) from None
            self._full.data[:] = data  # for the residual check in solve
        elif self.backend == "supernodal":
            if self._factor is None:  # ordering + analysis, once per pattern
                self._factor = SupernodalCholesky(
                    self.indptr, self.indices, self.size, blocks=self._blocks
                )
            self._factor.factor(data)
        elif self.backend == "cholmod":
            import cvxopt
            from cvxopt import cholmod

            values = cvxopt.matrix(data[self._lower])
            try:
                if self._factor is None:  # ordering + symbolic analysis, once per pattern
                    col = np.repeat(np.arange(self.size, dtype=np.int32), np.diff(self.indptr))
                    self._matrix = cvxopt.spmatrix(
                        values,
                        cvxopt.matrix(self.indices[self._lower]),
                        cvxopt.matrix(col[self._lower]),
                        (self.size, self.size),
                    )
                    self._factor = cholmod.symbolic(self._matrix)
                else:  # same pattern, same (CSC) order of the values: numeric only
                    self._matrix.V = values
                cholmod.numeric(self._matrix, self._factor)
            except ArithmeticError:  # "not positive definite"
                raise DivergenceError(_SINGULAR) from None
        else:
            try:
                self._factor = spla.splu(
                    sp.csc_matrix((data, self.indices, self.indptr), shape=self._full.shape),
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True},
                )
            except RuntimeError:  # an exactly zero pivot
                raise DivergenceError(_SINGULAR) from None

    def solve(self, rhs: Array) -> Array:
        """``A⁻¹ rhs`` with the last factorisation; ``rhs`` of shape ``(n,)`` or ``(n, k)``."""
        if self._factor is None:
            raise RuntimeError("SparseCholesky.solve before factor")
        b = np.ascontiguousarray(rhs, dtype=np.float64)
        if self.backend == "cholmod":
            import cvxopt
            from cvxopt import cholmod

            x = cvxopt.matrix(np.asfortranarray(b))
            cholmod.solve(self._factor, x)
            return np.array(x).reshape(b.shape)
        if self.backend != "qdldl":  # SuperLU, supernodal
            return self._factor.solve(b)
        if b.ndim == 2:
            x = np.column_stack([self._factor.solve(b[:, k]) for k in range(b.shape[1])])
        else:
            x = self._factor.solve(b)
        # QDLDL's refactorisation stops silently at an exactly zero pivot and leaves a
        # stale factor: a backward-stable solve has a residual near rounding, that one not
        a = self._full
        scale = np.abs(a.data).max() * np.abs(x).sum(axis=0) + np.abs(b).sum(axis=0)
        if not (np.abs(a @ x - b).sum(axis=0) <= 1e-8 * scale).all():
            raise DivergenceError(_SINGULAR)
        return x
