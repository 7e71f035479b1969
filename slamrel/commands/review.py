"""``slamrel review``: a page to check and correct a landmark association in a browser."""

from __future__ import annotations

import argparse
import os
from typing import TYPE_CHECKING

from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_association_arguments,
    association_choice,
    association_file,
    check_outputs,
    errors_about,
    in_option_words,
)

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
    p.add_argument("estimate", metavar="ESTIMATE_MAP", help="estimated landmark map (CSV)")
    p.add_argument("reference", metavar="REFERENCE_MAP", help="reference landmark map (CSV)")
    p.add_argument(
        "-o", "--output", default="review.html", metavar="F.html", help="(default: review.html)"
    )
    add_association_arguments(p, align=False)  # the proposal to review, as in map-compare
    p.add_argument(
        "--cutoff",
        type=opt.length,
        default=1.0,
        help="auto-association cut-off c [m]; residual colours saturate at c (default: 1)",
    )
    p.add_argument(
        "--seed",
        type=opt.seed,
        default=0,
        help="seed of the automatic association (default: %(default)s)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def proposal(
    mode: str, est: LandmarkMap, ref: LandmarkMap, *, cutoff: float, seed: int
) -> Association:
    """The association named by ``--associate id-or-auto|id|auto|FILE`` (as ``map-compare``
    chooses it; by id, a proposal may be empty: pairs can be drawn on the page)."""
    from landmark_graph.landmark_association import associate_by_id
    from landmark_graph.map_compare import choose_association

    how = association_choice(mode, est, ref)
    if not isinstance(how, str):
        return how
    if how == "id":
        return associate_by_id(est, ref)
    words = {"on a review page": "on this page", "as the association": "with --associate FILE"}
    with in_option_words(words):  # no pair found: the page without pairs, said (a warning)
        choice = choose_association(est, ref, how, cutoff=cutoff, seed=seed, allow_empty=True)
    return choice.association


def run(args: argparse.Namespace) -> int:
    from slamrel.formats.landmark_maps import read_map
    from slamrel.review.page import write_review

    check_outputs([args.output], [args.estimate, args.reference, association_file(args.associate)])
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
