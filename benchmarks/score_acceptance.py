"""Acceptance of issue 37: scoring against relations made by scan alignment and reviewed
gives the ranking and the means of scoring against the true relations.

A simulated laser log of the ``"loop"`` world (:mod:`slamrel.simulation.laser`: the corridor
around the block, driven once and on past the start, 1 cm range noise, drifting odometry).
Relations are made as ``slamrel relations align`` makes them, through its public functions:
consecutive keyframes every 0.5 m (``--keyframes``, below) and loop pairs (``--loops``), the
global aligner (:func:`slamrel.scans.global_align.align_scans_global`, default options). Pairs and guesses
come from ``--guesses``: ``chain`` (default) the scans' own scan-matched odometry
(:func:`slamrel.scans.own_guesses.chain_guesses`, built from the log's odometry: no truth,
no estimate), ``odometry`` the log's odometry itself (from which seed 2 proposes no loop
pair), ``truth`` the true poses (a check that the harness can pass). The scripted review
accepts the unflagged relations and rejects the flagged ones; with ``--cycle-check`` the
relations the cycle check contradicts (:func:`slamrel.scans.cycles.check_scan_relations`)
are rejected too; with ``--confirm`` the relations flagged only ``large correction`` or only
``ambiguous`` that their cycles confirm (≥ 2 cycles, none failed, with the unflagged ones)
are accepted — what a person does with a flagged relation its neighbours agree with.

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
        [--guesses chain|odometry|truth] [--world loop|corridor] [--loop-max-angle DEG]
        [--keyframes travel|motion] [--adjust] [--json OUT]

With ``--adjust`` the accepted relations are also adjusted
(:func:`slamrel.backends.relation_adjust.adjust_relations`: a least-squares pose-graph fit over the
accepted relations weighted by their covariances, the relations re-read from the fitted
poses) and scored as ``adjusted`` beside ``reviewed``; the accepted relations' error
against the truth (mean, median, p99) is printed before and after.

Loop pairs are kept only where the two headings differ by at most ``--loop-max-angle``
(:data:`LOOP_MAX_ANGLE`, 45°; 180 keeps every one, ``relations align``'s default): pairs
seen from opposite headings are the aliasing ones in corridors.

Keyframes go by ``--keyframes`` (:data:`KEYFRAMES`, ``travel``: one every 0.5 m of path,
``relations align --keyframes travel``; ``motion`` is the command's default), for the
reviewed and the true pairs alike. By motion, drifting guesses keep fewer keyframes than
the exact 0.1 m steps of the corridor worlds' truth, and 12–20 % fewer loop pairs, which
lowered the drifting estimates' reviewed means by 3–11 % (benchmarks/README.md).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import fields

import numpy as np

from relation_metric import se2
from relation_metric.evaluate import evaluate
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory
from slamrel.scans.proposals import (
    LOOP_GROWTH_ANGLE,
    SPACINGS,
    Proposals,
    consecutive_pairs,
    drop_unseen_loops,
    expected_overlap,
    keep_overlapping,
    keep_within_reach,
    loop_pairs,
)
from slamrel.scans.relations import (
    AlignOptions,
    align_scans,
    guesses_from_poses,
)
from slamrel.scans.scripted_review import scripted_review
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

CORNERS = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])
ESTIMATES = ("jitter", "odometry", "drift")
#: Largest heading difference of a loop pair [rad] (``--loop-max-angle`` in degrees): two
#: scans of a corridor seen from opposite headings share little and alias most.
LOOP_MAX_ANGLE = np.pi / 4
#: How keyframes are spaced (``--keyframes``, :func:`slamrel.scans.proposals.keyframes`):
#: ``travel`` keeps the drifting guesses' pairs as dense as the truth's.
KEYFRAMES = "travel"


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


def _pairs(
    poses: np.ndarray,
    times: np.ndarray,
    max_angle: float = LOOP_MAX_ANGLE,
    spacing: str = KEYFRAMES,
    growth: float = 0.0,
) -> Proposals:
    """``relations align --loops``' pairs with its defaults, proposed from ``poses``, loop
    pairs at most ``max_angle`` [rad] apart in heading (``--loop-max-angle``), keyframes
    by ``spacing`` (``--keyframes``); ``growth`` [m/m] widens the loop pairs' radius and
    heading limit by the travel between them (``--loop-growth``: candidates, see
    :func:`slamrel.scans.proposals.within_reach`)."""
    prop = consecutive_pairs(poses, times, distance=0.5, angle=0.3, spacing=spacing)
    return prop + loop_pairs(
        poses,
        times,
        radius=1.0,
        min_travel=10.0,
        distance=0.5,
        angle=0.3,
        max_angle=max_angle,
        spacing=spacing,
        growth=growth,
        growth_angle=growth * LOOP_GROWTH_ANGLE,
    )


def run(
    seed: int,
    *,
    cycle_check: bool = False,
    confirm: bool = False,
    guesses: str = "odometry",
    aligner: str = "global",
    world: str = "loop",
    loop_max_angle: float = LOOP_MAX_ANGLE,
    keyframes: str = KEYFRAMES,
    loop_growth: float = 0.0,
    adjust: bool = False,
    min_overlap: float = 0.0,
) -> dict:
    """One simulated log: relations made and reviewed, three estimates scored both ways.

    ``guesses``: the poses that propose the pairs and give the alignments their guesses —
    the log's ``odometry`` (the honest start), or the ``truth`` (to check that the harness
    can pass when the aligner gets every pair right). ``aligner``: ``global`` (the command's
    default, :func:`slamrel.scans.global_align.align_scans_global`) or ``icp`` (ICP from the
    guess, :func:`slamrel.scans.relations.align_scans`)."""
    log = _log(world, seed)
    s = log.scans
    odo = s.laser_pose
    t0 = time.process_time()
    start = _start(guesses, log)
    candidates_all = _pairs(start, s.timestamps, loop_max_angle, keyframes, loop_growth)
    t_overlap = time.process_time()
    prop, unseen = drop_unseen_loops(  # --loop-min-overlap: before alignment
        candidates_all,
        s,
        start,
        min_overlap=min_overlap,
        growth=loop_growth,
        growth_angle=loop_growth * LOOP_GROWTH_ANGLE,
        radius=1.0 if loop_growth > 0 else None,
    )
    t_overlap = time.process_time() - t_overlap
    wrongly = _wrongly_left_out(candidates_all, prop, log.truth, s, min_overlap)
    res = _aligned(aligner, s, prop, start)
    candidates = len(prop)
    if loop_growth > 0:  # the loop rule on the aligned motion: what the scans say
        res = keep_within_reach(res, radius=1.0, max_angle=loop_max_angle)
    res, apart = keep_overlapping(res, s, min_overlap=min_overlap)  # and after
    prop = res.proposals
    cpu = time.process_time() - t0
    review = scripted_review(res, cycle_check=cycle_check, confirm=confirm)
    accept, contradicted, confirmed = review.accepted, review.contradicted, review.confirmed
    true = guesses_from_poses(log.truth, prop)
    err = se2.between(true, res.delta)
    gross = _gross(err)
    p = prop.pairs
    reviewed = RelationSet(prop.t1[accept], prop.t2[accept], res.delta[accept])
    extra, adjusted = _adjusted(res, accept, true) if adjust else ({}, None)
    ideal_all, ideal, true_ideal, true_all = _truth_sets(
        log.truth, s, loop_max_angle, keyframes, min_overlap
    )
    true_prop = RelationSet(prop.t1, prop.t2, true)
    true_acc = RelationSet(prop.t1[accept], prop.t2[accept], true[accept])
    sets = {
        "reviewed": reviewed,
        "true": true_ideal,
        "true_all": true_all,
        "true_proposed": true_prop,
        "true_accepted": true_acc,
        **({"adjusted": adjusted} if adjusted is not None else {}),
    }
    scores = {
        name: {k: _score(rel, s.timestamps, poses) for k, rel in sets.items()}
        for name, poses in estimates(log.truth, odo, seed).items()
    }
    return {
        "seed": seed,
        "scans": len(s),
        "pairs": len(prop),
        "loop_pairs": int(np.count_nonzero(prop.kind == "loop")),
        "true_pairs": len(ideal),
        "true_loop_pairs": int(np.count_nonzero(ideal.kind == "loop")),
        "true_loop_pairs_all": int(np.count_nonzero(ideal_all.kind == "loop")),
        "min_overlap": min_overlap,
        "unseen_before": unseen,
        "unseen_after": apart,
        "overlap_cpu_s": t_overlap,
        "wrongly_left_out": wrongly,
        "loop_flagged": int((res.flagged & (prop.kind == "loop")).sum()),
        "loop_accepted": int((accept & (prop.kind == "loop")).sum()),
        "guesses": guesses,
        "loop_max_angle_deg": float(np.degrees(loop_max_angle)),
        "keyframes": keyframes,
        "loop_growth": loop_growth,
        "candidates": candidates,
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
        **extra,
        **({"adjusted_verdict": verdict(scores, "adjusted")} if adjust else {}),
    }


def _start(guesses: str, log) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The poses that propose the pairs and guess them: ``odometry``, ``truth`` or ``chain``
    (scan-matched odometry: the scans' own chain, :mod:`slamrel.scans.own_guesses`)."""
    odo = log.scans.laser_pose
    start = {"odometry": odo, "truth": log.truth}.get(guesses)
    if start is None:
        from slamrel.scans.own_guesses import chain_guesses

        start = chain_guesses(log.scans, odo).poses
    return start


