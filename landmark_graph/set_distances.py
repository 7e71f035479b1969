"""OSPA and GOSPA: distances between two finite point sets, such as two landmark maps.

For point sets X = {x_1, …, x_m} and Y = {y_1, …, y_n} with ``m ≤ n`` (else swap them),
cut-off ``c > 0``, order ``p ≥ 1`` and ``d^(c)(x, y) = min(‖x − y‖, c)``, over the
assignments π of X's points to distinct points of Y:

    OSPA  = ( (1/n) [ min_π Σ_i d^(c)(x_i, y_π(i))^p + c^p (n − m) ] )^(1/p)
    GOSPA = ( min_π Σ_i d^(c)(x_i, y_π(i))^p + (c^p / 2) (n − m) )^(1/p)

OSPA is Schuhmacher, Vo & Vo, "A consistent metric for performance evaluation of
multi-object filters", IEEE Trans. Signal Processing 56(8), 2008: the mean
per-point error, each missing or extra point counted at the cut-off ``c``; 0 for two empty
sets. GOSPA is Rahmathullah, García-Fernández & Svensson, "Generalized optimal sub-pattern
assignment metric", FUSION 2017, with α = 2: not divided by ``n``, so that it grows
with every localisation error, missed and false point (each of the latter costs
``c^p / 2``; a pair farther than ``c`` costs ``c^p``, as one missed and one false point).

The assignment is computed on ``min(d, c)^p`` — not on ``min(d, c)``, which is only the same
problem for ``p = 1``: densely (``scipy.optimize.linear_sum_assignment``) up to
:data:`DENSE_ASSIGNMENT_PAIRS` pairs, beyond on the pairs closer than ``c`` only
(:func:`landmark_graph.matching.sparse_matching`), which has the same optimum. The sums are
formed in units of ``c`` and in logarithms, so that a large order ``p`` neither overflows
``c^p`` nor underflows ``(d/c)^p`` to 0.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from landmark_graph.matching import sparse_matching
from relation_metric.errors import InputError

__all__ = ["ospa", "gospa", "DENSE_ASSIGNMENT_PAIRS"]

#: OSPA and GOSPA solve the dense ``m × n`` assignment up to this many pairs (32 MB of
#: distances; the results of all earlier versions, bit for bit) and the sparse one on the
#: pairs within the cut-off beyond (20,000 landmarks a side: 3.2 GB dense per matrix).
DENSE_ASSIGNMENT_PAIRS = 4_000_000


def _optimal_terms(
    x: NDArray[np.float64], y: NDArray[np.float64], c: float, p: float
) -> tuple[NDArray[np.float64], int, int]:
    """``p · log(min(d, c)/c)`` of the pairs of the optimal assignment, and ``m ≤ n``.

    The distances are scaled by the cut-off, ``u = min(d, c)/c ∈ [0, 1]``: the assignment
    minimises ``Σ (u/u_max)^p`` (``u_max`` the largest ``u`` of the matrix; the order of the
    costs is that of ``Σ min(d, c)^p``, the factor ``(c u_max)^p`` is common), and the sums of
    OSPA/GOSPA are formed from the logarithms (:func:`_log_sum_exp`). So a large order ``p``
    does not underflow ``u^p`` to 0 and report two different maps as equal.
    """
    if not (np.isfinite(c) and c > 0):
        raise InputError(f"the OSPA/GOSPA cut-off c must be a positive number, got {c}")
    if not (np.isfinite(p) and p >= 1):
        raise InputError(f"the OSPA/GOSPA order p must be a number ≥ 1, got {p}")
    if x.shape[0] > y.shape[0]:
        x, y = y, x
    m, n = x.shape[0], y.shape[0]
    if m == 0:
        return np.empty(0), m, n
    if m * n > DENSE_ASSIGNMENT_PAIRS:
        # large sets: only pairs closer than c can cost less than c^p (_within_cutoff_terms)
        return _within_cutoff_terms(x, y, c, p), m, n
    d = np.hypot(x[:, None, 0] - y[None, :, 0], x[:, None, 1] - y[None, :, 1])
    u = np.minimum(d, c) / c
    top = float(u.max())
    if top == 0.0:
        return np.full(m, -np.inf), m, n
    r, s = linear_sum_assignment((u / top) ** p)
    with np.errstate(divide="ignore"):
        return p * np.log(u[r, s]), m, n


def _within_cutoff_terms(
    x: NDArray[np.float64], y: NDArray[np.float64], c: float, p: float
) -> NDArray[np.float64]:
    """The terms of :func:`_optimal_terms` (``|x| ≤ |y|``) from the pairs closer than ``c``.

    A full assignment's pairs at ``d ≥ c`` cost ``c^p`` each, as an unassigned ``x`` would;
    and a partial matching on pairs closer than ``c`` completes (``|x| ≤ |y|``) to a full
    assignment whose added pairs cost at most ``c^p`` each. So the optimum is the min-weight
    partial matching on the within-``c`` pairs with ``d^p`` per pair and ``c^p`` per
    unmatched ``x`` (an unmatched ``y`` costs nothing): a sparse problem of ``O(m + n +
    pairs)`` memory, solved by :func:`~landmark_graph.matching.sparse_matching` (the full
    matching of its square augmentation). Each unmatched ``x`` gives the term 0 (``u = 1``).
    """
    # in units of c: the costs u^p ≤ 1 and 1 per unmatched x cannot overflow for any p
    er, rr, u = sparse_matching(x / c, y / c, 1.0, power=p, cost_x=1.0, cost_y=0.0)
    with np.errstate(divide="ignore"):
        matched = p * np.log(np.minimum(u, 1.0))
    return np.concatenate((matched, np.zeros(x.shape[0] - er.size)))


def _log_sum_exp(terms: NDArray[np.float64]) -> float:
    """``log Σ exp(terms)`` without overflow or underflow (−inf for no or only −inf terms)."""
    if terms.size == 0:
        return -np.inf
    top = float(terms.max())
    if not np.isfinite(top):
        return top
    return top + float(np.log(np.exp(terms - top).sum()))


def ospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """OSPA distance of two point sets (the formula is in the module docstring).

    Computed as ``c · ((1/n) Σ u^p)^(1/p)`` with ``u = min(d, c)/c`` (1 for each unmatched
    point) in logarithms: exact for any order ``p``, no underflow to 0.

    Parameters
    ----------
    x, y : array_like, shape (m, 2) and (n, 2)
        The two point sets [m] (either may be the larger, or empty).
    c : float
        The cut-off [m], > 0: the most one point's error or a missing point can count.
    p : float
        The order, ≥ 1.

    Returns
    -------
    float
        In metres, in ``[0, c]``; 0 when both sets are empty.

    Raises
    ------
    InputError
        ``c`` not a positive number or ``p`` not a number ≥ 1.
    """
    terms, m, n = _optimal_terms(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    if n == 0:
        return 0.0
    log_sum = _log_sum_exp(np.concatenate((terms, np.zeros(n - m))))
    return float(c * np.exp((log_sum - np.log(n)) / p))


def gospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """GOSPA distance with α = 2 (the formula is in the module docstring).

    Computed in units of ``c`` and in logarithms as :func:`ospa`. Parameters and errors as
    :func:`ospa`; the result is in metres, ≥ 0, and not bounded by ``c`` (it grows with the
    number of points).
    """
    terms, m, n = _optimal_terms(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    log_sum = _log_sum_exp(np.concatenate((terms, np.full(n - m, -np.log(2.0)))))
    return float(c * np.exp(log_sum / p))
