"""``slamrel compare``: a comparison table over results, like Kümmerle et al.'s Sec. VI."""

from __future__ import annotations

import argparse
import re
import textwrap
from dataclasses import replace
from pathlib import Path

from relation_metric.constants import BOOTSTRAP_RESAMPLES, MIN_BLOCKS, OVERLAP_FACTOR
from relation_metric.errors import OptionError
from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, check_outputs

_SPEC = re.compile(r"^(?P<dataset>[^:=]+):(?P<algorithm>[^=]+)=(?P<path>.+)$")


DESCRIPTION = (
    "Each RESULT is DATASET:ALGORITHM=PER_RELATION.csv, the --per-relation output of slamrel "
    "evaluate (or a relations_*.csv of slamrel run). Writes table.md, table.csv (errors per "
    "dataset and algorithm, mean ± std as Kümmerle et al. tabulate them), tests.csv (the "
    "tests), table.tex and errors.png to -o."
)

_TESTS = (
    "Every pair of algorithms of a dataset is compared on the relations both scored, one test "
    "per relation set (the 'set' column the per-relation CSV has when slamrel run or slamrel "
    "evaluate --strategy wrote it; without it all relations are one set 'all') and per part "
    "(translation in m, rotation in rad or deg): the mean difference A - B of the abs errors "
    "(negative: A is better), in the part's unit and in % of B's mean.",
    "Relations that share a stretch of the run are not independent (drift enters all of "
    "them), so the pairs are not resampled one by one: a circular block bootstrap resamples "
    "blocks of L consecutive differences, the relations ordered by start time. It gives the "
    "(1 - alpha) confidence interval of the mean difference and a two-sided p-value, (1 + "
    "#resamples at least as far from 0) / (B + 1), which is never 0: at its floor it is "
    f"printed '< 1/B'. L is the largest of {OVERLAP_FACTOR} x (1 + the mean number of later "
    "relations a relation overlaps in time), the Politis-White length from the "
    f"autocorrelation of the differences, and n^(1/3). With fewer than {MIN_BLOCKS} blocks "
    "(loop and global relations, which overlap one another nearly everywhere) there is no "
    "test: the table gives the difference and says why.",
    "The p-values of all tests of the table are Holm-adjusted together; 'better' names the "
    "algorithm with the smaller mean error when the adjusted p-value is below --alpha. "
    "--seed makes the resampling repeatable (the same inputs and seed give the same table).",
)


def _paragraphs(*texts: str, indent: str = "") -> str:
    return "\n\n".join(
        textwrap.fill(t, 88, initial_indent=indent, subsequent_indent=indent) for t in texts
    )


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "compare",
        help="compare results (algorithms × datasets) with paired significance tests",
        description=_paragraphs(DESCRIPTION),
        epilog="the tests:\n" + _paragraphs(*_TESTS, indent="  "),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "results",
        nargs="+",
        metavar="RESULT",
        help="per-relation CSVs of slamrel evaluate --per-relation, one per algorithm",
    )
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write")
    p.add_argument(
        "--alpha",
        type=opt.probability,
        default=0.05,
        help="significance level (Holm-adjusted); intervals at 1 - alpha (default %(default)s)",
    )
    p.add_argument(
        "--resamples",
        type=opt.int_range(99, 10**7),
        default=BOOTSTRAP_RESAMPLES,
        metavar="B",
        help="bootstrap resamples per test (default %(default)s)",
    )
    p.add_argument(
        "--seed",
        type=opt.seed,
        default=0,
        help="seed of the bootstrap (default: %(default)s)",
    )
    add_force_argument(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from slamrel.outputs import staged_directory, write_text_atomic
    from slamrel.report.tables import compare_results, read_per_relation

    specs = []
    for spec in args.results:
        m = _SPEC.match(spec)
        if not m:
            raise OptionError(
                f"{spec!r}: expected DATASET:ALGORITHM=PER_RELATION.csv", option="RESULT"
            )
        specs.append(m)
    check_outputs([], [m["path"] for m in specs], dirs=[args.output], force=args.force)
    results = [
        replace(
            read_per_relation(m["path"], dataset=m["dataset"], algorithm=m["algorithm"]),
            source=m["path"],
        )
        for m in specs
    ]
    comp = compare_results(results, alpha=args.alpha, resamples=args.resamples, seed=args.seed)
    with staged_directory(Path(args.output), kind="compare", force=args.force) as out:
        write_text_atomic(out / "table.md", comp.markdown())
        write_text_atomic(out / "table.csv", comp.csv())
        write_text_atomic(out / "tests.csv", comp.tests_csv())
        write_text_atomic(out / "table.tex", comp.latex())
        _figure(comp, out / "errors.png")
    if not args.quiet:
        print(comp.markdown(), end="")
    return 0


def _figure(comp, path: Path) -> None:  # type: ignore[no-untyped-def]
    import numpy as np

    from slamrel.plots.relation_errors import literal_text, pyplot, save_figure

    plt = pyplot()
    datasets = list(dict.fromkeys(ds for ds, _ in comp.stats))
    algorithms = list(dict.fromkeys(alg for _, alg in comp.stats))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    width = 0.8 / max(len(algorithms), 1)
    x = np.arange(len(datasets))
    for ax, part, unit in (
        (axes[0], "translation", "m"),
        (axes[1], "rotation", comp.rotation_unit),
    ):
        for k, alg in enumerate(algorithms):
            means = [
                comp.stats[(ds, alg)].part(part, "abs").mean if (ds, alg) in comp.stats else np.nan
                for ds in datasets
            ]
            stds = [
                comp.stats[(ds, alg)].part(part, "abs").std if (ds, alg) in comp.stats else np.nan
                for ds in datasets
            ]
            bar_x = x + k * width - 0.4 + width / 2
            ax.bar(bar_x, means, width, yerr=stds, capsize=3, label=literal_text(alg))
        ax.set_xticks(x, [literal_text(ds) for ds in datasets])
        ax.set_ylabel(f"{part} error, abs [{unit}] (mean ± std)")
    axes[0].legend()
    save_figure(fig, path)