def _aligned(aligner: str, scans, prop: Proposals, start: np.ndarray):  # type: ignore[no-untyped-def]
    """``prop`` aligned by the ``global`` aligner or by ``icp`` from the guesses ``start``."""
    if aligner == "global":
        from slamrel.scans.global_align import align_scans_global

        return align_scans_global(scans, prop, start, AlignOptions())[0]
    return align_scans(scans, prop, guesses_from_poses(start, prop), AlignOptions())


def _log(world: str, seed: int):  # type: ignore[no-untyped-def]
    """The simulated laser log of ``world`` (``loop`` or ``corridor``) and ``seed``."""
    if world == "corridor":  # slamrel.simulation.corridors: a 200 m drive, world ``seed``
        from slamrel.simulation.corridors import corridor_log

        return corridor_log(seed)[1]
    truth = loop_path(CORNERS, 0.3)
    truth = np.vstack((truth, truth[:60]))  # on past the start: loop closures
    return simulate_laser_log(laser_world("loop"), truth, seed=seed)


def _truth_sets(  # type: ignore[no-untyped-def]
    truth: np.ndarray, scans, loop_max_angle: float, keyframes: str, min_overlap: float
) -> tuple[Proposals, Proposals, RelationSet, RelationSet]:
    """The truth's pairs (all, and those the overlap rule keeps at the true relation) and
    their true relations (kept, all)."""
    ideal_all = _pairs(truth, scans.timestamps, loop_max_angle, keyframes)
    d_all = guesses_from_poses(truth, ideal_all)
    ov = expected_overlap(scans, ideal_all.pairs, d_all, spread_xy=0.0, spread_theta=0.0)
    keep = (ideal_all.kind != "loop") | (ov >= min_overlap)
    ideal = Proposals(*(getattr(ideal_all, f.name)[keep] for f in fields(Proposals)))
    true_ideal = RelationSet(ideal.t1, ideal.t2, d_all[keep])
    true_all = RelationSet(ideal_all.t1, ideal_all.t2, d_all)
    return ideal_all, ideal, true_ideal, true_all


