"""Supernodal multifrontal Cholesky ``A = L Lᵀ`` of a sparse SPD matrix, numpy + scipy only.

The ``"supernodal"`` back-end of :mod:`slamrel.backends.sparse_cholesky`, written from the
textbook algorithms (Liu 1990, "The role of elimination trees in sparse factorization";
Ashcraft & Grimes 1989, relaxed supernode amalgamation; Duff & Reid 1983 / Liu 1992, the
multifrontal method). The analysis (:class:`SupernodalCholesky` constructor) runs once per
pattern; :meth:`SupernodalCholesky.factor` is numeric only, and its work on every supernode
is three dense LAPACK/BLAS calls (``dpotrf``, ``dtrsm``, ``dsyrk``) and one extend-add
through index maps computed in the analysis:

1. *Supervariables.* Consecutive columns with identical patterns (the 3 columns of a pose,
   the 2 of a landmark) are one node of a compressed graph (checked entry by entry, not
   assumed).
2. *Ordering and elimination tree.* QDLDL's AMD ordering and its symbolic factor of the
   compressed graph (a numeric factorisation of a diagonally dominant matrix with its
   pattern: 1/27 of the scalar work for 3 × 3 blocks) give the block factor's pattern, its
   elimination tree (parent: first off-diagonal row of a column) and column counts. The
   tree is postordered (``scipy.sparse.csgraph.depth_first_order``, reversed).
3. *Fundamental supernodes*: a column joins the previous one when it is its parent and
   its column count is one less. *Relaxed amalgamation*: a child supernode is merged into
   its parent when the merged one stays small or the explicit zeros it adds stay a small
   fraction (:data:`RELAX`); the merged tree is postordered again so that every supernode's
   columns are consecutive.
4. *Multifrontal numeric factorisation*, children before parents: the frontal matrix ``F``
   of a supernode (its rows: its columns, then the rows below) receives its columns of
   ``A`` and the update matrices of its children (extend-add through precomputed flat
   indices), then ``L₁₁ = chol(F₁₁)``, ``L₂₁ = F₂₁ L₁₁⁻ᵀ`` and the update
   ``F₂₂ − L₂₁ L₂₁ᵀ`` for the parent. Only lower triangles are read (the upper ones hold
   stale values, never used).

A pivot that is not positive (``dpotrf``'s ``info > 0``) raises
:class:`~relation_metric.errors.DivergenceError`, as CHOLMOD does. The BLAS calls run on one
thread (OpenBLAS's thread-local setting, when scipy's OpenBLAS offers it): with many small
dense blocks the second thread's wake-ups cost more than it computes, and on a machine
whose cores are busy a two-thread call waits for a core (an order of magnitude slower on
2 shared cores). Timings: benchmarks/README.md (``bench_sparse_cholesky.py``).
"""

from __future__ import annotations

import ctypes
import glob
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg import blas, lapack
from scipy.sparse import csgraph

from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError

__all__ = ["RELAX", "SupernodalCholesky", "symbolic_factor"]

#: Relaxed amalgamation (Ashcraft & Grimes' rule, scalar columns): a child joins its parent
#: when the merged supernode has at most ``RELAX[0]`` columns and a fraction of explicit
#: zeros below ``RELAX[1]``, or at most ``RELAX[2]`` and ``RELAX[3]``, or at most
#: ``RELAX[4]`` and ``RELAX[5]``. Chosen on Manhattan 10⁴ (CPU ms per factorisation / solve,
#: 2026-12-02, ``bench_sparse_cholesky.py``'s matrix): CHOLMOD-like limits (8, 0.8, 32, 0.1,
#: 96, 0.05) gave 4,783 supernodes, 1.36·10⁹ flops, 143 / 31 ms (an earlier version of the
#: numeric phase); (24, 0.9, 64, 0.4, 160, 0.15) 1,275 supernodes, 1.51·10⁹ flops, 84 / 13.9;
#: these 642, 1.92·10⁹, 83 / 10.6 (less extend-add and fewer Python steps for the added
#: flops); (64, 0.95, 160, 0.6, 400, 0.3) 489, 2.18·10⁹, 99 / 10.0.
RELAX = (48, 0.9, 128, 0.5, 320, 0.25)

