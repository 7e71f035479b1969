"""Acceptance of issue 37: scoring against relations made by scan alignment and reviewed
gives the ranking and the means of scoring against the true relations.

A simulated laser log of the ``"loop"`` world (:mod:`slamrel.simulation.laser`: the corridor
around the block, driven once and on past the start, 1 cm range noise, drifting odometry).
Relations are made as ``slamrel relations align`` makes them today, through its public
function :func:`slamrel.scans.relations.align_scans`: consecutive keyframes every 0.5 m and
loop pairs (``--loops``), guesses from the log's own odometry, default options. The
scripted review accepts the unflagged relations and rejects the flagged ones; with
``--cycle-check`` the relations the cycle check contradicts
(:func:`slamrel.scans.cycles.check_scan_relations`) are rejected too; with ``--confirm`` the
relations flagged only for a ``large correction`` that their cycles confirm (≥ 2 cycles,
none failed) are accepted.

Three estimates of different quality are scored (relation metric, paper mode) against

* the reviewed relations (aligned motions, accepted pairs only), and
* the true relations (``between(truth[i], truth[j])``) at the pairs the same proposal rules
  pick from the true poses — the reference a perfect process would give (``true``); and, to
  separate what is lost in proposing and reviewing from the accuracy of what is kept, at the
  pairs proposed from the guesses (``true_proposed``) and at the accepted ones
  (``true_accepted``).

Estimates: ``jitter`` — the truth with independent 5 mm / 0.05° noise on every pose;
``odometry`` — the log's own odometry; ``drift`` — the true increments scaled by 1.05 and
turned 0.004 rad a step (worse than the odometry at every scale). Acceptance: the same
ranking (by mean translational error, and by mean rotational error) and each mean
translational error within 10 % (ratio reviewed / true in 0.9–1.1); the rotational ratios
are reported beside them.

    python benchmarks/score_acceptance.py [--seeds 0 1 2] [--cycle-check] [--confirm]
        [--guesses truth] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from relation_metric import se2
from relation_metric.evaluate import evaluate
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory
from slamrel.scans.proposals import Proposals, consecutive_pairs, loop_pairs
from slamrel.scans.relations import (
    AlignOptions,
    ScanRelations,
    align_scans,
    guesses_from_poses,
)
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

CORNERS = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])
ESTIMATES = ("jitter", "odometry", "drift")


def estimates(truth: np.ndarray, odometry: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    """The three estimates' poses (N, 3)."""
    rng = np.random.default_rng(1000 + seed)
    jitter = se2.compose(truth, rng.normal(0, 1, truth.shape) * [0.005, 0.005, np.radians(0.05)])
    inc = se2.between(truth[:-1], truth[1:])
    inc[:, :2] *= 1.05
    inc[:, 2] += 0.004
    drift = se2.cumulative_compose(inc, truth[0])
    return {"jitter": jitter, "odometry": odometry, "drift": drift}


def _score(rel: RelationSet, times: np.ndarray, poses: np.ndarray) -> tuple[float, float]:
    ev = evaluate(rel, Trajectory(times, poses))
    return float(ev.translation.abs.mean), float(ev.rotation.abs.mean)


def _pairs(poses: np.ndarray, times: np.ndarray) -> Proposals:
    """``relations align --loops``' pairs with its defaults, proposed from ``poses``."""
    prop = consecutive_pairs(poses, times, distance=0.5, angle=0.3)
    return prop + loop_pairs(poses, times, radius=1.0, min_travel=10.0, distance=0.5, angle=0.3)


def _review(res: ScanRelations, cycle_check: bool, confirm: bool) -> tuple[np.ndarray, int, int]:
    """The scripted review: accept the unflagged relations; with ``cycle_check`` not those
    the cycle check contradicts; with ``confirm`` also the relations flagged only for a
    ``large correction`` whose cycles (with the unflagged ones) confirm them (≥ 2 cycles,
    none failed). Returns the accepted mask and the counts contradicted and confirmed."""
    from slamrel.scans.cycles import check_scan_relations

    accept = ~res.flagged
    if not (cycle_check or confirm):
        return accept, 0, 0
    moved = res.flags == "large correction"
    check = check_scan_relations(res, use=accept | moved if confirm else accept)
    if cycle_check:
        accept &= ~check.contradicted
    extra = moved & check.confirmed() & ~check.contradicted if confirm else moved & False
    return accept | extra, check.count, int(extra.sum())