def _wrongly_left_out(
    before: Proposals, after: Proposals, truth: np.ndarray, scans, min_overlap: float
) -> int:
    """Loop candidates the test before alignment left out although their true relation
    lies within the 1 m radius and overlaps by ``min_overlap`` (exact, at the truth)."""
    kept = {tuple(p) for p in after.pairs.tolist()}
    out = np.array([tuple(p) not in kept for p in before.pairs.tolist()], dtype=bool)
    out &= before.kind == "loop"
    if not out.any():
        return 0
    p = before.pairs[out]
    d = se2.between(truth[p[:, 0]], truth[p[:, 1]])
    ov = expected_overlap(scans, p, d, spread_xy=0.0, spread_theta=0.0)
    return int(((np.hypot(d[:, 0], d[:, 1]) <= 1.0) & (ov >= min_overlap)).sum())


def _adjusted(res, accept: np.ndarray, true: np.ndarray) -> tuple[dict, RelationSet]:
    """``--adjust``: the accepted relations of ``res`` after the pose-graph fit, and what it
    did (counts, CPU time, their error against the ``true`` relations before and after)."""
    from slamrel.backends.relation_adjust import adjust_relations

    t1 = time.process_time()
    prop = res.proposals
    p = prop.pairs
    adj = adjust_relations(p[:, 0], p[:, 1], res.delta, res.covariance, use=accept)
    err_adj = se2.between(true, adj.delta)
    extra = {
        "adjust_cpu_s": time.process_time() - t1,
        "adjusted": int(adj.adjusted.sum()),
        "set_aside": int(adj.set_aside.sum()),
        "redundancy": adj.redundancy,
        "error_before": _error_stats(se2.between(true, res.delta)[accept]),
        "error_after": _error_stats(err_adj[accept]),
        "gross_after": int((_gross(err_adj) & accept).sum()),
    }
    return extra, RelationSet(prop.t1[accept], prop.t2[accept], adj.delta[accept])


