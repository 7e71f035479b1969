"""slamrel.backends.sparse_cholesky: every back-end against dense numpy solves, the
fixed-pattern refactorisation, singular matrices, the back-end choice and the fallback."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_estimation_graph import small_world

from relation_metric.errors import DivergenceError
from slamrel.backends import sparse_cholesky
from slamrel.backends.least_squares import _NormalEquations, solve_graph
from slamrel.backends.sparse_cholesky import SparseCholesky, choose_backend, factor_flops

BACKENDS = [
    b for b in ("qdldl", "supernodal", "cholmod", "superlu") if b in sparse_cholesky.BACKENDS
]


def random_spd_blocks(rng, n_blocks=40, n_edges=80):
    """A random SPD matrix with 3 × 3 and 2 × 2 blocks on a random block graph (a pose graph
    with landmarks): ``Σ_e B_eᵀ B_e`` over edges plus a small multiple of the identity."""
    size_of = rng.choice([2, 3], n_blocks)
    start = np.concatenate(([0], np.cumsum(size_of)))
    n = int(start[-1])
    a = np.zeros((n, n))
    for i, j in rng.integers(0, n_blocks, (n_edges, 2)):  # test set-up, not a hot path
        idx = np.r_[start[i] : start[i + 1], start[j] : start[j + 1]]
        b = rng.normal(size=(3, idx.size))
        a[np.ix_(idx, idx)] += b.T @ b
    return a + 0.1 * np.eye(n)


def pattern_of(a):
    """CSC pattern (both triangles, diagonal stored) of a dense symmetric matrix."""
    m = sp.csc_matrix(a)
    m.sort_indices()
    return m


@pytest.mark.parametrize("backend", BACKENDS)
def test_solves_equal_dense_solve_and_refactor_keeps_pattern(rng, backend):
    a = random_spd_blocks(rng)
    m = pattern_of(a)
    chol = SparseCholesky(m.indptr, m.indices, a.shape[0], backend=backend)
    assert chol.backend == backend
    col = np.repeat(np.arange(a.shape[0]), np.diff(m.indptr))
    for trial in range(3):  # D A D + t I: new numbers, same pattern (QDLDL: numeric only)
        d = rng.uniform(0.5, 2.0, a.shape[0])
        data = m.data * d[m.indices] * d[col] + trial * (m.indices == col)
        dense = sp.csc_matrix((data, m.indices, m.indptr), shape=a.shape).toarray()
        given = (m.indptr.copy(), m.indices.copy(), data.copy())
        chol.factor(data)
        for before, after in zip(given, (m.indptr, m.indices, data), strict=True):
            np.testing.assert_array_equal(after, before)  # the caller's arrays left alone
        b = rng.normal(size=a.shape[0])
        np.testing.assert_allclose(chol.solve(b), np.linalg.solve(dense, b), rtol=1e-9, atol=1e-12)
        bb = rng.normal(size=(a.shape[0], 4))
        np.testing.assert_allclose(
            chol.solve(bb), np.linalg.solve(dense, bb), rtol=1e-9, atol=1e-12
        )


@pytest.mark.parametrize("backend", BACKENDS)
def test_unsorted_rows_within_columns_solve_the_same(rng, backend):
    """A pattern whose row indices are not sorted inside each column (valid CSC) gives the
    dense solution, on the first factorisation and on a numeric refactorisation."""
    a = random_spd_blocks(rng, n_blocks=12, n_edges=20)
    m = pattern_of(a)
    n = a.shape[0]
    order = np.concatenate([np.arange(m.indptr[j], m.indptr[j + 1])[::-1] for j in range(n)])
    rows = m.indices[order]  # every column's rows reversed
    assert not np.array_equal(rows, m.indices)
    diagonal = rows == np.repeat(np.arange(n), np.diff(m.indptr))
    chol = SparseCholesky(m.indptr, rows, n, backend=backend)
    b = rng.normal(size=n)
    for shift in (0.0, 2.0):  # first factorisation, then a numeric refactorisation
        chol.factor(m.data[order] + shift * diagonal)
        expected = np.linalg.solve(a + shift * np.eye(n), b)
        np.testing.assert_allclose(chol.solve(b), expected, rtol=1e-9, atol=1e-12)


def test_sorted_rows_check_matches_the_sort(rng):
    """The check that lets a sorted pattern skip the sort answers as the sort would (its
    order is the identity), on random CSC patterns with empty and one-entry columns, rows
    falling across a column boundary, and a repeated row."""
    from slamrel.backends.sparse_cholesky import _sorted_rows

    seen = set()
    for _ in range(300):
        n = int(rng.integers(1, 6))
        counts = rng.integers(0, 4, n)
        indptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int32)
        rows = [np.sort(rng.choice(8, c, replace=False)) for c in counts]
        if rng.random() < 0.4 and indptr[-1] > 1:  # shuffle one column, or repeat a row
            j = int(rng.integers(n))
            rows[j] = rng.permutation(rows[j]) if rng.random() < 0.5 else np.full(counts[j], 3)
        indices = np.concatenate([*rows, np.empty(0, int)]).astype(np.int32)
        col = np.repeat(np.arange(n), counts)
        # strictly rising in every column <=> lexsort changes nothing and no row repeats
        expected = bool(
            np.array_equal(np.lexsort((indices, col)), np.arange(indices.size))
            and all(np.unique(r).size == r.size for r in rows)
        )
        assert _sorted_rows(indptr, indices) == expected
        seen.add(expected)
    assert seen == {True, False}
    # a drop across a column boundary is sorted: column 0 holds rows 0, 5; column 1 rows 1, 2
    assert _sorted_rows(np.array([0, 2, 4], np.int32), np.array([0, 5, 1, 2], np.int32))


@pytest.mark.parametrize("backend", BACKENDS)
def test_singular_matrix_is_a_divergence(backend):
    a = np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    m = pattern_of(a)
    singular = np.array([1.0, 1.0, 1.0, 1.0, 0.0])  # [[1, 1, 0], [1, 1, 0], [0, 0, 0]]
    dense = sp.csc_matrix((singular, m.indices, m.indptr), shape=(3, 3)).toarray()
    assert np.linalg.matrix_rank(dense) == 1
    chol = SparseCholesky(m.indptr, m.indices, 3, backend=backend)
    chol.factor(m.data)  # a good factorisation first: QDLDL then refactorises in place
    np.testing.assert_allclose(chol.solve(np.ones(3)), np.linalg.solve(a, np.ones(3)))
    with pytest.raises(DivergenceError, match="singular"):
        chol.factor(singular)
        chol.solve(np.array([1.0, 2.0, 3.0]))  # inconsistent: no solution exists
    chol.factor(m.data)  # LM's next, damped trial: the same object factorises again
    np.testing.assert_allclose(chol.solve(np.ones(3)), np.linalg.solve(a, np.ones(3)))
    with pytest.raises(DivergenceError, match="singular"):
        fresh = SparseCholesky(m.indptr, m.indices, 3, backend=backend)
        fresh.factor(singular)
        fresh.solve(np.array([1.0, 2.0, 3.0]))


def test_solve_before_factor_and_unknown_backend():
    m = pattern_of(np.eye(2))
    with pytest.raises(RuntimeError, match="before factor"):
        SparseCholesky(m.indptr, m.indices, 2).solve(np.ones(2))
    with pytest.raises(ValueError, match="unknown"):
        SparseCholesky(m.indptr, m.indices, 2, backend="umfpack")


@pytest.mark.parametrize("have", [("superlu",), ("qdldl", "superlu")])
def test_factor_flops_match_hand_counts(monkeypatch, have):
    """Tridiagonal: no fill in any minimum-degree order (columns of 2, the last of 1);
    dense: columns of n, n-1, …, 1."""
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", have)
    n = 30
    tri = sp.diags([np.ones(n - 1), np.ones(n), np.ones(n - 1)], [-1, 0, 1])
    assert factor_flops(tri) == 4.0 * (n - 1) + 1.0
    k = 12
    assert factor_flops(sp.csc_matrix(np.ones((k, k)))) == k * (k + 1) * (2 * k + 1) / 6


def test_choose_backend(monkeypatch):
    monkeypatch.setattr(sparse_cholesky, "CHOLMOD_MIN_FLOPS", 1e7)
    monkeypatch.setattr(sparse_cholesky, "SUPERNODAL_MIN_FLOPS", 1e8)
    big, mid, small = 1e9, 3e7, 1e6
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", ("cholmod", "supernodal", "qdldl", "superlu"))
    assert [choose_backend(f) for f in (big, mid, small, None)] == [
        "cholmod",
        "cholmod",
        "qdldl",
        "qdldl",
    ]
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", ("supernodal", "qdldl", "superlu"))
    assert [choose_backend(f) for f in (big, mid, small, None)] == [
        "supernodal",
        "qdldl",
        "qdldl",
        "qdldl",
    ]
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", ("qdldl", "superlu"))
    assert choose_backend(big) == "qdldl"
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", ("superlu",))
    assert choose_backend(big) == choose_backend(None) == "superlu"
    assert sparse_cholesky.available_backends()[-1] == "superlu"


@pytest.mark.parametrize(
    ("have", "min_flops", "expected"),
    [
        (("superlu",), None, "superlu"),  # neither library installed: the fallback
        (("qdldl", "superlu"), None, "qdldl"),
        (("cholmod", "qdldl", "superlu"), 0.0, "cholmod"),
        (("supernodal", "qdldl", "superlu"), 0.0, "supernodal"),
    ],
)
def test_least_squares_same_minimum_on_every_backend(rng, monkeypatch, have, expected, min_flops):
    """The back-end is picked when the normal equations are built (the installed libraries
    patched); every one reaches the default's minimum to rounding."""
    if expected != "superlu" and expected not in sparse_cholesky.available_backends():
        pytest.skip(f"{expected} not installed")
    g, _, _ = small_world(rng, n=40, m=8)
    reference = solve_graph(g)
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", have)
    if min_flops is not None:
        monkeypatch.setattr(sparse_cholesky, "CHOLMOD_MIN_FLOPS", min_flops)
        monkeypatch.setattr(sparse_cholesky, "SUPERNODAL_MIN_FLOPS", min_flops)
    normal = _NormalEquations(g, g.n_poses, g.n_landmarks)
    assert normal.cholesky.backend == expected
    perm_is_identity = bool((normal.perm == np.arange(normal.size)).all())
    assert perm_is_identity == (expected != "superlu")  # block order only for SuperLU
    got = solve_graph(g)
    assert got.converged and reference.converged
    np.testing.assert_allclose(got.poses, reference.poses, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.landmarks, reference.landmarks, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.cost[-1], reference.cost[-1], rtol=1e-9)


