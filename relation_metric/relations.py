"""Reference relation sets and relation selection (their file: :mod:`slamrel.formats.relations`).

A relation is a pair of poses and the reference relative motion between them,
``δ*_ij = x*_i⁻¹ ∘ x*_j`` (Kümmerle et al. 2009, Eq. 1 and Sec. IV). A :class:`RelationSet`
holds M of them as struct-of-arrays; the pair is named either by timestamps (``key="time"``,
the Freiburg files) or by pose indices into the evaluated trajectory (``key="index"``).

Selection strategies (:func:`generate_relations`) follow the relation selection discussed
in Kümmerle et al. 2009 (Sec. V): local relations between nearby poses (every k poses, every
d metres of travel), loop-closing relations between poses that are close in space but far
apart along the path, global relations between far-apart poses, and a seeded random sample.
Every generated set reproduces its reference trajectory exactly (``δ*`` are computed with
the group's ``between`` on the reference poses). Relations live on the reference's group:
``delta`` is ``(M, 3)`` on SE(2) and ``(M, 7)`` ``[x, y, z, qx, qy, qz, qw]`` on SE(3)
(:mod:`relation_metric.groups`); spatial strategies use 2-D or 3-D positions accordingly.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se3
from relation_metric.constants import STRATEGIES
from relation_metric.errors import InputError
from relation_metric.groups import SE2, SE3, PoseGroup, group_of
from relation_metric.trajectory import Trajectory, readonly, readonly_fresh

__all__ = [
    "RelationSet",
    "generate_relations",
    "chain_from_zero",
    "STRATEGIES",
]


@dataclass(frozen=True)
class RelationSet:
    """M reference relations ``(first_k, second_k, δ*_k)``.

    Parameters
    ----------
    first, second : array_like, shape (M,)
        Timestamps (``key="time"``) or pose indices (``key="index"``) of the two poses.
        ``second < first`` is allowed (the Freiburg files contain such relations).
    delta : array_like, shape (M, 3) or (M, 7)
        Reference motions ``δ*_k = x*_first⁻¹ ∘ x*_second``: ``[x, y, θ]`` on SE(2),
        ``[x, y, z, qx, qy, qz, qw]`` on SE(3) (the column count decides :attr:`group`).
    key : {"time", "index"}
    out_of_plane : array_like, shape (M, 3), optional
        SE(2) only: ``[z, roll, pitch]`` of the relations (Freiburg files carry them; zero
        for planar data). :meth:`lifted` turns them into SE(3) relations.
    information : array_like, shape (M, 3, 3), optional
        Information matrices of the relations, where a source provides them.
    """

    first: NDArray[np.float64]
    second: NDArray[np.float64]
    delta: NDArray[np.float64]
    key: Literal["time", "index"] = "time"
    out_of_plane: NDArray[np.float64] | None = None
    information: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        a = np.asarray(self.first, dtype=np.float64)
        b = np.asarray(self.second, dtype=np.float64)
        d = np.asarray(self.delta, dtype=np.float64)
        m = a.shape[0] if a.ndim == 1 else -1
        if a.ndim != 1 or b.shape != (m,) or d.shape not in ((m, 3), (m, 7)):
            raise InputError(
                f"relation arrays must have shapes (M,), (M,), (M, 3) or (M, 7); got {a.shape}, "
                f"{b.shape}, {d.shape}"
            )
        if self.key not in ("time", "index"):
            raise InputError(f"relation key must be 'time' or 'index', got {self.key!r}")
        if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(d).all()):
            raise InputError("relations contain non-finite values")
        if self.key == "index" and (np.any(a != np.round(a)) or np.any(b != np.round(b))):
            raise InputError("index relations need integer pose indices")
        object.__setattr__(self, "first", readonly(a))
        object.__setattr__(self, "second", readonly(b))
        group = group_of(d)
        object.__setattr__(self, "delta", readonly_fresh(group.normalize(d)))
        if group is SE3 and self.out_of_plane is not None:
            raise InputError("SE(3) relations hold z, roll and pitch in delta, not out_of_plane")
        k = group.dof
        for name, shape in (("out_of_plane", (m, 3)), ("information", (m, k, k))):
            value = getattr(self, name)
            if value is not None:
                arr = np.asarray(value, dtype=np.float64)
                if arr.shape != shape:
                    raise InputError(f"{name} must have shape {shape}, got {arr.shape}")
                object.__setattr__(self, name, readonly(arr))

    def __len__(self) -> int:
        return int(self.first.shape[0])

    @property
    def group(self) -> PoseGroup:
        """The group of the relations: SE(2) for ``(M, 3)`` deltas, SE(3) for ``(M, 7)``."""
        return group_of(self.delta)

    @property
    def has_out_of_plane(self) -> bool:
        """SE(2) relations whose ``out_of_plane`` parts are not all zero."""
        return self.out_of_plane is not None and bool(np.any(self.out_of_plane != 0.0))

    def lifted(self) -> RelationSet:
        """The relations on SE(3): ``[x, y, z]`` and the rotation of ``[roll, pitch, yaw]``.

        SE(2) relations with ``out_of_plane = [z, roll, pitch]`` (Freiburg 6-DoF lines)
        become the full 6-DoF motions; SE(3) relations are returned unchanged. Information
        matrices are not carried over (their order differs between the groups).
        """
        if self.group is SE3:
            return self
        oop = np.zeros((len(self), 3)) if self.out_of_plane is None else self.out_of_plane
        rpy = np.column_stack((oop[:, 1], oop[:, 2], self.delta[:, 2]))
        delta = np.column_stack((self.delta[:, 0:2], oop[:, 0], se3.from_euler_zyx(rpy)))
        return RelationSet(self.first, self.second, delta, key=self.key)

    def planar(self) -> RelationSet:
        """The relations projected onto SE(2) (``[x, y, yaw]``; z, roll, pitch kept in
        ``out_of_plane``)."""
        if self.group is SE2:
            return self
        p = SE3.parameters(self.delta)
        return RelationSet(
            self.first, self.second, p[:, [0, 1, 5]], key=self.key, out_of_plane=p[:, 2:5]
        )

    def subset(self, mask: ArrayLike) -> RelationSet:
        """The relations selected by a boolean mask or index array."""
        sel = np.asarray(mask)
        return RelationSet(
            self.first[sel],
            self.second[sel],
            self.delta[sel],
            key=self.key,
            out_of_plane=None if self.out_of_plane is None else self.out_of_plane[sel],
            information=None if self.information is None else self.information[sel],
        )

    def span(self) -> tuple[float, float]:
        """Smallest and largest timestamp (or index) the relations refer to."""
        if len(self) == 0:
            return (float("nan"), float("nan"))
        both = np.concatenate((self.first, self.second))
        return float(both.min()), float(both.max())

    @classmethod
    def from_trajectory_pairs(
        cls, reference: Trajectory, i: ArrayLike, j: ArrayLike, *, key: str = "time"
    ) -> RelationSet:
        """Relations between poses ``i`` and ``j`` of ``reference`` (δ* from the poses)."""
        i = np.asarray(i, dtype=np.int64)
        j = np.asarray(j, dtype=np.int64)
        delta = reference.group.between(reference.poses[i], reference.poses[j])
        if key == "time":
            return cls(reference.timestamps[i], reference.timestamps[j], delta, key="time")
        return cls(i.astype(np.float64), j.astype(np.float64), delta, key="index")


def generate_relations(
    reference: Trajectory,
    strategy: str,
    *,
    step: int = 1,
    distance: float = 1.0,
    radius: float = 1.0,
    min_separation_time: float | None = 30.0,
    min_separation_distance: float | None = None,
    count: int = 1000,
    min_distance: float | None = None,
    seed: int = 0,
    key: Literal["time", "index"] = "time",
    chained: bool = False,
    seconds: float = 1.0,
    max_relations: int | None = None,
) -> RelationSet:
    """Select relations from a reference trajectory (Kümmerle et al. 2009, Sec. V).

    Parameters
    ----------
    reference : Trajectory
        Ground truth; ``δ*`` are its relative motions.
    strategy : str
        ``"consecutive"``: pose k with pose k + ``step``.
        ``"distance"``: each pose with the first later pose at least ``distance`` metres
        further along the path.
        ``"loops"``: pairs within ``radius`` metres of each other that lie at least
        ``min_separation_time`` seconds (or ``min_separation_distance`` metres of travel)
        apart — the loop closures a SLAM system should have made.
        ``"global"``: ``count`` seeded random pairs at least ``min_distance`` metres apart in
        space (default: a quarter of the trajectory's extent) — far-apart relations that
        reveal global breakage.
        ``"random"``: ``count`` seeded random pairs, uniformly over all pairs i < j.
        ``"all-pairs"``: every pair i < j (quadratic; for short trajectories only).
        ``"time"``: RPE by seconds, TUM's definition (``evaluate_rpe.py --fixed_delta
        --delta S --delta_unit s``): each pose ``i`` with the pose ``j`` nearest in time to
        ``t_i + seconds``; the pair is dropped when ``j`` is the last pose (TUM's rule: a
        target past the end finds the last pose) or ``j == i`` (``seconds`` below half the
        pose spacing).
    step, distance, radius, min_separation_time, min_separation_distance, count, \
