"""The one covariance check of slamrel: symmetric and positive semi-definite, one tolerance.

A matrix ``C`` (a covariance, or an information matrix) passes when it is finite and

* symmetric within ``t``: ``|C_ij − C_ji| ≤ t`` for all ``i, j``, and
* positive semi-definite within ``t``: ``C + t I`` is positive semi-definite (its smallest
  eigenvalue is ``≥ −t``),

with ``t = COV_RTOL · max_ij |C_ij|`` (relative to the matrix's own scale, so that units do
not matter; an all-zero matrix passes). With ``definite=True`` (a covariance that is
inverted) the smallest eigenvalue must be ``> t`` instead: zero and near-singular matrices
are refused.

Stacks of small blocks ``(N, k, k)`` (landmark marginals, edge information matrices) are
checked with one vectorised ``eigvalsh``; one big joint matrix (a bundle's
``map_covariance.npy``, up to a few thousand rows) with a Cholesky factorisation of
``C + t I`` (``(C + t I)`` positive definite ⇔ smallest eigenvalue ``> −t``; a third of the
work of an eigendecomposition).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.arrays import PathLike
from relation_metric.errors import InputError

__all__ = [
    "COV_RTOL",
    "MAX_INFORMATION",
    "check_covariances",
    "check_joint_covariance",
    "bad_covariances",
]

COV_RTOL = 1e-9
"""Relative tolerance of the symmetry and positive semi-definiteness checks."""


MAX_INFORMATION = 1e200
"""Largest information entry a graph file may state (a standard deviation of 1e-100).

A least-squares cost sums ``rᵀ Ω r`` over the edges; with residuals up to twice
:data:`~relation_metric.trajectory.MAX_COORDINATE` (1e30 m, so ``r² ≤ 4e60``) and up to 1e8
edges, ``Ω ≤ 1e200`` keeps every cost and normal-equation entry below float64's 1.8e308.
Beyond it the solver would overflow (a floating-point warning, then a singular system); the
same bound holds for the inverse of a filter's covariance in a NEES (``eᵀ Σ⁻¹ e``)."""


def bad_covariances(
    cov: ArrayLike,
    *,
    allow_unknown: bool = False,
    definite: bool = False,
    max_abs: float | None = None,
) -> tuple[NDArray[np.int64], list[str]]:
    """Blocks of ``cov`` (N, k, k) that fail the check, and why.

    Parameters
    ----------
    cov : array_like, shape (N, k, k)
    allow_unknown : bool
        An all-NaN block (a covariance the file left empty) passes.
    definite : bool
        Require positive definiteness (the matrix is inverted).
    max_abs : float, optional
        Refuse blocks with an entry beyond it in magnitude (e.g. :data:`MAX_INFORMATION`).

    Returns
    -------
    rows : ndarray of int, shape (B,)
        Indices of the failing blocks, in increasing order.
    reasons : list of str, length B
        What is wrong with each (for messages).
    """
    c = np.asarray(cov, dtype=np.float64)
    n = c.shape[0]
    if n == 0:
        return np.empty(0, np.int64), []
    flat = c.reshape(n, -1)
    nan = np.isnan(flat)
    unknown = nan.all(axis=1) if allow_unknown else np.zeros(n, dtype=bool)
    finite = np.isfinite(flat).all(axis=1)
    reasons: dict[int, str] = {}
    for k in np.flatnonzero(~finite & ~unknown).tolist():
        if allow_unknown and nan[k].any() and not nan[k].all():
            reasons[k] = "only partly given; expected all entries or none"
        else:
            reasons[k] = "expected finite values"
    ok = finite & ~unknown
    if max_abs is not None and ok.any():
        top = np.where(ok, np.abs(np.where(nan, 0.0, flat)).max(axis=1), 0.0)
        for k in np.flatnonzero(top > max_abs).tolist():
            reasons[k] = (
                f"an entry of {float(top[k]):.6g} is beyond {max_abs:.6g}, where sums of "
                "squares (a solve's cost, a NEES) overflow"
            )
        ok &= top <= max_abs
    if ok.any():
        idx = np.flatnonzero(ok)
        m = c[idx]
        scale = np.abs(m).reshape(idx.size, -1).max(axis=1)
        # Each block relative to its own scale (no overflow near the largest doubles); the
        # numbers in the messages are scaled back.
        unit = m / np.where(scale > 0, scale, 1.0)[:, None, None]
        tol = np.full(idx.size, COV_RTOL)
        asym = np.abs(unit - np.swapaxes(unit, 1, 2)).reshape(idx.size, -1).max(axis=1)
        low = np.linalg.eigvalsh(0.5 * (unit + np.swapaxes(unit, 1, 2)))[:, 0]
        with np.errstate(over="ignore"):
            asym_abs, low_abs, tol_abs = asym * scale, low * scale, tol * scale
        for j in np.flatnonzero(asym > tol).tolist():
            reasons[int(idx[j])] = (
                f"expected a symmetric matrix (entries differ by {float(asym_abs[j]):.6g}, "
                f"tolerance {float(tol_abs[j]):.3g})"
            )
        if definite:
            bad = np.flatnonzero((low <= tol) & (asym <= tol))
            for j in bad.tolist():
                reasons[int(idx[j])] = (
                    "expected a positive definite (invertible) matrix (smallest eigenvalue "
                    f"{float(low_abs[j]):.6g})"
                )
        else:
            bad = np.flatnonzero((low < -tol) & (asym <= tol))
            for j in bad.tolist():
                reasons[int(idx[j])] = (
                    "expected a positive semi-definite matrix (smallest eigenvalue "
                    f"{float(low_abs[j]):.6g}, tolerance {float(tol_abs[j]):.3g})"
                )
    rows = np.array(sorted(reasons), dtype=np.int64)
    return rows, [reasons[int(k)] for k in rows]