def test_available_backends_follow_the_installed_libraries(monkeypatch):
    """Libraries that do not import are not offered; SuperLU (scipy) always is."""
    import importlib.util

    for missing, expected in (
        ({"cvxopt", "qdldl"}, ("superlu",)),
        ({"cvxopt"}, ("supernodal", "qdldl", "superlu")),
        ({"qdldl"}, ("cholmod", "superlu")),  # the supernodal back-end orders with QDLDL
        (set(), ("cholmod", "supernodal", "qdldl", "superlu")),
    ):
        found = object()  # stands for a module spec
        monkeypatch.setattr(
            importlib.util,
            "find_spec",
            lambda name, *a, m=missing, f=found: None if name in m else f,
        )
        assert sparse_cholesky.available_backends() == expected


# --- the supernodal back-end (slamrel.backends.supernodal) ---------------------------------

NO_AMALGAMATION = (0, 0.0, 0, 0.0, 0, 0.0)
EVERYTHING_MERGED = (10**9, 1.01, 10**9, 1.01, 10**9, 1.01)


def structural_entries(a, perm):
    """Entries of ``L`` (diagonal included) of the pattern of ``a`` eliminated in the order
    ``perm``: the graph model of Gaussian elimination on a dense boolean matrix (every
    pair of a pivot's later neighbours becomes adjacent)."""
    p = (a != 0)[np.ix_(perm, perm)]
    count = 0
    for j in range(len(perm)):  # an oracle on small matrices, not a hot path
        rows = np.flatnonzero(p[j:, j]) + j
        count += rows.size
        p[np.ix_(rows[1:], rows[1:])] = True
    return count