min_distance, seed, seconds :
        Strategy parameters, see above.
    key : {"time", "index"}
        Name the pairs by timestamps or by pose indices.
    chained : bool
        ``consecutive`` and ``distance`` only: instead of a relation from every pose, a
        chain from pose 0, each relation starting where the previous one ended —
        ``(0, s), (s, 2s), ...`` and, by travelled distance, ``0 → j₁ → j₂ ...`` with
        ``j_{k+1}`` the first pose at least ``distance`` further along the path. These are
        evo's RPE pairs (``all_pairs=False``, delta in frames or metres); without
        ``chained`` they are evo's ``all_pairs=True`` in frames.
    max_relations : int, optional
        The pair budget of the quadratic strategies (``loops``, ``all-pairs``, ``global``,
        ``random``; default :data:`MAX_RELATIONS`): a selection that would hold more is
        refused up front (:class:`InputError` saying what to change) instead of filling
        the memory — scoring costs about 200 bytes a relation. ``loops`` streams its
        candidate pairs in bounded chunks, so its peak memory follows the pairs kept.

    Returns
    -------
    RelationSet
        Pairs with ``first < second`` (in pose order), sorted by ``(first, second)``.
    """
    n = len(reference)
    if n < 2:
        raise InputError(f"a reference trajectory needs at least 2 poses, has {n}")
    budget = MAX_RELATIONS if max_relations is None else int(max_relations)
    if strategy in ("global", "random") and count > budget:
        raise InputError(_over_budget(f"a count of {count:,}", budget, "a smaller count"))
    if strategy == "consecutive":
        if step < 1:
            raise InputError(f"step must be >= 1, got {step}")
        if chained:
            ids = np.arange(0, n, step)
            i, j = ids[:-1], ids[1:]
        else:
            i = np.arange(0, n - step)
            j = i + step
    elif strategy == "distance":
        if not distance > 0:
            raise InputError(f"distance must be > 0, got {distance}")
        s = reference.path_length()
        j = np.searchsorted(s, s + distance, side="left")
        if chained:
            ids = chain_from_zero(j, n)
            i, j = ids[:-1], ids[1:]
        else:
            i = np.arange(n)
            keep = j < n
            i, j = i[keep], j[keep]
    elif strategy == "loops":
        i, j = _loop_pairs(reference, radius, min_separation_time, min_separation_distance, budget)
    elif strategy == "global":
        xy = reference.positions
        extent = float(np.linalg.norm(xy.max(axis=0) - xy.min(axis=0)))
        if xy.shape[1] == 2:
            extent = float(np.hypot(*(xy.max(axis=0) - xy.min(axis=0))))
        dmin = extent / 4.0 if min_distance is None else float(min_distance)
        i, j = _random_pairs(n, count, seed, xy=xy, min_distance=dmin)
    elif strategy == "random":
        i, j = _random_pairs(n, count, seed)
    elif strategy == "all-pairs":
        if n * (n - 1) // 2 > budget:
            raise InputError(
                _over_budget(
                    f"strategy 'all-pairs' on {n:,} poses makes {n * (n - 1) // 2:,} pairs",
                    budget,
                    "strategy 'random' with a count, or strategy 'loops' or 'global'",
                )
            )
        i, j = np.triu_indices(n, k=1)
    elif strategy == "time":
        if not (np.isfinite(seconds) and seconds > 0):
            raise InputError(f"seconds must be > 0, got {seconds}")
        from relation_metric.time_association import nearest_index

        t = reference.timestamps
        j = nearest_index(t, t + seconds)
        i = np.arange(n)
        keep = (j != n - 1) & (j != i)
        i, j = i[keep], j[keep]
    else:
        raise InputError(f"unknown strategy {strategy!r}; expected one of {', '.join(STRATEGIES)}")
    order = np.lexsort((j, i))
    return RelationSet.from_trajectory_pairs(reference, i[order], j[order], key=key)


def chain_from_zero(successor: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """``0, f(0), f(f(0)), ...`` while below ``n`` (``f = successor``, ``f(k) > k``).

    Pointer doubling: ``log₂`` of the chain length vectorised steps, no loop per pose.
    """
    jump = np.append(np.minimum(successor, n), n).astype(np.int64)  # jump[n] = n (absorbing)
    chain = np.zeros(1, dtype=np.int64)
    while chain[-1] < n:
        chain = np.concatenate((chain, jump[chain]))  # nodes 0 .. 2^(k+1) − 1 steps out
        jump = jump[jump]
    return chain[chain < n]


MAX_RELATIONS = 5_000_000
"""The pair budget of the quadratic strategies (about 1 GB when scored; see
:func:`generate_relations`' ``max_relations``)."""

LOOP_CHUNK_PAIRS = 2_000_000
"""Candidate pairs ``loops`` materialises at once (24 bytes each, plus their filtering)."""

LOOP_COUNT_SEGMENT = 65_536
"""Poses whose candidate pairs ``loops`` counts at once."""


def _over_budget(what: str, budget: int, change: str) -> str:
    """The message of a selection over the pair budget: what, the budget, what to change."""
    return (
        f"{what}: more than the {budget:,} relations slamrel scores in one run "
        f"(max_relations; about 200 bytes of memory each); pass {change}, or raise "
        "max_relations if the memory is there"
    )


def _loop_pairs(
    reference: Trajectory,
    radius: float,
    min_time: float | None,
    min_travel: float | None,
    budget: int = MAX_RELATIONS,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs ``i < j`` at most ``radius`` apart and at least ``min_time`` s (or ``min_travel``
    m of path) apart, streamed: the candidates within ``radius`` are counted per pose, then
    found for blocks of poses holding at most :data:`LOOP_CHUNK_PAIRS` of them, filtered,
    and kept; more than ``budget`` kept pairs is refused as soon as it is reached.
    """
    if not radius > 0:
        raise InputError(f"radius must be > 0, got {radius}")
    if min_time is None and min_travel is None:
        raise InputError("loop relations need a minimum separation in time or distance")
    from scipy.spatial import cKDTree  # here, not at import: scipy.spatial costs start-up

    xy = np.ascontiguousarray(reference.positions)
    tree = cKDTree(xy)
    t = reference.timestamps
    s = reference.path_length() if min_travel is not None else None
    kept_i: list[NDArray[np.int64]] = []
    kept_j: list[NDArray[np.int64]] = []
    total = 0
    for lo, hi in _loop_blocks(tree, xy, radius):
        near = cKDTree(xy[lo:hi]).sparse_distance_matrix(tree, radius, output_type="ndarray")
        i = near["i"].astype(np.int64) + lo
        j = near["j"].astype(np.int64)
        del near
        up = j > i
        i, j = i[up], j[up]
        keep = np.zeros(i.shape, dtype=bool)
        if min_time is not None:
            keep |= (t[j] - t[i]) >= min_time
        if s is not None:
            keep |= (s[j] - s[i]) >= min_travel  # type: ignore[operator]
        kept_i.append(i[keep])
        kept_j.append(j[keep])
        total += kept_i[-1].size
        if total > budget:
            raise InputError(
                _over_budget(
                    f"strategy 'loops' finds at least {total:,} pose pairs within radius "
                    f"{radius:g} m",
                    budget,
                    "a smaller radius, a larger min_separation_time (or "
                    "min_separation_distance), or strategy 'random' with a count",
                )
            )
    if not kept_i:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    return np.concatenate(kept_i), np.concatenate(kept_j)


def _loop_blocks(tree: object, xy: NDArray[np.float64], radius: float) -> Iterator[tuple[int, int]]:
    """Blocks ``[lo, hi)`` of poses whose candidate pairs within ``radius`` total at most
    :data:`LOOP_CHUNK_PAIRS` each (a single pose with more is a block of its own). The
    candidates are counted per pose without materialising them, a segment of poses at a
    time, so that a refusal over the budget comes before the rest is counted."""
    n = len(xy)
    for start in range(0, n, LOOP_COUNT_SEGMENT):
        stop = min(start + LOOP_COUNT_SEGMENT, n)
        counts = tree.query_ball_point(xy[start:stop], radius, return_length=True)  # type: ignore[attr-defined]
        ends = np.cumsum(counts, dtype=np.int64)
        lo = 0
        while lo < stop - start:
            base = ends[lo - 1] if lo else 0
            hi = int(np.searchsorted(ends, base + LOOP_CHUNK_PAIRS, side="right"))
            hi = min(max(hi, lo + 1), stop - start)
            yield start + lo, start + hi
            lo = hi


MAX_SAMPLED_RELATIONS = MAX_RELATIONS
"""The most relations ``global``/``random`` draw: the pair budget :data:`MAX_RELATIONS`."""


def _random_pairs(
    n: int,
    count: int,
    seed: int,
    *,
    xy: NDArray[np.float64] | None = None,
    min_distance: float = 0.0,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``count`` distinct seeded pairs ``i < j`` (at least ``min_distance`` apart with ``xy``).

    Candidates are drawn in batches; the result is the first ``count`` distinct pairs in the
    order drawn. The work is bounded: when every pair is wanted (``random``) all are taken;
    batches are capped, and the search stops when a batch finds no new pair or after 64
    batches. Fewer pairs than asked are returned with a warning that says how many.
    """
    if count < 1:
        raise InputError(f"count must be >= 1, got {count}")
    total = n * (n - 1) // 2
    if xy is None and count >= total:
        if count > total:
            warnings.warn(
                f"{count} random relations asked, but {n} poses have only {total} pairs; "
                "all of them are used",
                UserWarning,
                stacklevel=4,
            )
        i, j = np.triu_indices(n, k=1)
        return i.astype(np.int64), j.astype(np.int64)
    rng = np.random.default_rng(seed)
    picked = np.empty(0, dtype=np.int64)  # distinct codes i*n + j, in the order drawn
    for _ in range(64):
        batch = min(max(4 * (count - picked.size), 1024), 4 * 1024 * 1024)
        a = rng.integers(0, n, size=batch)
        b = rng.integers(0, n, size=batch)
        i, j = np.minimum(a, b), np.maximum(a, b)
        ok = i != j
        if xy is not None:
            d = xy[j] - xy[i]
            dist = np.hypot(d[:, 0], d[:, 1]) if d.shape[1] == 2 else np.linalg.norm(d, axis=1)
            ok &= dist >= min_distance
        codes = i[ok] * n + j[ok]
        codes = codes[~np.isin(codes, picked)]
        _, first = np.unique(codes, return_index=True)
        if first.size == 0 and picked.size:
            break  # saturated: this batch found no new pair
        picked = np.concatenate((picked, codes[np.sort(first)]))
        if picked.size >= min(count, total):
            break
    picked = picked[:count]
    if picked.size == 0:
        raise InputError(f"no pose pairs at least {min_distance:.3g} m apart; lower min_distance")
    if picked.size < count:
        what = f"at least {min_distance:.3g} m apart " if xy is not None else ""
        warnings.warn(
            f"only {picked.size} distinct pose pairs {what}were found of the {count} asked; "
            f"{picked.size} relations are used",
            UserWarning,
            stacklevel=4,
        )
    return picked // n, picked % n
