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

BACKENDS = [b for b in ("qdldl", "cholmod", "superlu") if b in sparse_cholesky.BACKENDS]


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
    big, small = 10 * sparse_cholesky.CHOLMOD_MIN_FLOPS, 0.1 * sparse_cholesky.CHOLMOD_MIN_FLOPS
    monkeypatch.setattr(sparse_cholesky, "BACKENDS", ("cholmod", "qdldl", "superlu"))
    assert [choose_backend(f) for f in (big, small, None)] == ["cholmod", "qdldl", "qdldl"]
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
        ({"cvxopt"}, ("qdldl", "superlu")),
        ({"qdldl"}, ("cholmod", "superlu")),
        (set(), ("cholmod", "qdldl", "superlu")),
    ):
        found = object()  # stands for a module spec
        monkeypatch.setattr(
            importlib.util,
            "find_spec",
            lambda name, *a, m=missing, f=found: None if name in m else f,
        )
        assert sparse_cholesky.available_backends() == expected