_NOT_PD = "the normal equations are singular or not positive definite (unobserved states?)"


def _openblas_local_threads() -> Any:
    """scipy's OpenBLAS ``openblas_set_num_threads_local``, or ``None`` when not found."""
    import scipy

    root = os.path.dirname(os.path.dirname(scipy.__file__))
    patterns = ("scipy.libs/*openblas*", "scipy/.dylibs/*openblas*")
    for path in sorted(p for pattern in patterns for p in glob.glob(os.path.join(root, pattern))):
        try:
            fn = ctypes.CDLL(path).openblas_set_num_threads_local
        except (OSError, AttributeError):
            continue
        fn.argtypes, fn.restype = [ctypes.c_int], ctypes.c_int
        return fn
    return None


_SET_LOCAL_THREADS = _openblas_local_threads()


@contextmanager
def _one_blas_thread() -> Iterator[None]:
    """Run scipy's BLAS on this thread only, inside the block (no-op if not settable)."""
    if _SET_LOCAL_THREADS is None:
        yield
        return
    before = _SET_LOCAL_THREADS(1)
    try:
        yield
    finally:
        _SET_LOCAL_THREADS(before)


_SCRATCH = threading.local()


def _scratch(name: str, size: int, dtype: type) -> NDArray[Any]:
    """A work array of at least ``size`` elements, kept for the thread's later calls (and
    later patterns: LM's growing graphs), first touched in order when (re)allocated."""
    have: NDArray[Any] | None = getattr(_SCRATCH, name, None)
    if have is None or have.size < size:
        have = np.zeros(max(size, 1), dtype=dtype)
        have.fill(0)
        setattr(_SCRATCH, name, have)
    return have


def _ranges(starts: NDArray[np.int64], widths: NDArray[np.int64]) -> NDArray[np.int64]:
    """``starts[i], …, starts[i] + widths[i] − 1`` for every ``i``, concatenated."""
    offsets = np.cumsum(widths) - widths
    total = int(widths.sum())
    return np.arange(total) - np.repeat(offsets - starts, widths)


