"""Issue 38's end-to-end acceptance: EKF-SLAM on point landmarks while a laser is logged,
reference relations made from the scans and reviewed by script, the recovered trajectory
(and the online one, and dead reckoning) scored against them and against the true relations.

The story is :func:`slamrel.studies.end_to_end.end_to_end` (pillar world, reference
EKF-SLAM, recovery, ``relations align``'s global aligner from the scans' own chain, scripted
review). Acceptance: every estimate's mean translational error against the laser relations
within 10 % of its mean against the true relations (at the truth's pairs), and the same
ranking recovered / online / dead reckoning.

    python benchmarks/end_to_end.py [--seeds 0 1 2] [--no-confirm] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import time

from slamrel.studies.end_to_end import ESTIMATES, REFERENCES, end_to_end


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument(
        "--no-confirm",
        action="store_true",
        help="reject every flagged relation (default: accept those their cycles confirm)",
    )
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args()
    out = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        r = end_to_end(seed, confirm=not args.no_confirm)
        wall = time.perf_counter() - t0
        print(
            f"seed {seed}: map {r.map_landmarks} of {r.landmarks} pillars; {r.pairs} laser pairs "
            f"({r.loop_pairs} loop; from the truth {r.true_pairs}, {r.true_loop_pairs} loop), "
            f"{r.flagged} flagged, {r.confirmed} confirmed, {r.contradicted} contradicted, "
            f"{r.accepted} accepted ({r.gross_accepted} grossly wrong); {wall:.1f} s"
        )
        for e in ESTIMATES:
            sc = r.scores[e]
            print(
                f"  {e:15s} laser {sc['laser'][0]:.4f} m true {sc['true'][0]:.4f} m "
                f"(same pairs {sc['true_accepted'][0]:.4f}) ratio {r.ratio(e):.3f}; "
                f"rot ratio {r.ratio(e, 1):.3f}"
            )
        print(
            f"  ranking laser {r.ranking('laser')} true {r.ranking('true')}: same "
            f"{r.same_ranking}; means within 10 %: {r.within_10_percent}"
        )
        out.append(
            {
                "seed": seed,
                "scores": {e: {k: r.scores[e][k] for k in REFERENCES} for e in ESTIMATES},
                "ratio": {e: [r.ratio(e), r.ratio(e, 1)] for e in ESTIMATES},
                "ranking_laser": r.ranking("laser"),
                "ranking_true": r.ranking("true"),
                "same_ranking": r.same_ranking,
                "within_10_percent": r.within_10_percent,
                "pairs": r.pairs,
                "loop_pairs": r.loop_pairs,
                "flagged": r.flagged,
                "confirmed": r.confirmed,
                "accepted": r.accepted,
                "gross_accepted": r.gross_accepted,
                "wall_s": wall,
            }
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
