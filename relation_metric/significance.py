"""Paired comparison of two error samples on the same relations, with dependence.

Two estimates scored on the same M relations give paired errors ``a_k``, ``b_k``; the
question is whether the mean difference ``d̄ = 1/M Σ (a_k − b_k)`` is more than chance.
Relations that share a stretch of the trajectory are not independent: the drift an estimate
accumulates between two poses enters every relation that spans them, so M overlapping
relations carry far less evidence than M independent pairs, and a test that treats them as
independent (the Wilcoxon signed-rank test on the pairs) rejects a true null most of the
time (``tests/test_compare_dependence.py`` shows it on simulated estimates).

Here the differences, ordered by the start time of their relation, are resampled with the
**circular block bootstrap** (Politis & Romano, "A circular block-resampling procedure for
stationary data", 1992): a resample is ``⌈M/L⌉`` blocks of ``L`` consecutive differences,
each starting at a uniformly drawn relation and wrapping round the end, cut to M. Blocks keep
the dependence between neighbouring relations; wrapping gives every relation the same weight,
so the resampled means are centred on ``d̄`` exactly.

**Block length** (relations per block), the largest of three:

- ``⌈3 (m̄ + 1)⌉`` with ``m̄`` the mean number of later relations (in start order) whose time
  interval ``[min(t1, t2), max(t1, t2)]`` meets a relation's own: the range of the
  dependence that overlap makes (drift enters overlapping relations together). Three times
  that range keeps the variance the blocks lose across their boundaries small: for a
  correlation falling linearly to 0 at lag m, blocks of L lose about ``m / (3 L)`` of it;
- the automatic length of Politis & White ("Automatic block-length selection for the
  dependent bootstrap", 2004, with the correction of Patton, Politis & White 2009) from the
  autocorrelation of the differences, for dependence that overlap does not show (errors
  correlated in time beyond a relation's own span);
- ``⌈M^(1/3)⌉``, the rate of the MSE-optimal block length, as a floor.

With fewer than :data:`MIN_BLOCKS` blocks the relations hold too few independent stretches
for a test (loop and global relations, each spanning much of the run, overlap one another
nearly everywhere): no p-value and no interval are given, and the result says why.

**Statistics** from ``B`` resampled means ``d̄*_b`` of the centred differences
``c_k = d_k − d̄`` (so ``d̄*_b`` is distributed as ``d̄ − μ``):

- two-sided p-value for ``μ = 0``: ``p = (1 + #{b : |d̄*_b| ≥ |d̄|}) / (B + 1)`` — never 0;
  its smallest value ``1 / (B + 1)`` means "below 1/B" (:attr:`PairedDifference.p_at_floor`);
- symmetric confidence interval ``d̄ ± h``, ``h`` the ``confidence`` quantile of ``|d̄*_b|``:
  it excludes 0 exactly when ``p`` is below ``1 − confidence`` (up to the resolution 1/B).

A resample's mean is a sum of block sums, each one difference of prefix sums of the
circularly extended series, so the work is ``B ⌈M/L⌉`` look-ups, vectorised over resamples
(in chunks that bound the memory), with no loop over resamples or relations.

**Many tests at once.** A table of comparisons makes one test per pair of algorithms,
relation set and part; :func:`holm_adjust` adjusts their p-values together (Holm 1979), so
that the chance of any false "significant" in the table stays below α, whatever the
dependence between the tests (they share relations and results).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.constants import BOOTSTRAP_RESAMPLES, MIN_BLOCKS, OVERLAP_FACTOR
from relation_metric.errors import InputError

__all__ = [
    "DEFAULT_RESAMPLES",
    "MIN_BLOCKS",
    "OVERLAP_FACTOR",
    "BlockLength",
    "PairedDifference",
    "block_length",
    "circular_block_means",
    "holm_adjust",
    "paired_difference",
    "politis_white_block_length",
]

DEFAULT_RESAMPLES = BOOTSTRAP_RESAMPLES
"""Bootstrap resamples ``B``: the p-value's resolution is ``1/(B + 1) = 10⁻⁴``."""

_CHUNK = 1 << 21
"""Block look-ups per vectorised step (16 MiB of int64 indices)."""


@dataclass(frozen=True)
class BlockLength:
    """The block length of :func:`block_length` and the three rules behind it.

    Attributes
    ----------
    length : int
        ``L``, relations per block: the largest of the three below (at most M).
    overlap : float
        ``m̄``: the mean number of later relations whose interval meets a relation's own.
    from_overlap, from_autocorrelation, floor : int
        ``⌈3 (m̄ + 1)⌉``, ``⌈b̂⌉`` of Politis & White, ``⌈M^(1/3)⌉``.
    blocks : float
        ``M / L``.
    """

    length: int
    overlap: float
    from_overlap: int
    from_autocorrelation: int
    floor: int
    blocks: float