def _print_adjusted(r: dict) -> None:
    """The ``--adjust`` lines of one seed's result ``r``."""
    a, b = r["error_before"], r["error_after"]
    v = r["adjusted_verdict"]
    print(
        f"  adjusted: {r['adjusted']} relations moved, {r['set_aside']} set aside, "
        f"redundancy {r['redundancy']}, {r['adjust_cpu_s']:.2f} CPU-s; accepted "
        f"relations' error mean / median / p99 {a['mm_mean']:.2f} / "
        f"{a['mm_median']:.2f} / {a['mm_p99']:.2f} mm -> {b['mm_mean']:.2f} / "
        f"{b['mm_median']:.2f} / {b['mm_p99']:.2f} mm, {a['deg_mean']:.4f} / "
        f"{a['deg_median']:.4f} / {a['deg_p99']:.3f}° -> {b['deg_mean']:.4f} / "
        f"{b['deg_median']:.4f} / {b['deg_p99']:.3f}°; gross {r['gross_after']}"
    )
    print(
        "  adjusted ratios "
        + ", ".join(f"{e} {v['ratio'][e][0]:.3f}" for e in ESTIMATES)
        + f"; same ranking {v['same_ranking']}; within 10 %: {v['within_10_percent']}"
    )


def _gross(err: np.ndarray) -> np.ndarray:
    """Relations off the truth by more than 10 cm or 2° (``err``: (P, 3))."""
    return (np.hypot(err[:, 0], err[:, 1]) > 0.1) | (np.abs(err[:, 2]) > np.radians(2))


def _error_stats(err: np.ndarray) -> dict:
    """Mean, median and 99th percentile of the translational [mm] and rotational [deg]
    error of relations (``err``: (P, 3), relation ⊖ truth)."""
    t = 1000 * np.hypot(err[:, 0], err[:, 1])
    r = np.degrees(np.abs(err[:, 2]))
    return {
        f"{name}_{q}": float(f(v))
        for name, v in (("mm", t), ("deg", r))
        for q, f in (
            ("mean", np.mean),
            ("median", np.median),
            ("p99", lambda a: np.percentile(a, 99)),
        )
    }


def _ranking(scores: dict, which: str, part: int) -> list[str]:
    return sorted(ESTIMATES, key=lambda e: scores[e][which][part])


def verdict(scores: dict, which: str = "reviewed") -> dict:
    """Ranking equality (translation, rotation) and the mean ratios ``which`` (reviewed, or
    adjusted) / true."""
    ratio = {e: [scores[e][which][k] / scores[e]["true"][k] for k in (0, 1)] for e in ESTIMATES}
    same = all(_ranking(scores, which, k) == _ranking(scores, "true", k) for k in (0, 1))
    return {
        "ranking_reviewed": _ranking(scores, which, 0),
        "ranking_true": _ranking(scores, "true", 0),
        "same_ranking": same,
        "ratio": ratio,
        "within_10_percent": all(abs(ratio[e][0] - 1.0) <= 0.10 for e in ESTIMATES),
        "rotation_within_10_percent": all(abs(ratio[e][1] - 1.0) <= 0.10 for e in ESTIMATES),
    }


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--cycle-check", action="store_true")
    ap.add_argument("--confirm", action="store_true")
    ap.add_argument("--guesses", choices=("odometry", "chain", "truth"), default="chain")
    ap.add_argument("--aligner", choices=("global", "icp"), default="global")
    ap.add_argument(
        "--world",
        choices=("loop", "corridor"),
        default="loop",
        help="loop (default) or a corridor world of slamrel.simulation.corridors (seeds 101...)",
    )
    ap.add_argument(
        "--loop-max-angle",
        type=float,
        default=float(np.degrees(LOOP_MAX_ANGLE)),
        metavar="DEG",
        help="largest heading difference of a loop pair [deg] (default 45; 180: any)",
    )
    ap.add_argument(
        "--keyframes",
        choices=SPACINGS,
        default=KEYFRAMES,
        help="keyframe spacing of the pairs (relations align --keyframes; default travel)",
    )
    ap.add_argument(
        "--loop-growth",
        type=float,
        default=0.0,
        metavar="M",
        help="loop candidates within 1 m + M per metre travelled between them (and the "
        "heading limit + 0.05 M rad/m), kept when their aligned motion is within 1 m and "
        "the heading limit (default 0: the pairs the guesses propose)",
    )
    ap.add_argument(
        "--adjust",
        action="store_true",
        help="also score the accepted relations adjusted by a pose-graph fit over them "
        "(slamrel.backends.relation_adjust)",
    )
    ap.add_argument(
        "--min-overlap",
        type=float,
        default=0.0,
        metavar="F",
        help="relations align --loop-min-overlap: leave out loop pairs whose scans cannot "
        "share F of their returns (before alignment, within the guesses' uncertainty) or "
        "do not (after, at the aligned pose); the truth's loop pairs by the same rule at "
        "the true relation (default 0: keep all)",
    )
    ap.add_argument("--json", metavar="OUT")
    return ap


