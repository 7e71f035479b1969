"""``slamrel compare``: a comparison table over results, like Kümmerle et al.'s Sec. VI."""

from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path

from relation_metric.errors import InputError
from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, check_outputs

_SPEC = re.compile(r"^(?P<dataset>[^:=]+):(?P<algorithm>[^=]+)=(?P<path>.+)$")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "compare",
        help="compare results (algorithms × datasets) with paired significance tests",
        description="Each RESULT is DATASET:ALGORITHM=PER_RELATION.csv, the --per-relation "
        "output of slamrel evaluate. Writes table.md, table.csv, table.tex and errors.png to -o.",
    )
    p.add_argument("results", nargs="+", metavar="RESULT")
    p.add_argument("-o", "--output", required=True, metavar="DIR")
    p.add_argument(
        "--alpha", type=opt.probability, default=0.05, help="significance level (Holm-adjusted)"
    )
    add_force_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from slamrel.outputs import staged_directory, write_text_atomic
    from slamrel.report.tables import compare_results, read_per_relation

    specs = []
    for spec in args.results:
        m = _SPEC.match(spec)
        if not m:
            raise InputError(f"result {spec!r}: expected DATASET:ALGORITHM=PER_RELATION.csv")
        specs.append(m)
    check_outputs([], [m["path"] for m in specs], dirs=[args.output], force=args.force)
    results = [
        replace(
            read_per_relation(m["path"], dataset=m["dataset"], algorithm=m["algorithm"]),
            source=m["path"],
        )
        for m in specs
    ]
    comp = compare_results(results, alpha=args.alpha)
    with staged_directory(Path(args.output), kind="compare", force=args.force) as out:
        write_text_atomic(out / "table.md", comp.markdown())
        write_text_atomic(out / "table.csv", comp.csv())
        write_text_atomic(out / "table.tex", comp.latex())
        _figure(comp, out / "errors.png")
    if not args.quiet:
        print(comp.markdown(), end="")
    return 0


def _figure(comp, path: Path) -> None:  # type: ignore[no-untyped-def]
    import numpy as np

    from slamrel.plots.relation_errors import pyplot, save_figure

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
                comp.stats[(ds, alg)][part]["abs"].mean if (ds, alg) in comp.stats else np.nan
                for ds in datasets
            ]
            stds = [
                comp.stats[(ds, alg)][part]["abs"].std if (ds, alg) in comp.stats else np.nan
                for ds in datasets
            ]
            ax.bar(x + k * width - 0.4 + width / 2, means, width, yerr=stds, capsize=3, label=alg)
        ax.set_xticks(x, datasets)
        ax.set_ylabel(f"{part} error, abs [{unit}] (mean ± std)")
    axes[0].legend()
    save_figure(fig, path)