@dataclass(frozen=True)
class PairedDifference:
    """The mean paired difference ``A − B`` and its block-bootstrap test.

    Attributes
    ----------
    n : int
        Relations M.
    mean_a, mean_b : float
        Mean errors of A and B (the unit of the errors).
    mean_difference : float
        ``d̄ = mean_a − mean_b``; negative: A has the smaller errors.
    ci_low, ci_high : float
        The ``confidence`` interval of the mean difference (NaN without a test).
    confidence : float
    p_value : float
        Two-sided bootstrap p-value of "no difference in the means" (NaN without a test).
    exceedances : int
        ``#{b : |d̄*_b| ≥ |d̄|}`` (0: :attr:`p_at_floor`; −1 without a test).
    resamples : int
        ``B``.
    block : BlockLength
    tested : bool
        False when the relations form fewer than :data:`MIN_BLOCKS` blocks.
    reason : str
        Why there is no test ("" when there is one).
    """

    n: int
    mean_a: float
    mean_b: float
    mean_difference: float
    ci_low: float
    ci_high: float
    confidence: float
    p_value: float
    exceedances: int
    resamples: int
    block: BlockLength
    tested: bool
    reason: str = ""

    @property
    def p_at_floor(self) -> bool:
        """No resample reached ``|d̄|``: the p-value is below ``1/B`` (shown so, never 0)."""
        return self.tested and self.exceedances == 0

    @property
    def relative_difference(self) -> float:
        """``100 (mean_a − mean_b) / mean_b`` in percent of B's mean (NaN when it is 0)."""
        if self.mean_b == 0.0:
            return float("nan")
        return 100.0 * self.mean_difference / self.mean_b


def _overlap_range(first: NDArray[np.float64], second: NDArray[np.float64]) -> float:
    """``m̄``: mean count of later relations (by start, then end) meeting each interval."""
    start, end = np.minimum(first, second), np.maximum(first, second)
    order = np.lexsort((end, start))
    s, e = start[order], end[order]
    last = np.searchsorted(s, e, side="right") - 1  # the last relation starting by my end
    return float(np.mean(last - np.arange(s.size)))


