"""Reference relations from scan pairs: initialise, align, judge (typed results, no I/O).

For each proposed pair ``(i, j)`` (:mod:`slamrel.scans.proposals`):

1. the guess ``δ₀ = x_i⁻¹ ∘ x_j`` from an estimate's laser poses (or the log's odometry);
2. point-to-line ICP from ``δ₀`` (:func:`slamrel.scans.matching.align`);
3. when the global initialiser is on (``global_search="flagged"``: for pairs the first
   alignment leaves failed, with low overlap or a high residual — signs of a wrong basin;
   ``"always"``: for every pair), a correlative search around
   ``δ₀`` (:func:`slamrel.scans.correlative.correlative_match`) and ICP from its best
   candidate, kept only when it passes every quality check and matches clearly more
   (``initialiser`` says which was kept);
4. the quality flags (:class:`QualityLimits`): ``failed``, ``not converged``,
   ``degenerate`` (the matcher's own test), ``weak geometry``, ``low overlap``,
   ``high residual``, ``large correction``. The **suspicion** is the largest of
   ``min_matched / f``, ``residual / max_residual``, ``min_condition / condition`` and the
   correction over its limit (∞ for a failure): a pair is
   flagged when it exceeds 1; the review page visits pairs in decreasing suspicion.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from relation_metric.relations import RelationSet
from relation_metric.se2 import between
from slamrel.formats.laser import LaserScans
from slamrel.scans.correlative import CorrelativeOptions, correlative_match, table_cells
from slamrel.scans.matching import Alignment, IcpOptions, PreparedScan, align, prepare_scan
from slamrel.scans.proposals import Proposals

__all__ = ["QualityLimits", "AlignOptions", "ScanRelations", "align_scans", "GLOBAL_SEARCH"]

GLOBAL_SEARCH = ("never", "flagged", "always")


@dataclass(frozen=True)
class QualityLimits:
    """When a relation is flagged for review.

    Attributes
    ----------
    min_matched : float
        Matched fraction below this: ``low overlap`` (0.3).
    max_residual : float
        RMS residual above this [m]: ``high residual`` (0.03).
    min_condition : float
        Translational condition below this: ``weak geometry`` (0.1; the matcher's
        ``degenerate`` is the stricter ``IcpOptions.degenerate_ratio``).
    max_correction, max_correction_angle : float
        The alignment moved the relation farther than this from its guess
        (``guess⁻¹ ∘ δ``: 0.1 m, 0.05 rad ≈ 2.9°): ``large correction``. A matcher that slides
        into a neighbouring basin (a door frame, the next stretch of corridor) fits well
        there; only the distance from a sound guess gives it away.
    """

    min_matched: float = 0.3
    max_residual: float = 0.03
    min_condition: float = 0.1
    max_correction: float = 0.1
    max_correction_angle: float = 0.05


@dataclass(frozen=True)
class AlignOptions:
    """Everything :func:`align_scans` needs besides the data.

    Attributes
    ----------
    icp : IcpOptions
    correlative : CorrelativeOptions
    global_search : {"never", "flagged", "always"}
        When the correlative initialiser runs ("flagged").
    limits : QualityLimits
    max_range : float or None
        Readings at or beyond this are not used [m] (None: each scan's own maximum).
    min_range : float
        Readings at or below this are not used [m] (0.05).
    """

    icp: IcpOptions = field(default_factory=IcpOptions)
    correlative: CorrelativeOptions = field(default_factory=CorrelativeOptions)
    global_search: str = "flagged"
    limits: QualityLimits = field(default_factory=QualityLimits)
    max_range: float | None = None
    min_range: float = 0.05


@dataclass(frozen=True)
class ScanRelations:
    """Aligned pairs, struct of arrays (``P`` pairs).

    Attributes
    ----------
    proposals : Proposals
    guess, delta : (P, 3) float
        The initial guess and the estimate ``[x, y, θ]`` (reference frame of scan ``i``).
    covariance : (P, 3, 3) float
    matched_fraction, residual, condition : (P,) float
    weak_direction : (P, 2) float
    converged : (P,) bool
    initialiser : (P,) str
        ``"guess"`` or ``"correlative"``.
    flags : (P,) str
        Comma-separated flags (empty: none).
    suspicion : (P,) float
    score : (P,) float or None
        The branch-and-bound search's best score (NaN where no search ran; None: the
        aligner has none, :func:`align_scans`).
    second : (P, 3) float or None
        The search's best hypothesis at a distinct pose (NaN where none).
    second_ratio : (P,) float or None
        Its score over the best's (0 where none reached the search's ``keep``).
    """

    proposals: Proposals
    guess: NDArray[np.float64]
    delta: NDArray[np.float64]
    covariance: NDArray[np.float64]
    matched_fraction: NDArray[np.float64]
    residual: NDArray[np.float64]
    condition: NDArray[np.float64]
    weak_direction: NDArray[np.float64]
    converged: NDArray[np.bool_]
    initialiser: NDArray[np.str_]
    flags: NDArray[np.str_]
    suspicion: NDArray[np.float64]
    score: NDArray[np.float64] | None = None
    second: NDArray[np.float64] | None = None
    second_ratio: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.proposals)

    @property
    def flagged(self) -> NDArray[np.bool_]:
        """Pairs with at least one flag."""
        return self.flags != ""

    @property
    def failed(self) -> NDArray[np.bool_]:
        """Pairs no alignment exists for (their ``delta`` is the guess, not a relation)."""
        return np.array(["failed" in f.split(", ") for f in self.flags.tolist()], dtype=bool)

    def relation_set(self) -> RelationSet:
        """The estimates as a time-keyed :class:`RelationSet` (``t1 t2`` of the proposals),
        without the failed pairs: a failed relation is never written as its guess."""
        ok = ~self.failed
        p = self.proposals
        return RelationSet(p.t1[ok], p.t2[ok], self.delta[ok], key="time")


def _judge(
    a: Alignment, limits: QualityLimits, guess: NDArray[np.float64]
) -> tuple[list[str], float]:
    """Flags and suspicion of ``a``; the correction is measured from the pair's own ``guess``
    (not from a correlative re-start)."""
    if a.failed:
        return ["failed"], float("inf")
    corr = between(guess, a.delta)
    moved = max(
        float(np.hypot(corr[0], corr[1])) / limits.max_correction,
        abs(float(corr[2])) / limits.max_correction_angle,
    )
    flags = []
    if not a.converged:
        flags.append("not converged")
    if a.degenerate:
        flags.append("degenerate")
    if a.condition < limits.min_condition:
        flags.append("weak geometry")
    if a.matched_fraction < limits.min_matched:
        flags.append("low overlap")
    if a.residual > limits.max_residual:
        flags.append("high residual")
    if moved > 1.0:
        flags.append("large correction")
    ratios = (
        moved,
        limits.min_matched / max(a.matched_fraction, 1e-9),
        a.residual / limits.max_residual,
        limits.min_condition / max(a.condition, 1e-9),
    )
    suspicion = max(ratios)
    if flags and suspicion <= 1.0:  # not converged alone still needs a look
        suspicion = 1.0 + 1e-9
    return flags, float(suspicion)


def _better(a: Alignment, b: Alignment, limits: QualityLimits) -> bool:
    """Does the re-initialised ``b`` replace ``a``?

    Only when ``b`` passes every quality check and matches clearly more (by 0.1 of the
    current scan's returns): in corridors a search window holds many near-equal fits, and a
    slightly larger overlap elsewhere is aliasing, not a better relation.
    """
    if b.failed or _judge(b, limits, b.guess)[0]:
        return False
    return bool(a.failed) or b.matched_fraction >= a.matched_fraction + 0.1


#: Lookup-table cells (1 GB of float64) beyond which a correlative search is refused rather
#: than run: its table (the reference's returns and every place the current scan reaches from
#: the window) would not fit in memory. A window that lets the two scans overlap nowhere is
#: refused as a far guess (it cannot succeed, and its table grows with the square of the
#: guess's distance: a pose at 1e20 m asked for a table of negative size); a window merely too
#: large (``--search-xy``) is refused as such.
MAX_TABLE_CELLS = 2**27


def _refuse_large_table(
    scans: LaserScans,
    pair: tuple[int, int],
    ref: PreparedScan,
    cur: PreparedScan,
    guess: NDArray[np.float64],
    options: CorrelativeOptions,
) -> None:
    """Refuse the correlative search of a pair whose lookup table would exceed
    :data:`MAX_TABLE_CELLS`: as a far guess when no placement in the window lets the scans
    overlap (the poses of the two scans' lines made the guess), else as a window too large."""
    cells = table_cells(ref.points, cur.points, guess, options)
    if cells <= MAX_TABLE_CELLS:
        return
    reach = float(np.max(np.hypot(*ref.points.T)) + np.max(np.hypot(*cur.points.T)))
    apart = float(np.hypot(guess[0], guess[1]))
    if apart > reach + options.search_xy + 4 * options.sigma:
        raise far_guess_error(
            scans,
            pair,
            apart,
            reach,
            f" and the correlative search moves ±{options.search_xy:g} m: no placement it "
            f"tries lets them overlap, and its table would need {cells:.3g} cells (limit "
            f"{MAX_TABLE_CELLS})",
        )
    from relation_metric.errors import InputError

    i, j = pair
    raise InputError(
        f"the correlative search of the scans of lines {int(scans.lines[i])} and "
        f"{int(scans.lines[j])} (±{options.search_xy:g} m at {options.resolution:g} m cells) "
        f"needs a lookup table of {cells:.3g} cells, {8 * cells / 2**30:.3g} GiB of float64: "
        f"it would not fit in memory (limit {MAX_TABLE_CELLS} cells); expected a smaller "
        "--search-xy",
        path=scans.path,
        line=int(scans.lines[j]),
    )


def far_guess_error(
    scans: LaserScans, pair: tuple[int, int], apart: float, reach: float, why: str
) -> Exception:
    """The input error of a guess that puts scan ``pair[1]`` ``apart`` m from scan
    ``pair[0]``, farther than their returns ``reach`` together (``why``: the search's words),
    at the line of ``pair[1]``; both aligners refuse such a guess with it."""
    from relation_metric.errors import InputError

    i, j = pair
    return InputError(
        f"the guess puts the scan of line {int(scans.lines[j])} {apart:.6g} m from the scan of "
        f"line {int(scans.lines[i])}, but their returns reach {reach:.6g} m together{why}; "
        "expected poses (the log's, or --estimate's) that put the two scans near each other",
        path=scans.path,
        line=int(scans.lines[j]),
    )


def align_scans(
    scans: LaserScans,
    proposals: Proposals,
    guesses: NDArray[np.float64],
    options: AlignOptions | None = None,
) -> ScanRelations:
    """Align every proposed pair from its guess (see the module docstring).

    Parameters
    ----------
    scans : LaserScans
    proposals : Proposals
    guesses : (P, 3) float
        Initial relations, e.g. ``between(poses[i], poses[j])``.
    options : AlignOptions, optional
    """
    opt = options or AlignOptions()
    if opt.global_search not in GLOBAL_SEARCH:
        raise ValueError(f"global_search must be one of {GLOBAL_SEARCH}, got {opt.global_search!r}")
    guesses = np.asarray(guesses, dtype=np.float64).reshape(-1, 3)
    prepared: dict[int, PreparedScan] = {}

    def scan(k: int) -> PreparedScan:
        if k not in prepared:
            pts = scans.points(k, min_range=opt.min_range, max_range=opt.max_range)
            prepared[k] = prepare_scan(pts)
        return prepared[k]

    out: list[tuple[Alignment, str, list[str], float]] = []
    for (i, j), g in zip(proposals.pairs.tolist(), guesses, strict=True):
        ref, cur = scan(i), scan(j)
        a = align(ref, cur, g, opt.icp)
        flags, susp = _judge(a, opt.limits, g)
        how = "guess"
        lost = bool({"failed", "low overlap", "high residual"} & set(flags))
        if opt.global_search == "always" or (opt.global_search == "flagged" and lost):
            if ref.points.shape[0] and cur.points.shape[0]:
                _refuse_large_table(scans, (i, j), ref, cur, g, opt.correlative)
                c = correlative_match(ref.points, cur.points, g, opt.correlative)
                b = align(ref, cur, c.delta, opt.icp)
                if _better(a, b, opt.limits):
                    a, how = b, "correlative"
                    flags, susp = _judge(a, opt.limits, g)
        out.append((a, how, flags, susp))
    return collect_relations(proposals, guesses, out)


def collect_relations(
    proposals: Proposals,
    guesses: NDArray[np.float64],
    out: list[tuple[Alignment, str, list[str], float]],
    **search: NDArray[np.float64],
) -> ScanRelations:
    """:class:`ScanRelations` from one ``(alignment, initialiser, flags, suspicion)`` per
    pair (and the search's ``score``, ``second``, ``second_ratio`` when there are)."""
    p = len(proposals)
    al = [o[0] for o in out]
    return ScanRelations(
        proposals=proposals,
        guess=guesses.copy(),
        delta=np.array([a.delta for a in al]).reshape(p, 3),
        covariance=np.array([a.covariance for a in al]).reshape(p, 3, 3),
        matched_fraction=np.array([a.matched_fraction for a in al]),
        residual=np.array([a.residual for a in al]),
        condition=np.array([a.condition for a in al]),
        weak_direction=np.array([a.weak_direction for a in al]).reshape(p, 2),
        converged=np.array([a.converged for a in al], dtype=bool),
        initialiser=np.array([o[1] for o in out], dtype=str),
        flags=np.array([", ".join(o[2]) for o in out], dtype=str),
        suspicion=np.array([o[3] for o in out]),
        **search,
    )


def guesses_from_poses(poses: NDArray[np.float64], proposals: Proposals) -> NDArray[np.float64]:
    """``between(poses[i], poses[j])`` for every proposed pair ``(i, j)``."""
    return between(poses[proposals.pairs[:, 0]], poses[proposals.pairs[:, 1]])