def run(
    seed: int,
    *,
    cycle_check: bool = False,
    confirm: bool = False,
    guesses: str = "odometry",
    aligner: str = "global",
) -> dict:
    """One simulated log: relations made and reviewed, three estimates scored both ways.

    ``guesses``: the poses that propose the pairs and give the alignments their guesses —
    the log's ``odometry`` (the honest start), or the ``truth`` (to check that the harness
    can pass when the aligner gets every pair right). ``aligner``: ``global`` (the command's
    default, :func:`slamrel.scans.global_align.align_scans_global`) or ``icp`` (ICP from the
    guess, :func:`slamrel.scans.relations.align_scans`)."""
    walls = laser_world("loop")
    truth = loop_path(CORNERS, 0.3)
    truth = np.vstack((truth, truth[:60]))  # on past the start: loop closures
    log = simulate_laser_log(walls, truth, seed=seed)
    s = log.scans
    odo = s.laser_pose
    start = odo if guesses == "odometry" else log.truth
    prop = _pairs(start, s.timestamps)
    t0 = time.process_time()
    if aligner == "global":
        from slamrel.scans.global_align import align_scans_global

        res, _ = align_scans_global(s, prop, start, AlignOptions())
    else:
        res = align_scans(s, prop, guesses_from_poses(start, prop), AlignOptions())
    cpu = time.process_time() - t0
    accept, contradicted, confirmed = _review(res, cycle_check, confirm)
    true = guesses_from_poses(log.truth, prop)
    err = se2.between(true, res.delta)
    gross = (np.hypot(err[:, 0], err[:, 1]) > 0.1) | (np.abs(err[:, 2]) > np.radians(2))
    p = prop.pairs
    reviewed = RelationSet(prop.t1[accept], prop.t2[accept], res.delta[accept])
    ideal = _pairs(log.truth, s.timestamps)
    true_ideal = RelationSet(ideal.t1, ideal.t2, guesses_from_poses(log.truth, ideal))
    true_prop = RelationSet(prop.t1, prop.t2, true)
    true_acc = RelationSet(prop.t1[accept], prop.t2[accept], true[accept])
    scores = {}
    for name, poses in estimates(log.truth, odo, seed).items():
        scores[name] = {
            "reviewed": _score(reviewed, s.timestamps, poses),
            "true": _score(true_ideal, s.timestamps, poses),
            "true_proposed": _score(true_prop, s.timestamps, poses),
            "true_accepted": _score(true_acc, s.timestamps, poses),
        }
    return {
        "seed": seed,
        "scans": len(s),
        "pairs": len(prop),
        "loop_pairs": int(np.count_nonzero(prop.kind == "loop")),
        "true_pairs": len(ideal),
        "true_loop_pairs": int(np.count_nonzero(ideal.kind == "loop")),
        "guesses": guesses,
        "flagged": int(res.flagged.sum()),
        "contradicted": contradicted,
        "confirmed": confirmed,
        "accepted": int(accept.sum()),
        "gross": int(gross.sum()),
        "gross_accepted": int((gross & accept).sum()),
        "align_cpu_s": cpu,
        "pairs_per_cpu_s": len(prop) / cpu if cpu > 0 else float("nan"),
        "max_pair_gap": int(np.abs(p[:, 1] - p[:, 0]).max()),
        "scores": scores,
        **verdict(scores),
    }


def _ranking(scores: dict, which: str, part: int) -> list[str]:
    return sorted(ESTIMATES, key=lambda e: scores[e][which][part])


def verdict(scores: dict) -> dict:
    """Ranking equality (translation, rotation) and the mean ratios reviewed / true."""
    ratio = {
        e: [scores[e]["reviewed"][k] / scores[e]["true"][k] for k in (0, 1)] for e in ESTIMATES
    }
    same = all(_ranking(scores, "reviewed", k) == _ranking(scores, "true", k) for k in (0, 1))
    return {
        "ranking_reviewed": _ranking(scores, "reviewed", 0),
        "ranking_true": _ranking(scores, "true", 0),
        "same_ranking": same,
        "ratio": ratio,
        "within_10_percent": all(abs(ratio[e][0] - 1.0) <= 0.10 for e in ESTIMATES),
        "rotation_within_10_percent": all(abs(ratio[e][1] - 1.0) <= 0.10 for e in ESTIMATES),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--cycle-check", action="store_true")
    ap.add_argument("--confirm", action="store_true")
    ap.add_argument("--guesses", choices=("odometry", "truth"), default="odometry")
    ap.add_argument("--aligner", choices=("global", "icp"), default="global")
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args()
    out = []
    for seed in args.seeds:
        r = run(
            seed,
            cycle_check=args.cycle_check,
            confirm=args.confirm,
            guesses=args.guesses,
            aligner=args.aligner,
        )
        out.append(r)
        print(
            f"seed {seed}, guesses from {r['guesses']}: {r['pairs']} pairs ({r['loop_pairs']} "
            f"loop; from the truth {r['true_pairs']}, {r['true_loop_pairs']} loop), "
            f"{r['flagged']} flagged, "
            f"{r['contradicted']} contradicted, {r['confirmed']} confirmed, "
            f"{r['accepted']} accepted "
            f"({r['gross_accepted']} of {r['gross']} gross ones accepted); "
            f"{r['pairs_per_cpu_s']:.1f} pairs/CPU-s"
        )
        for e in ESTIMATES:
            sc = r["scores"][e]
            print(
                f"  {e:9s} trans reviewed {sc['reviewed'][0]:.4f} true {sc['true'][0]:.4f} "
                f"(proposed {sc['true_proposed'][0]:.4f}, accepted {sc['true_accepted'][0]:.4f}) ratio {r['ratio'][e][0]:.3f}; "
                f"rot ratio {r['ratio'][e][1]:.3f}"
            )
        print(
            f"  ranking reviewed {r['ranking_reviewed']} true {r['ranking_true']}: same "
            f"{r['same_ranking']}; translation means within 10 %: {r['within_10_percent']}, "
            f"rotation means: {r['rotation_within_10_percent']}"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