def politis_white_block_length(x: ArrayLike) -> float:
    """The automatic circular-block length of Politis & White (2004), corrected (2009).

    With ``R̂(k)`` the sample autocovariances of ``x`` (divisor n) and ``ρ̂(k) = R̂(k)/R̂(0)``:
    ``m̂`` is the smallest ``m`` such that ``|ρ̂(m + j)| < 2 sqrt(log₁₀ n / n)`` for
    ``j = 1 .. K``, ``K = max(5, ⌈sqrt(log₁₀ n)⌉)`` (searched up to ``⌈sqrt n⌉ + K``);
    ``M = 2 m̂``; with the flat-top window ``λ(t) = min(1, 2 (1 − |t|))⁺``,
    ``Ĝ = Σ_{|k|≤M} λ(k/M) |k| R̂(k)``, ``ĝ = Σ_{|k|≤M} λ(k/M) R̂(k)``, ``D̂ = 4/3 ĝ²`` and
    ``b̂ = (2 Ĝ² / D̂)^(1/3) n^(1/3)``, clipped to ``[1, min(3 sqrt n, n / 3)]``.

    Parameters
    ----------
    x : array_like, shape (n,)
        A series in time order.

    Returns
    -------
    float
        ``b̂`` (1 for fewer than 4 values or a constant series).
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    n = v.size
    if n < 4:
        return 1.0
    c = v - v.mean()
    if not np.any(c):
        return 1.0
    log_n = math.log10(n)
    k_n = max(5, math.ceil(math.sqrt(log_n)))
    m_max = min(math.ceil(math.sqrt(n)) + k_n, n - 1)
    spectrum = np.fft.rfft(c, 2 * n)  # zero-padded: the circular products are the linear ones
    acov = np.fft.irfft(spectrum * np.conj(spectrum), 2 * n)[: m_max + 1] / n
    rho = acov[1:] / acov[0]  # lags 1 .. m_max
    small = (np.abs(rho) < 2.0 * math.sqrt(log_n / n)).astype(np.int64)
    runs = np.convolve(small, np.ones(k_n, dtype=np.int64), mode="valid")  # run m: lags m+1..
    hits = np.flatnonzero(runs == k_n)
    m_hat = int(hits[0]) if hits.size else m_max
    big_m = min(2 * m_hat, m_max)
    if big_m == 0:
        return 1.0
    k = np.arange(1, big_m + 1)
    lam = np.minimum(1.0, 2.0 * (1.0 - k / big_m))
    g = 2.0 * np.sum(lam * k * acov[1 : big_m + 1])
    g0 = acov[0] + 2.0 * np.sum(lam * acov[1 : big_m + 1])
    if not g0 > 0.0:
        return 1.0
    b = (2.0 * g * g / (4.0 / 3.0 * g0 * g0)) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return float(np.clip(b, 1.0, min(3.0 * math.sqrt(n), n / 3.0)))


def block_length(first: ArrayLike, second: ArrayLike, differences: ArrayLike) -> BlockLength:
    """The block length for the differences of relations ``(first, second)`` (see the module).

    Parameters
    ----------
    first, second : array_like, shape (M,)
        The two times (or pose indices) of each relation.
    differences : array_like, shape (M,)
        The paired differences, in the order of the relations' start (``min(first,
        second)``, then end).

    Returns
    -------
    BlockLength
    """
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    d = np.asarray(differences, dtype=np.float64)
    n = d.size
    if a.shape != (n,) or b.shape != (n,):
        raise InputError(
            f"first, second and differences must have one shape (M,), got {a.shape}, "
            f"{b.shape}, {d.shape}"
        )
    if n == 0:
        return BlockLength(0, float("nan"), 0, 0, 0, 0.0)
    m_bar = _overlap_range(a, b)
    from_overlap = math.ceil(OVERLAP_FACTOR * (m_bar + 1.0))
    from_acf = math.ceil(politis_white_block_length(d))
    floor = math.ceil(n ** (1.0 / 3.0) - 1e-9)
    length = min(max(from_overlap, from_acf, floor), n)
    return BlockLength(length, m_bar, from_overlap, from_acf, floor, n / length)


def circular_block_means(
    x: ArrayLike, length: int, resamples: int, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Means of ``resamples`` circular block-bootstrap resamples of ``x``.

    A resample is ``k = ⌈n/L⌉`` blocks ``x[s], x[s+1], ..., x[s+L−1]`` (indices mod n), each
    ``s`` uniform on ``0 .. n−1``, the last block cut so that the resample has n values. With
    ``S`` the prefix sums of ``x`` extended circularly by L values, a block sums to
    ``S[s + ℓ] − S[s]``.

    Parameters
    ----------
    x : array_like, shape (n,)
    length : int
        Block length L (1 ≤ L ≤ n).
    resamples : int
        ``B``.
    rng : numpy.random.Generator
        Draws the block starts (``B × k`` integers, resample by resample).

    Returns
    -------
    ndarray, shape (B,)
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    n = v.size
    if n == 0 or not 1 <= length <= n or resamples < 1:
        raise InputError(
            f"a block bootstrap needs values, 1 <= L <= n and B >= 1; got n = {n}, "
            f"L = {length}, B = {resamples}"
        )
    k = -(-n // length)
    prefix = np.concatenate(([0.0], np.cumsum(np.concatenate((v, v[:length])))))
    sizes = np.full(k, length, dtype=np.int64)
    sizes[-1] = n - (k - 1) * length
    out = np.empty(resamples)
    per_chunk = max(1, _CHUNK // k)
    for lo in range(0, resamples, per_chunk):  # a few chunks, not a loop per resample
        hi = min(resamples, lo + per_chunk)
        starts = rng.integers(0, n, size=(hi - lo, k))
        out[lo:hi] = (prefix[starts + sizes] - prefix[starts]).sum(axis=1)
    return out / n


def paired_difference(
    first: ArrayLike,
    second: ArrayLike,
    a: ArrayLike,
    b: ArrayLike,
    *,
    confidence: float = 0.95,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int | np.random.SeedSequence = 0,
) -> PairedDifference:
    """Mean paired difference ``A − B`` on the same relations, with its block-bootstrap test.

    Parameters
    ----------
    first, second : array_like, shape (M,)
        The two times of each relation (any order of the relations: they are put in the
        order of their start, ``min(first, second)``, then end).
    a, b : array_like, shape (M,)
        The errors of A and B on those relations (one unit, e.g. m or rad).
    confidence : float
        Level of the interval, in (0, 1).
    resamples : int
        ``B`` ≥ 1.
    seed : int or numpy.random.SeedSequence
        The bootstrap's seed: the same inputs and seed give the same result.

    Returns
    -------
    PairedDifference
        Without a test (``tested`` False, ``reason`` given) when the relations form fewer
        than :data:`MIN_BLOCKS` blocks.

    Raises
    ------
    InputError
        Arrays of different shapes, no relations, non-finite errors, ``confidence`` outside
        (0, 1) or ``resamples`` < 1.
    """
    t1 = np.asarray(first, dtype=np.float64)
    t2 = np.asarray(second, dtype=np.float64)
    ea = np.asarray(a, dtype=np.float64)
    eb = np.asarray(b, dtype=np.float64)
    n = ea.size
    if ea.ndim != 1 or any(x.shape != (n,) for x in (t1, t2, eb)):
        raise InputError(
            f"first, second, a and b must have one shape (M,), got {t1.shape}, {t2.shape}, "
            f"{ea.shape}, {eb.shape}"
        )
    if n == 0:
        raise InputError("no relations to compare")
    if not (np.isfinite(ea).all() and np.isfinite(eb).all()):
        raise InputError("errors must be finite to compare them")
    if not 0.0 < confidence < 1.0:
        raise InputError(f"confidence must be in (0, 1), got {float(confidence):g}")
    if resamples < 1:
        raise InputError(f"resamples must be >= 1, got {resamples}")
    order = np.lexsort((np.maximum(t1, t2), np.minimum(t1, t2)))
    d = (ea - eb)[order]
    mean_a, mean_b, d_bar = float(ea.mean()), float(eb.mean()), float(d.mean())
    block = block_length(t1[order], t2[order], d)
    nan = float("nan")
    if block.blocks < MIN_BLOCKS:
        if block.from_overlap >= max(block.from_autocorrelation, block.floor):
            why = f"each relation overlaps {block.overlap:.3g} later ones in time on average"
        elif block.from_autocorrelation >= block.floor:
            why = f"the differences are correlated over ~{block.from_autocorrelation} relations"
        else:
            why = "too few relations"
        reason = (
            f"{n} relations in blocks of {block.length} make {block.blocks:.3g} < {MIN_BLOCKS} "
            f"blocks: {why}"
        )
        return PairedDifference(
            n, mean_a, mean_b, d_bar, nan, nan, confidence, nan, -1, resamples, block,
            tested=False, reason=reason,
        )  # fmt: skip
    rng = np.random.default_rng(seed)
    centred = circular_block_means(d - d_bar, block.length, resamples, rng)
    spread = np.abs(centred)
    exceed = int(np.count_nonzero(spread >= abs(d_bar)))
    half = float(np.quantile(spread, confidence))
    return PairedDifference(
        n=n,
        mean_a=mean_a,
        mean_b=mean_b,
        mean_difference=d_bar,
        ci_low=d_bar - half,
        ci_high=d_bar + half,
        confidence=confidence,
        p_value=(1 + exceed) / (resamples + 1),
        exceedances=exceed,
        resamples=resamples,
        block=block,
        tested=True,
    )


def holm_adjust(p: ArrayLike) -> NDArray[np.float64]:
    """Holm's step-down adjusted p-values of ``m`` tests made together.

    Holm, "A simple sequentially rejective multiple test procedure", Scandinavian Journal
    of Statistics 6 (1979), 65–70. With the p-values sorted, ``p_(1) ≤ … ≤ p_(m)``, the
    adjusted value of the k-th smallest is

        ``p̃_(k) = min(1, max_{j ≤ k} (m − j + 1) p_(j))``:

    each p-value times the number of hypotheses not yet rejected at its step, made monotone
    by the running maximum (a test is never significant when a smaller p-value before it is
    not) and clipped to 1. Rejecting every test with ``p̃ < α`` keeps the family-wise error
    rate (the chance of any false rejection) at most α under any dependence between the
    tests, and rejects at least what Bonferroni's ``m p`` rejects. Tied p-values get the
    same adjusted value, whatever their order.

    Parameters
    ----------
    p : array_like, shape (m,)
        The p-values, each in [0, 1] (``m`` may be 0).

    Returns
    -------
    ndarray, shape (m,)
        The adjusted p-values, in the order of ``p``.

    Raises
    ------
    InputError
        ``p`` not one-dimensional, or a value outside [0, 1] (NaN included).
    """
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 1:
        raise InputError(f"p-values must have shape (m,), got {p.shape}")
    outside = ~((p >= 0.0) & (p <= 1.0))
    if outside.any():
        raise InputError(
            f"p-values must be in [0, 1], got {float(p[np.flatnonzero(outside)[0]])!r}"
        )
    m = p.size
    if m == 0:
        return p
    order = np.argsort(p)
    adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out