@pytest.mark.parametrize("relax", [NO_AMALGAMATION, None, EVERYTHING_MERGED])
def test_supernodal_equals_dense_cholesky_on_block_patterns(rng, relax):
    """Random SPD matrices on block graphs with much fill (poses' 3 × 3 and landmarks'
    2 × 2 blocks): the solution equals scipy's dense Cholesky solve, for new values in the
    same pattern too; without amalgamation ``L`` stores exactly the structural nonzeros of
    the elimination in its order, with everything merged one supernode per component."""
    from scipy.linalg import cho_factor, cho_solve

    from slamrel.backends.supernodal import RELAX, SupernodalCholesky

    a = random_spd_blocks(rng, n_blocks=120, n_edges=260)
    m = pattern_of(a)
    n = a.shape[0]
    chol = SupernodalCholesky(m.indptr, m.indices, n, relax=RELAX if relax is None else relax)
    components = sp.csgraph.connected_components(m, directed=False)[0]
    if relax == NO_AMALGAMATION:
        assert chol.entries == structural_entries(a, chol.perm)
        assert chol.n_supernodes > components
    elif relax == EVERYTHING_MERGED:
        assert chol.n_supernodes == components
    else:
        assert components < chol.n_supernodes < n
    col = np.repeat(np.arange(n), np.diff(m.indptr))
    for trial in range(3):
        d = rng.uniform(0.5, 2.0, n)
        data = m.data * d[m.indices] * d[col] + trial * (m.indices == col)
        dense = sp.csc_matrix((data, m.indices, m.indptr), shape=a.shape).toarray()
        chol.factor(data)
        b = rng.normal(size=(n, 3))
        expected = cho_solve(cho_factor(dense, lower=True), b)
        np.testing.assert_allclose(chol.solve(b), expected, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(chol.solve(b[:, 0]), expected[:, 0], rtol=1e-9, atol=1e-12)


def test_supernodal_refuses_an_indefinite_matrix(rng):
    """Nonsingular but indefinite (the lowest eigenvalues shifted below zero, none to zero):
    DivergenceError, like CHOLMOD (QDLDL would solve it as an LDLᵀ); the next positive
    definite values factorise again."""
    a = random_spd_blocks(rng, n_blocks=30, n_edges=60)
    m = pattern_of(a)
    n = a.shape[0]
    eig = np.linalg.eigvalsh(a)
    above = eig[eig > eig[0] * (1 + 1e-6)][0]
    shift = 0.5 * (eig[0] + above)  # between two distinct eigenvalues: a nonsingular A − sI
    assert (eig < shift).any() and np.abs(eig - shift).min() > 1e-6
    col = np.repeat(np.arange(n), np.diff(m.indptr))
    chol = SparseCholesky(m.indptr, m.indices, n, backend="supernodal")
    with pytest.raises(DivergenceError, match="not positive definite"):
        chol.factor(m.data - shift * (m.indices == col))
    with pytest.raises(RuntimeError, match="before factor"):
        chol.solve(np.ones(n))  # no stale factor is used
    chol.factor(m.data)
    np.testing.assert_allclose(chol.solve(np.ones(n)), np.linalg.solve(a, np.ones(n)), rtol=1e-9)


def _manhattan():  # type: ignore[no-untyped-def]
    """benchmarks/bench_least_squares.py's Manhattan-world pose graph generator."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_least_squares.py"
    spec = importlib.util.spec_from_file_location("bench_least_squares_for_tests", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module.manhattan


def test_least_squares_on_a_manhattan_graph_same_on_every_backend(monkeypatch):
    """A 600-pose Manhattan graph (loop closures on a grid: much fill) solved with the
    supernodal back-end and with QDLDL (and CHOLMOD, when installed): the same minimum."""
    g = _manhattan()(600, size=12)
    monkeypatch.setattr(sparse_cholesky, "SUPERNODAL_MIN_FLOPS", 0.0)
    monkeypatch.setattr(sparse_cholesky, "CHOLMOD_MIN_FLOPS", 0.0)
    results = {}
    for have in (("supernodal", "qdldl", "superlu"), ("qdldl", "superlu"), ("cholmod", "qdldl")):
        if have[0] not in sparse_cholesky.available_backends():
            continue
        monkeypatch.setattr(sparse_cholesky, "BACKENDS", have)
        got = solve_graph(g)
        assert got.linear_solver == have[0] and got.converged
        results[have[0]] = got
    assert {"supernodal", "qdldl"} <= results.keys()
    reference = results.pop("qdldl")
    for got in results.values():
        assert got.iterations == reference.iterations
        np.testing.assert_allclose(got.poses, reference.poses, rtol=0, atol=1e-9)
        np.testing.assert_allclose(got.cost, reference.cost, rtol=1e-9)


@pytest.mark.parametrize("width", [1, 5])
def test_supernodal_with_given_blocks_solves_the_same(rng, width):
    """Groups given instead of found: single columns, or groups of 5 that cut across the
    matrix's 2 × 2 and 3 × 3 blocks (each group then stands for the union of its columns'
    patterns: more fill, the same solution)."""
    from slamrel.backends.supernodal import SupernodalCholesky

    a = random_spd_blocks(rng, n_blocks=60, n_edges=120)
    m = pattern_of(a)
    n = a.shape[0]
    blocks = np.full(n // width, width)
    blocks[-1] += n - blocks.sum()
    found = SupernodalCholesky(m.indptr, m.indices, n)
    given = SupernodalCholesky(m.indptr, m.indices, n, blocks=blocks)
    b = rng.normal(size=n)
    for chol in (found, given):
        chol.factor(m.data)
        np.testing.assert_allclose(chol.solve(b), np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="summing to"):
        SupernodalCholesky(m.indptr, m.indices, n, blocks=blocks[:-1])
