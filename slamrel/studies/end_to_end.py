"""The seeds' whole story, end to end: EKF-SLAM on landmarks while a laser is logged,
reference relations made from the scans, the recovered trajectory scored against them.

For one seed of the pillar world (:func:`slamrel.simulation.pillars.pillar_log`: walls,
20 point landmarks, one drive around a corridor loop and on past the start):

1. **EKF-SLAM** on the pillars (:func:`slamrel.backends.ekf_slam.ekf_slam_bundle`, known
   association, the reference filter as ``slamrel slam`` runs it): its online poses and final
   map;
2. **recovery** (:func:`recovery.recover.recover`, the smoother, defaults): the trajectory
   localised in that final map;
3. **reference relations from the scans**, as ``slamrel relations align --loops`` makes them
   with the global aligner, but with pairs and guesses from the scans' own chain
   (:func:`slamrel.scans.own_guesses.chain_guesses`, started from the log's odometry: the
   reference leans on neither the truth nor the SLAM result it will judge), and a
   **scripted review** (:func:`slamrel.scans.scripted_review.scripted_review`: unflagged
   accepted, contradicted rejected, flagged ones their cycles confirm accepted);
4. three estimates — ``recovered``, ``online`` and ``dead reckoning`` (the odometry) —
   scored by the relation metric (paper mode) against

   * ``laser``: the reviewed laser relations,
   * ``true``: the true relations ``between(truth[i], truth[j])`` at the pairs the same
     proposal rules pick from the true poses (what a perfect process would give), and
   * ``true_accepted``: the true relations at the accepted laser pairs (the same pairs: it
     separates the relations' own error from what proposing and reviewing change).

Acceptance (issue 38): each estimate's mean translational error against ``laser`` within
10 % of its mean against ``true``, and the same ranking of the three under both.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from relation_metric.evaluate import evaluate
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory
from slamrel.scans.proposals import Proposals, consecutive_pairs, loop_pairs

if TYPE_CHECKING:
    from recovery.bundle import Bundle
    from slamrel.scans.relations import ScanRelations
    from slamrel.scans.scripted_review import ScriptedReview
    from slamrel.simulation.laser import SimulatedLog

__all__ = ["ESTIMATES", "REFERENCES", "EndToEnd", "align_pairs", "end_to_end"]

ESTIMATES = ("recovered", "online", "dead reckoning")
REFERENCES = ("laser", "true", "true_accepted")


def align_pairs(poses: NDArray[np.float64], times: NDArray[np.float64]) -> Proposals:
    """``relations align --loops --keyframes motion --loop-growth 0 --loop-min-overlap 0``'s
    pairs (keyframes every 0.5 m / 0.3 rad of motion, the loop world's rule,
    benchmarks/README.md; loop pairs within 1 m, at least 10 m of travel apart), proposed
    from ``poses`` (N, 3)."""
    prop = consecutive_pairs(poses, times, distance=0.5, angle=0.3)
    return prop + loop_pairs(poses, times, radius=1.0, min_travel=10.0, distance=0.5, angle=0.3)


@dataclass(frozen=True)
class EndToEnd:
    """One seed's story.

    Attributes
    ----------
    seed : int
    estimates : dict of str to Trajectory
        ``recovered``, ``online``, ``dead reckoning``.
    references : dict of str to RelationSet
        ``laser``, ``true``, ``true_accepted`` (module docstring).
    scores : dict of str to dict of str to (float, float)
        ``scores[estimate][reference]``: mean translational [m] and rotational [rad] error.
    pairs, loop_pairs, true_pairs, true_loop_pairs, flagged, confirmed, contradicted,
    accepted : int
        The laser relations' counts (proposed from the chain; from the truth).
    gross_accepted : int
        Accepted laser relations more than 10 cm or 2° from the truth.
    landmarks, map_landmarks : int
        True pillars and landmarks in the EKF-SLAM's final map.
    """

    seed: int
    estimates: dict[str, Trajectory]
    references: dict[str, RelationSet]
    scores: dict[str, dict[str, tuple[float, float]]]
    pairs: int
    loop_pairs: int
    true_pairs: int
    true_loop_pairs: int
    flagged: int
    confirmed: int
    contradicted: int
    accepted: int
    gross_accepted: int
    landmarks: int
    map_landmarks: int

    def ratio(self, estimate: str, part: int = 0) -> float:
        """Mean error against the laser relations over the mean against the true ones
        (``part`` 0 translation, 1 rotation)."""
        sc = self.scores[estimate]
        return sc["laser"][part] / sc["true"][part]

    def ranking(self, reference: str, part: int = 0) -> list[str]:
        """The estimates, best first, by their mean error against ``reference``."""
        return sorted(ESTIMATES, key=lambda e: self.scores[e][reference][part])

    @property
    def same_ranking(self) -> bool:
        """The laser and the true relations rank the estimates alike (translation and
        rotation)."""
        return all(self.ranking("laser", k) == self.ranking("true", k) for k in (0, 1))

    @property
    def within_10_percent(self) -> bool:
        """Every estimate's translational ratio within 0.9–1.1."""
        return all(abs(self.ratio(e) - 1.0) <= 0.10 for e in ESTIMATES)