def _supervariables(
    indptr: NDArray[np.int64], indices: NDArray[np.int64], n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Group of every column (runs of consecutive identical columns) and each group's first."""
    lens = np.diff(indptr)
    same = np.zeros(max(n - 1, 0), dtype=bool)
    cand = np.flatnonzero(lens[:-1] == lens[1:])
    if cand.size:
        ln = lens[cand]
        pos = _ranges(indptr[cand], ln)
        differ = indices[pos] != indices[pos + np.repeat(ln, ln)]
        seg = np.repeat(np.arange(cand.size), ln)
        same[cand[np.bincount(seg, weights=differ, minlength=cand.size) == 0]] = True
    new = np.concatenate(([True], ~same))
    return np.cumsum(new) - 1, np.flatnonzero(new)


def _block_factor(
    indptr: NDArray[np.int64],
    indices: NDArray[np.int64],
    n: int,
    blocks: NDArray[np.int64] | None,
) -> tuple[sp.csc_matrix, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The compressed graph's factor pattern (AMD order), that order (compressed node at each
    position), each node's first column and width. Nodes: the given ``blocks`` (widths of
    consecutive columns; a node's pattern is the union of its columns'), else runs of
    identical columns."""
    col = np.repeat(np.arange(n), np.diff(indptr))
    if blocks is None:
        group, gstart = _supervariables(indptr, indices, n)
        keep = np.isin(col, gstart)  # the first column of each group stands for the group
    else:
        gstart = np.cumsum(blocks) - blocks
        group = np.repeat(np.arange(gstart.size), blocks)
        keep = np.ones(col.size, dtype=bool)
    ng = gstart.size
    b = sp.csc_matrix(
        (np.ones(int(keep.sum())), (group[indices[keep]], group[col[keep]])), shape=(ng, ng)
    )
    lower, order = symbolic_factor(b)
    width = np.diff(np.append(gstart, n))
    return lower, order, gstart, width


#: the last :func:`symbolic_factor`: its pattern's key and result
_LAST_SYMBOLIC: list[Any] = [None, None]


def symbolic_factor(pattern: sp.spmatrix) -> tuple[sp.csc_matrix, NDArray[np.int64]]:
    """QDLDL's AMD order of a symmetric ``pattern`` (shape ``(n, n)``; values ignored, the
    diagonal optional) and the pattern of its factor ``L`` in that order.

    Returns
    -------
    lower : csc_matrix
        Strictly lower triangle of ``L`` in the new order (sorted rows).
    order : ndarray of int
        The original index at each new position.

    Notes
    -----
    QDLDL factorises a diagonally dominant matrix with the pattern (no pivot test needed).
    The last result is kept: :func:`~slamrel.backends.sparse_cholesky.factor_flops` on a
    block graph and the supernodal analysis of the same graph's scalar matrix ask for the
    same one (a second symbolic analysis per LM problem saved; benchmarks/README.md).
    """
    import qdldl

    a = sp.csc_matrix(pattern, dtype=np.float64, copy=True)
    a.data[:] = 1.0
    a = (a + sp.diags(np.asarray(abs(a).sum(axis=0)).ravel() + 1.0)).tocsc()
    upper = sp.triu(a, format="csc")
    upper.sort_indices()
    key = (upper.shape, upper.indptr.tobytes(), upper.indices.tobytes())
    if _LAST_SYMBOLIC[0] != key:
        lower, _, order = qdldl.Solver(upper, upper=True).factors()
        lower = sp.csc_matrix(lower)
        lower.sort_indices()
        _LAST_SYMBOLIC[:] = [key, (lower, np.asarray(order, dtype=np.int64))]
    result: tuple[sp.csc_matrix, NDArray[np.int64]] = _LAST_SYMBOLIC[1]
    return result


class SupernodalCholesky:
    """Analysis of one SPD pattern; :meth:`factor` and :meth:`solve` per matrix.

    Parameters
    ----------
    indptr, indices : array_like of int
        CSC pattern of the whole symmetric matrix (both triangles, sorted row indices, every
        diagonal entry stored).
    size : int
        ``n``.
    relax : tuple, optional
        Amalgamation limits (:data:`RELAX`).
    blocks : array_like of int, optional
        Widths of consecutive groups of columns that are eliminated together (3 per pose,
        2 per landmark); default: runs of identical columns, found. Either way the AMD
        ordering is of the graph of the groups.
    """

    def __init__(
        self,
        indptr: NDArray[np.integer],
        indices: NDArray[np.integer],
        size: int,
        *,
        relax: tuple[float, ...] = RELAX,
        blocks: NDArray[np.integer] | None = None,
    ) -> None:
        n = int(size)
        ip = np.asarray(indptr, dtype=np.int64)
        ix = np.asarray(indices, dtype=np.int64)
        self.size = n
        widths = None if blocks is None else np.asarray(blocks, dtype=np.int64)
        if widths is not None and (widths.sum() != n or (widths < 1).any()):
            raise ValueError(f"blocks of widths summing to {widths.sum()} for {n} columns")
        lb, p, gstart, width = _block_factor(ip, ix, n, widths)
        lb, order, w, parent = _postordered_tree(lb, p, width)
        sn = _supernodes(lb, parent, w, relax)
        ns = sn.parent.size
        w = w[sn.block_order]
        cw = np.concatenate(([0], np.cumsum(w)))
        bend = np.cumsum(sn.blocks)
        c0, c1 = cw[bend - sn.blocks], cw[bend]
        k = c1 - c0
        # --- scalar numbering and rows of every supernode -----------------------------------
        # the original column at each new position
        self.perm = _ranges(gstart[order[sn.block_order]], w)
        self.iperm = np.empty(n, dtype=np.int64)
        self.iperm[self.perm] = np.arange(n)
        self.below, rows, bsz = _front_rows(lb, sn, w, cw, c0, c1)
        m = k + bsz
        self.rel, self.children = _extend_add_rows(rows, self.below, sn.parent, bsz)
        self._src, self._fpos, self._aoff = _entry_positions(ip, ix, self.iperm, rows, k, m, c0)
        self.c0, self.c1, self.k, self.m = c0.tolist(), c1.tolist(), k.tolist(), m.tolist()
        self.n_supernodes = ns
        #: entries of ``L`` stored (explicit zeros of the amalgamation included)
        self.entries = int((k * bsz + k * (k + 1) // 2).sum())
        #: multiply-adds of the numeric factorisation (dense work on every front)
        self.flops = float((k * bsz**2 + k * k * bsz + k**3 / 3).sum())
        # --- storage, laid out once: L₁₁ and L₂₁ of every supernode in one array; the update
        # matrices on a stack (postorder: a supernode's children are the top of the stack)
        self._l_off = np.concatenate(([0], np.cumsum(k * m))).tolist()  # L₁₁ (k²), then L₂₁
        self._u_off, self._stack_size = _update_stack(self.children, bsz)
        self._front_size = int((m**2).max()) if ns else 0
        self._map_size = int((bsz**2).max()) if ns else 0
        self._l: Array | None = None  # L panels (column-major, m × k each), after factor()
        self._views: tuple[list[Array], list[Array | None]] | None = None
        self._factored = False

    def factor(self, data: Array) -> None:
        """Numeric factorisation with values ``data`` (in the constructor's pattern order)."""
        vals = np.asarray(data, dtype=np.float64)[self._src]
        fpos, aoff, rel, children = self._fpos, self._aoff, self.rel, self.children
        if self._l is None:  # every entry is written below, in storage order
            self._l = np.empty(self._l_off[-1])
            self._views = None
        frontbuf = _scratch("front", self._front_size, np.float64)
        stack = _scratch("stack", self._stack_size, np.float64)
        mapbuf = _scratch("map", self._map_size, np.int64)
        l11s, l21s = self._panels()
        u_off = self._u_off
        add, add_at, potrf, trsm, syrk = np.add, np.add.at, lapack.dpotrf, blas.dtrsm, blas.dsyrk
        self._factored = False
        with _one_blas_thread():
            for s, (m, k, l11, l21) in enumerate(zip(self.m, self.k, l11s, l21s, strict=True)):
                flat = frontbuf[: m * m]
                flat.fill(0.0)
                front = flat.reshape((m, m), order="F")
                flat[fpos[aoff[s] : aoff[s + 1]]] = vals[aoff[s] : aoff[s + 1]]
                for c in children[s]:
                    r = rel[c]
                    if r is not None:  # extend-add: U_c[i, j] into F[r_i, r_j]
                        b = r.size
                        e = mapbuf[: b * b]
                        # row-major (j, i) is column-major (i, j)
                        add(m * r[:, None], r[None, :], out=e.reshape((b, b)))
                        add_at(flat, e, stack[u_off[c] : u_off[c] + b * b])
                l11[:] = front[:k, :k]
                if potrf(l11, lower=1, clean=0, overwrite_a=1)[1] != 0:
                    raise DivergenceError(_NOT_PD)
                if l21 is not None:
                    b = m - k
                    l21[:] = front[k:, :k]
                    trsm(1.0, l11, l21, side=1, lower=1, trans_a=1, overwrite_b=1)
                    u = stack[u_off[s] : u_off[s] + b * b].reshape((b, b), order="F")
                    u[:] = front[k:, k:]
                    syrk(-1.0, l21, beta=1.0, c=u, lower=1, overwrite_c=1)
        self._factored = True

    def _panels(self) -> tuple[list[Array], list[Array | None]]:
        """Views of every supernode's ``L₁₁`` and ``L₂₁`` (``None`` at a root) in the storage."""
        if self._views is None:
            assert self._l is not None
            lbuf, off = self._l, self._l_off
            l11s: list[Array] = []
            l21s: list[Array | None] = []
            for s in range(self.n_supernodes):
                m, k = self.m[s], self.k[s]
                l11s.append(lbuf[off[s] : off[s] + k * k].reshape((k, k), order="F"))
                l21s.append(
                    lbuf[off[s] + k * k : off[s + 1]].reshape((m - k, k), order="F")
                    if m > k
                    else None
                )
            self._views = (l11s, l21s)
        return self._views

    def solve(self, rhs: Array) -> Array:
        """``A⁻¹ rhs`` with the last factorisation; ``rhs`` of shape ``(n,)`` or ``(n, k)``."""
        if self._l is None or not self._factored:
            raise RuntimeError("SupernodalCholesky.solve before factor")
        x = np.array(np.asarray(rhs, dtype=np.float64)[self.perm])
        below, c0, c1 = self.below, self.c0, self.c1
        l11s, l21s = self._panels()
        with _one_blas_thread():
            for s, (l11, l21) in enumerate(zip(l11s, l21s, strict=True)):  # L y = b
                y = lapack.dtrtrs(l11, x[c0[s] : c1[s]], lower=1)[0]
                x[c0[s] : c1[s]] = y
                if l21 is not None:
                    x[below[s]] -= l21 @ y
            for s in range(self.n_supernodes - 1, -1, -1):  # Lᵀ x = y
                l21 = l21s[s]
                xs = x[c0[s] : c1[s]]
                if l21 is not None:
                    xs = xs - l21.T @ x[below[s]]
                x[c0[s] : c1[s]] = lapack.dtrtrs(l11s[s], xs, lower=1, trans=1)[0]
        return x[self.iperm]


def _postordered_tree(
    lb: sp.csc_matrix, p: NDArray[np.int64], width: NDArray[np.int64]
) -> tuple[sp.csc_matrix, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The elimination tree of the block factor ``lb`` (``p``: its compressed node at each
    position, ``width``: each node's columns), postordered: children first, every subtree
    contiguous (``scipy.sparse.csgraph.depth_first_order``, reversed).

    Returns ``lb`` in the new order, the compressed node and the width of every block in it,
    and every block's parent (first row below the diagonal; the block count at a root).
    """
    ng = width.size
    cnt = np.diff(lb.indptr)
    parent = np.full(ng, ng)
    has = cnt > 0
    parent[has] = lb.indices[lb.indptr[:-1][has]]  # first row below the diagonal
    tree = sp.csr_matrix((np.ones(ng), (parent, np.arange(ng))), shape=(ng + 1, ng + 1))
    pre = csgraph.depth_first_order(tree, ng, directed=True, return_predecessors=False)
    post = np.asarray(pre[::-1][:-1], dtype=np.int64)  # children first, subtrees contiguous
    rank = np.empty(ng + 1, dtype=np.int64)
    rank[post] = np.arange(ng)
    rank[ng] = ng
    lb = sp.csc_matrix(lb[post][:, post])
    lb.sort_indices()
    order = p[post]  # compressed node of every block, in the new order
    return lb, order, width[order], rank[parent[post]]


class _Supernodes(NamedTuple):
    """The supernodes of a postordered block tree (:func:`_supernodes`), in postorder."""

    #: each supernode's parent supernode (−1 at a root)
    parent: NDArray[np.int64]
    #: the block (tree order) at each new position: every supernode's blocks consecutive
    block_order: NDArray[np.int64]
    #: each supernode's number of blocks
    blocks: NDArray[np.int64]
    #: each supernode's top member's last block (tree order): its rows below are the front's
    last: NDArray[np.int64]


def _supernodes(
    lb: sp.csc_matrix, parent: NDArray[np.int64], w: NDArray[np.int64], relax: tuple[float, ...]
) -> _Supernodes:
    """Fundamental supernodes of the postordered block factor ``lb`` (a column joins the
    previous one when it is its parent and its column count is one less), merged by relaxed
    amalgamation (:func:`_amalgamate`), then the merged tree postordered again so that every
    supernode's blocks are consecutive."""
    ng = parent.size
    cnt = np.diff(lb.indptr)
    below_w = np.bincount(np.repeat(np.arange(ng), cnt), weights=w[lb.indices], minlength=ng)
    # --- fundamental supernodes -------------------------------------------------------------
    j = np.arange(ng - 1)
    joins = (parent[:-1] == j + 1) & (cnt[:-1] == cnt[1:] + 1)
    new = np.concatenate(([True], ~joins))
    fstart = np.flatnonzero(new)
    fend = np.append(fstart[1:], ng) - 1
    nf = fstart.size
    fsn = np.cumsum(new) - 1
    fpar = np.where(parent[fend] < ng, fsn[np.minimum(parent[fend], ng - 1)], -1)
    cw = np.concatenate(([0], np.cumsum(w)))
    merged, kids = _amalgamate(
        (cw[fend + 1] - cw[fstart]).tolist(),
        below_w[fend].astype(np.int64).tolist(),
        fpar.tolist(),
        relax,
    )
    # --- postorder of the merged tree; every supernode's blocks made consecutive -------------
    tops = _postorder([f for f in range(nf) if fpar[f] < 0 and merged[f]], kids)
    ns = len(tops)
    sid = np.empty(nf, dtype=np.int64)
    sid[tops] = np.arange(ns)
    spar = np.full(ns, -1, dtype=np.int64)
    for f in tops:
        if kids[f]:
            spar[sid[kids[f]]] = sid[f]
    mem = np.array([m for f in tops for m in merged[f]], dtype=np.int64)
    nmem = np.array([len(merged[f]) for f in tops])
    block_order = _ranges(fstart[mem], fend[mem] - fstart[mem] + 1)
    nblk = np.bincount(
        np.repeat(np.arange(ns), nmem), weights=fend[mem] - fstart[mem] + 1, minlength=ns
    ).astype(np.int64)
    return _Supernodes(spar, block_order, nblk, fend[np.array(tops)])


def _front_rows(
    lb: sp.csc_matrix,
    sn: _Supernodes,
    w: NDArray[np.int64],
    cw: NDArray[np.int64],
    c0: NDArray[np.int64],
    c1: NDArray[np.int64],
) -> tuple[list[NDArray[np.int64]], list[NDArray[np.int64]], NDArray[np.int64]]:
    """Each supernode's scalar rows below its columns (new numbering, sorted), its front's
    rows (its columns ``c0 … c1 − 1``, then those), and how many rows are below.

    ``w`` and ``cw``: the blocks' widths in the new order and their cumulative sum.
    """
    ng, ns = w.size, sn.parent.size
    relabel = np.empty(ng, dtype=np.int64)
    relabel[sn.block_order] = np.arange(ng)
    start_b, len_b = lb.indptr[sn.last], np.diff(lb.indptr)[sn.last]
    brows = relabel[lb.indices[_ranges(start_b, len_b)]]
    owner = np.repeat(np.arange(ns), len_b)
    o = np.lexsort((brows, owner))
    brows = brows[o]
    below = _ranges(cw[brows], w[brows])
    bsz = np.bincount(np.repeat(owner, w[brows]), minlength=ns).astype(np.int64)
    boff = np.concatenate(([0], np.cumsum(bsz)))
    below_s = [below[boff[s] : boff[s + 1]] for s in range(ns)]
    rows = [np.concatenate((np.arange(c0[s], c1[s]), below_s[s])) for s in range(ns)]
    return below_s, rows, bsz


def _extend_add_rows(
    rows: list[NDArray[np.int64]],
    below: list[NDArray[np.int64]],
    parent: NDArray[np.int64],
    bsz: NDArray[np.int64],
) -> tuple[list[NDArray[np.int64] | None], list[list[int]]]:
    """Where a child's update matrix goes in its parent's front (its rows below, as row
    positions in the parent's front; ``None`` at a root or without rows below), and each
    supernode's children.

    The maps are kept as row positions: :meth:`SupernodalCholesky.factor` expands them to
    flat (column-major) positions in one reused array, because maps for every child (14·10⁶
    integers on Manhattan 10⁴) cost more in page faults when first written than their
    expansion at every factorisation.
    """
    ns = len(rows)
    rel: list[NDArray[np.int64] | None] = [None] * ns
    for s in range(ns):
        if parent[s] >= 0 and bsz[s]:
            rel[s] = np.searchsorted(rows[parent[s]], below[s])
    children: list[list[int]] = [[] for _ in range(ns)]
    for s, q in enumerate(parent.tolist()):
        if q >= 0:
            children[q].append(s)
    return rel, children


def _entry_positions(
    ip: NDArray[np.int64],
    ix: NDArray[np.int64],
    iperm: NDArray[np.int64],
    rows: list[NDArray[np.int64]],
    k: NDArray[np.int64],
    m: NDArray[np.int64],
    c0: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], list[int]]:
    """Where each entry of A's lower triangle (new numbering) goes in its front.

    Returns the entries' indices in A's pattern (``ip``, ``ix``) grouped by supernode, their
    flat (column-major) positions in their fronts (``k`` columns, ``m`` rows, first column
    ``c0``), and each supernode's first entry in that grouping (one more: the end).
    """
    n, ns = iperm.size, len(rows)
    col = np.repeat(np.arange(n), np.diff(ip))
    pi, pj = iperm[ix], iperm[col]
    low = np.flatnonzero(pi >= pj)
    owner_e = np.repeat(np.arange(ns), k)[pj[low]]
    roff = np.concatenate(([0], np.cumsum(m)))
    keys = np.concatenate(rows) + np.repeat(np.arange(ns), m) * n
    local_row = np.searchsorted(keys, owner_e * n + pi[low]) - roff[owner_e]
    fpos = local_row + m[owner_e] * (pj[low] - c0[owner_e])
    o = np.argsort(owner_e, kind="stable")
    return low[o], fpos[o], np.searchsorted(owner_e[o], np.arange(ns + 1)).tolist()


def _update_stack(children: list[list[int]], bsz: NDArray[np.int64]) -> tuple[list[int], int]:
    """Each supernode's update matrix's offset on one stack, and the stack's size: in
    postorder a supernode's children are the top of the stack, popped when it is formed."""
    ns = len(children)
    u_off = [0] * ns
    top, depth = 0, 0
    for s in range(ns):
        if children[s]:
            top = u_off[children[s][0]]  # pops every child
        u_off[s] = top
        top += int(bsz[s]) ** 2
        depth = max(depth, top)
    return u_off, depth


def _amalgamate(
    k: list[int], below: list[int], parent: list[int], relax: tuple[float, ...]
) -> tuple[list[list[int]], list[list[int]]]:
    """Relaxed amalgamation of fundamental supernodes (columns ``k``, rows below ``below``,
    ``parent`` −1 at roots, children numbered before parents).

    Returns the members of each surviving supernode (empty for those merged away; a
    supernode keeps its number) and its children among the survivors.
    """
    n0, z0, n1, z1, n2, z2 = relax
    nf = len(k)
    kids: list[list[int]] = [[] for _ in range(nf)]
    for f, q in enumerate(parent):
        if q >= 0:
            kids[q].append(f)
    cols = list(k)
    zeros = [0] * nf
    entries = [c * b + c * (c + 1) // 2 for c, b in zip(cols, below, strict=True)]
    members = [[f] for f in range(nf)]
    survivors: list[list[int]] = [[] for _ in range(nf)]
    for p in range(nf):
        b = below[p]
        for c in sorted(kids[p], key=cols.__getitem__):  # narrow children first
            k2 = cols[p] + cols[c]
            e2 = k2 * b + k2 * (k2 + 1) // 2
            z = zeros[p] + zeros[c] + e2 - entries[p] - entries[c]
            frac = z / e2
            if (k2 <= n0 and frac < z0) or (k2 <= n1 and frac < z1) or (k2 <= n2 and frac < z2):
                cols[p], zeros[p], entries[p] = k2, z, e2
                members[p] = members[c] + members[p]  # the child's columns come first
                members[c] = []
                survivors[p].extend(survivors[c])
            else:
                survivors[p].append(c)
    return members, survivors


def _postorder(roots: list[int], kids: list[list[int]]) -> list[int]:
    """Children before parents, every subtree consecutive (iterative depth-first)."""
    out: list[int] = []
    stack = [(r, False) for r in reversed(roots)]
    while stack:
        f, done = stack.pop()
        if done:
            out.append(f)
            continue
        stack.append((f, True))
        stack.extend((c, False) for c in reversed(kids[f]))
    return out