def main() -> None:
    ap = _parser()
    args = ap.parse_args()
    if not 0 < args.loop_max_angle <= 180:
        ap.error("--loop-max-angle must lie in (0, 180] degrees")
    out = []
    for seed in args.seeds:
        r = run(
            seed,
            cycle_check=args.cycle_check,
            confirm=args.confirm,
            guesses=args.guesses,
            aligner=args.aligner,
            world=args.world,
            loop_max_angle=float(np.radians(args.loop_max_angle)),
            keyframes=args.keyframes,
            loop_growth=args.loop_growth,
            adjust=args.adjust,
            min_overlap=args.min_overlap,
        )
        out.append(r)
        _print_run(seed, r, adjust=args.adjust)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


def _print_run(seed: int, r: dict, *, adjust: bool) -> None:
    """The lines :func:`main` prints for one seed's result ``r`` (:func:`run`)."""
    print(
        f"seed {seed}, guesses from {r['guesses']}: {r['pairs']} pairs of {r['candidates']} candidates ({r['loop_pairs']} "
        f"loop; from the truth {r['true_pairs']}, {r['true_loop_pairs']} loop), "
        f"{r['flagged']} flagged ({100 * r['flagged'] / r['pairs']:.1f} %; loop pairs "
        f"within {r['loop_max_angle_deg']:g}°), "
        f"{r['contradicted']} contradicted, {r['confirmed']} confirmed, "
        f"{r['accepted']} accepted "
        f"({r['gross_accepted']} of {r['gross']} gross ones accepted); "
        f"{r['pairs_per_cpu_s']:.1f} pairs/CPU-s"
    )
    print(
        f"  loop pairs: {r['loop_flagged']} flagged, {r['loop_accepted']} accepted; "
        f"overlap < {r['min_overlap']:g}: {r['unseen_before']} candidates left out before "
        f"alignment ({r['overlap_cpu_s']:.2f} CPU-s: overlap test; "
        f"{r['wrongly_left_out']} of them within 1 m and overlapping by the truth), "
        f"{r['unseen_after']} "
        f"after; truth's loop pairs {r['true_loop_pairs']} of {r['true_loop_pairs_all']}"
    )
    for e in ESTIMATES:
        sc = r["scores"][e]
        print(
            f"  {e:9s} trans reviewed {sc['reviewed'][0]:.4f} true {sc['true'][0]:.4f} "
            f"(proposed {sc['true_proposed'][0]:.4f}, accepted {sc['true_accepted'][0]:.4f}) ratio {r['ratio'][e][0]:.3f}; "
            f"rot ratio {r['ratio'][e][1]:.3f}; "
            f"ratio to every truth pair {sc['reviewed'][0] / sc['true_all'][0]:.3f}"
        )
    print(
        f"  ranking reviewed {r['ranking_reviewed']} true {r['ranking_true']}: same "
        f"{r['same_ranking']}; translation means within 10 %: {r['within_10_percent']}, "
        f"rotation means: {r['rotation_within_10_percent']}"
    )
    if adjust:
        _print_adjusted(r)


if __name__ == "__main__":
    main()