def _slam_estimates(bundle: Bundle) -> tuple[dict[str, Trajectory], int]:
    """EKF-SLAM, then recovery in its final map: the three estimates and the map's size."""
    from recovery.recover import recover
    from slamrel.backends.ekf_slam import ekf_slam_bundle

    result, run = ekf_slam_bundle(bundle)
    recovered = recover(result).trajectory
    odometry = bundle.odometry
    assert odometry is not None  # the pillar log is odometry-driven
    est = {"recovered": recovered, "online": run.online, "dead reckoning": odometry}
    return est, int(run.landmark_ids.size)


def _laser_relations(
    log: SimulatedLog, confirm: bool
) -> tuple[Proposals, ScanRelations, ScriptedReview]:
    """Pairs and guesses from the chain, the global aligner, the scripted review."""
    from slamrel.scans.global_align import align_scans_global
    from slamrel.scans.own_guesses import chain_guesses
    from slamrel.scans.scripted_review import scripted_review

    s = log.scans
    own = chain_guesses(s, s.laser_pose).poses
    prop = align_pairs(own, s.timestamps)
    res, _ = align_scans_global(s, prop, own)
    return prop, res, scripted_review(res, confirm=confirm)


def end_to_end(seed: int, *, confirm: bool = True) -> EndToEnd:
    """The story of one seed (module docstring); ``confirm=False``: the review rejects every
    flagged relation, whatever its cycles say."""
    from slamrel.simulation.pillars import pillar_log

    world = pillar_log(seed)
    log, truth = world.laser, world.laser.truth
    times = log.scans.timestamps
    estimates, mapped = _slam_estimates(world.bundle)
    prop, res, review = _laser_relations(log, confirm)
    ok = review.accepted
    true_at = se2.between(truth[prop.pairs[:, 0]], truth[prop.pairs[:, 1]])
    err = se2.between(true_at, res.delta)
    gross = (np.hypot(err[:, 0], err[:, 1]) > 0.1) | (np.abs(err[:, 2]) > np.radians(2))
    ideal = align_pairs(truth, times)
    refs = {
        "laser": RelationSet(prop.t1[ok], prop.t2[ok], res.delta[ok]),
        "true": RelationSet(
            ideal.t1, ideal.t2, se2.between(truth[ideal.pairs[:, 0]], truth[ideal.pairs[:, 1]])
        ),
        "true_accepted": RelationSet(prop.t1[ok], prop.t2[ok], true_at[ok]),
    }
    scores: dict[str, dict[str, tuple[float, float]]] = {}
    for name, traj in estimates.items():
        scores[name] = {}
        for ref, rel in refs.items():
            ev = evaluate(rel, traj)
            scores[name][ref] = (float(ev.translation.abs.mean), float(ev.rotation.abs.mean))
    return EndToEnd(
        seed=seed,
        estimates=estimates,
        references=refs,
        scores=scores,
        pairs=len(prop),
        loop_pairs=int(np.count_nonzero(prop.kind == "loop")),
        true_pairs=len(ideal),
        true_loop_pairs=int(np.count_nonzero(ideal.kind == "loop")),
        flagged=int(res.flagged.sum()),
        confirmed=review.confirmed,
        contradicted=review.contradicted,
        accepted=int(ok.sum()),
        gross_accepted=int((gross & ok).sum()),
        landmarks=int(world.landmarks.shape[0]),
        map_landmarks=mapped,
    )
