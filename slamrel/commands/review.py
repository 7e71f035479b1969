"""``slamrel review``: a page to check and correct a landmark association in a browser."""

from __future__ import annotations

import argparse
import os
from typing import TYPE_CHECKING

from slamrel.commands import options as opt
from slamrel.commands.common import check_outputs, errors_about

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    from landmark_graph.landmark_association import Association
    from landmark_graph.maps import LandmarkMap


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "review",
        help="write an HTML page to review and correct a landmark association",
        description="Writes one self-contained HTML page (opens from a file, no network): both "
        "maps in the reference frame after the alignment the association implies, the proposed "
        "pairs coloured by residual, unmatched landmarks on both sides. Accept or reject pairs, "
        "draw new ones, then save the association CSV and pass it to "
        "'slamrel map-compare --associate FILE'. The page reads a saved CSV back to continue.",
    )
    p.add_argument("estimate", metavar="ESTIMATE_MAP")
    p.add_argument("reference", metavar="REFERENCE_MAP")
    p.add_argument(
        "-o", "--output", default="review.html", metavar="F.html", help="(default: review.html)"
    )
    p.add_argument(
        "--associate",
        default="id",
        metavar="id|auto|FILE",
        help="the proposal to review, as in map-compare: by id, automatic (alignment and "
        "optimal assignment within --cutoff) or an association CSV (default: id)",
    )
    p.add_argument(
        "--cutoff",
        type=opt.positive_float,
        default=1.0,
        help="auto-association cut-off c [m]; residual colours saturate at c (default: 1)",
    )
    p.add_argument("--seed", type=opt.seed, default=0, help="seed of the automatic association")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=run)


def proposal(
    mode: str, est: LandmarkMap, ref: LandmarkMap, *, cutoff: float, seed: int
) -> Association:
    """The association named by ``--associate id|auto|FILE``."""
    from landmark_graph.landmark_association import associate_auto, associate_by_id
    from slamrel.formats.associations import read_association_csv

    if mode == "id":
        return associate_by_id(est, ref)
    if mode == "auto":
        return associate_auto(est, ref, cutoff=cutoff, seed=seed)
    return read_association_csv(mode, est, ref)


def run(args: argparse.Namespace) -> int:
    from slamrel.formats.landmark_maps import read_map
    from slamrel.review.page import write_review

    assoc_file = None if args.associate in ("id", "auto") else args.associate
    check_outputs([args.output], [args.estimate, args.reference, assoc_file])
    est = read_map(args.estimate)
    ref = read_map(args.reference)
    with errors_about(args.estimate):
        assoc = proposal(args.associate, est, ref, cutoff=args.cutoff, seed=args.seed)
    names = (os.path.basename(args.estimate), os.path.basename(args.reference))
    data = write_review(
        args.output,
        est,
        ref,
        assoc,
        cutoff=args.cutoff,
        names=names,
        title=f"slamrel review — {names[0]} against {names[1]}",
    )
    if not args.quiet:
        n_susp = int((data.suspicion >= 0.5).sum())
        print(
            f"{assoc.estimate_rows.size} proposed pairs ({n_susp} with suspicion >= 0.5), "
            f"{assoc.missed.size} missed, {assoc.spurious.size} spurious; "
            f"alignment: {data.alignment_source}"
        )
        print(
            f"review: {args.output} (open it in a browser; save the CSV and pass it to "
            "map-compare --associate)"
        )
    return 0