def check_covariances(
    cov: ArrayLike,
    *,
    path: PathLike | None = None,
    lines: Sequence[int] | NDArray[np.int64] | Callable[[int], int] | None = None,
    what: str | Callable[[int], str] = "covariance",
    allow_unknown: bool = False,
    definite: bool = False,
    max_abs: float | None = None,
) -> None:
    """Raise :class:`InputError` at the first block of ``cov`` (N, k, k) that fails.

    Parameters
    ----------
    cov : array_like, shape (N, k, k)
    path : str or PathLike, optional
        The file, for the message.
    lines : sequence of int or callable, optional
        The 1-based line of each block (``lines[k]`` or ``lines(k)``).
    what : str or callable
        What the block is (``"covariance"``), or a function of the block index (e.g.
        ``lambda k: f"landmark {ids[k]}: covariance"``).
    allow_unknown, definite, max_abs :
        See :func:`bad_covariances`.
    """
    rows, reasons = bad_covariances(
        cov, allow_unknown=allow_unknown, definite=definite, max_abs=max_abs
    )
    if rows.size == 0:
        return
    k = int(rows[0])
    line = None
    if lines is not None:
        line = int(lines(k) if callable(lines) else lines[k])
    name = what(k) if callable(what) else what
    c = np.asarray(cov, dtype=np.float64)[k]
    shown = (
        "[" + ", ".join("[" + ", ".join(f"{float(v):.6g}" for v in row) + "]" for row in c) + "]"
    )
    raise InputError(f"{name}: {reasons[0]}; got {shown}", path=path, line=line)


def check_joint_covariance(
    cov: NDArray[np.float64], *, path: PathLike | None = None, what: str = "covariance"
) -> None:
    """Raise :class:`InputError` when one big matrix ``cov`` (n, n) fails the check.

    Same rule and tolerance as :func:`check_covariances` (positive semi-definite), by a
    Cholesky factorisation of ``cov + t I`` instead of an eigendecomposition.
    """
    c = np.asarray(cov, dtype=np.float64)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise InputError(f"{what}: expected a square matrix, got shape {c.shape}", path=path)
    if c.size == 0:
        return
    if not np.isfinite(c).all():
        i, j = np.argwhere(~np.isfinite(c))[0].tolist()
        raise InputError(f"{what}: expected finite values (entry [{i}, {j}])", path=path)
    scale = float(np.abs(c).max())
    if scale == 0.0:
        return
    tol = COV_RTOL * scale
    unit = c / scale  # relative to its scale: no overflow near the largest doubles
    asym = np.abs(unit - unit.T)
    if float(asym.max()) > COV_RTOL:
        i, j = np.unravel_index(int(np.argmax(asym)), asym.shape)
        raise InputError(
            f"{what}: expected a symmetric matrix (entries [{i}, {j}] and [{j}, {i}] differ by "
            f"{float(asym[i, j]) * scale:.6g}, tolerance {tol:.3g})",
            path=path,
        )
    shifted = 0.5 * (unit + unit.T)
    shifted[np.diag_indices_from(shifted)] += COV_RTOL
    try:
        np.linalg.cholesky(shifted)
    except np.linalg.LinAlgError:
        raise InputError(
            f"{what}: expected a positive semi-definite matrix (an eigenvalue is below -{tol:.3g})",
            path=path,
        ) from None
