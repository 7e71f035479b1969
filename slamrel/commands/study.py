"""``slamrel study pose-only``: Hu, Huang & Dissanayake's study of pose-only SLAM, reproduced;
``slamrel study verdict-calibration``: the verdict's lamps on healthy and broken runs.

Writes into the output folder, which is reused when the study is run again (finished cases
are skipped; :func:`slamrel.outputs.resumable_directory`: only an absent or empty
folder, or a study folder slamrel wrote, is accepted; each file is written atomically):

* ``cases/`` — one JSON result per (world, noise, seed, method), the resumable state;
* ``table.md``, ``table.csv``, ``table.tex`` — the Tables II/III analogue;
* ``fig1_sigma_bounds.png``, ``fig2_nees1.png`` — the Fig. 1 / Fig. 2 analogues;
* ``findings.md`` — the paper's findings, each checked (holds or not, with the numbers).

``verdict-calibration`` (:mod:`slamrel.studies.calibration`) writes ``cases/`` and
``calibration.md`` / ``calibration.json``: per lamp, how often it is green on runs healthy by
construction and red on broken ones (``--runs`` seeds per world × noise × map form × fault).
"""

from __future__ import annotations

import argparse
import sys

from slamrel.commands import options as opt
from slamrel.constants import NOISE_NAMES, PAPER_WORLDS, POSE_ONLY_METHODS, WORLDS

STUDIES = ("pose-only", "verdict-calibration")


def _names(allowed: tuple[str, ...], what: str):  # type: ignore[no-untyped-def]
    def parse(text: str) -> list[str]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        bad = [t for t in items if t not in allowed]
        if not items or bad:
            raise argparse.ArgumentTypeError(
                f"expected a comma-separated list of {what} ({', '.join(allowed)}), got {text!r}"
            )
        return items

    return parse


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    s = sub.add_parser(
        "study",
        help="reproduce Hu et al.'s pose-only SLAM study (worlds x noise x runs x methods), or "
        "calibrate the verdict on healthy and broken runs",
    )
    s.add_argument("study", choices=STUDIES, metavar="STUDY", help=", ".join(STUDIES))
    s.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write")
    s.add_argument(
        "--runs",
        type=opt.positive_int,
        default=10,
        help="Monte Carlo runs (default: %(default)s)",
    )
    s.add_argument(
        "--worlds",
        type=_names(PAPER_WORLDS + WORLDS, "worlds"),
        default=list(PAPER_WORLDS),
        metavar="LIST",
        help="comma-separated worlds (default: the paper's four)",
    )
    s.add_argument(
        "--noise",
        type=_names(NOISE_NAMES, "noise types"),
        default=list(NOISE_NAMES),
        metavar="LIST",
        help="comma-separated noise types of Hu et al. (Table I; see slamrel simulate "
        "--help) (default: a,b,c)",
    )
    s.add_argument(
        "--methods",
        type=_names(POSE_ONLY_METHODS, "methods"),
        default=list(POSE_ONLY_METHODS),
        metavar="LIST",
        help="comma-separated methods: "
        + ", ".join(POSE_ONLY_METHODS)
        + " (default: "
        + ",".join(POSE_ONLY_METHODS)
        + ")",
    )
    s.add_argument(
        "--pair-start",
        choices=("truth", "odometry", "align"),
        default="truth",
        help="start of the pose-only pair least squares (truth: as the paper) (default: "
        "%(default)s)",
    )
    s.add_argument(
        "--broken-runs",
        type=opt.positive_int,
        default=None,
        metavar="N",
        help="verdict-calibration: seeds of the broken runs (default: --runs)",
    )
    s.add_argument(
        "--min-common",
        type=opt.int_range(2, 1000),
        default=5,
        metavar="K",
        help="method m2: pair every two poses that observe at least K common landmarks "
        "(default: %(default)s)",
    )
    s.add_argument(
        "--toro-iterations",
        type=opt.positive_int,
        default=100,
        metavar="N",
        help="method toro: iterations of the TORO solver (default: %(default)s)",
    )
    s.add_argument(
        "--toro-rules",
        choices=("toro", "papers"),
        default="toro",
        help="method toro: OpenSLAM toro's step as measured on it (toro), or the papers' "
        "update (papers) (default: %(default)s)",
    )
    s.add_argument(
        "--workers",
        type=opt.positive_int,
        default=1,
        help="worker processes (default: %(default)s)",
    )
    s.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on Dask: a scheduler address, or 'local' for a LocalCluster of --workers "
        "(needs dask[distributed])",
    )
    s.add_argument("--timing", action="store_true", help="add a time column to the tables")
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    s.set_defaults(func=run_study)


def run_study(args: argparse.Namespace) -> int:
    if args.study == "verdict-calibration":
        return _run_calibration(args)

    from slamrel.outputs import resumable_directory
    from slamrel.studies.pose_only import (
        study_tasks,
        summary_rows,
        write_figures,
        write_findings,
        write_tables,
    )
    from slamrel.studies.sweep import load_results, run_sweep

    # the folder keeps finished cases (resume): reused when it is a study folder slamrel wrote
    out = resumable_directory(args.output, kind="pose-only-study")
    tasks = study_tasks(
        args.worlds,
        args.noise,
        args.runs,
        args.methods,
        pair_start=args.pair_start,
        min_common=args.min_common,
        toro_iterations=args.toro_iterations,
        toro_rules=args.toro_rules,
    )

    def progress(line: str) -> None:
        if not args.quiet:
            print(f"study: {line}", file=sys.stderr, flush=True)

    report = run_sweep(
        tasks, out / "cases", workers=args.workers, scheduler=args.scheduler, progress=progress
    )
    results = load_results(out / "cases", tasks)
    rows = summary_rows(results)
    paths = write_tables(out, rows, timing=args.timing)
    paths += write_figures(out, results)
    paths.append(write_findings(out, rows))
    if not args.quiet:
        print(
            f"study pose-only: {len(tasks)} cases ({report.ran} run now, {report.skipped} "
            f"already done, {len(report.failed)} failed) -> " + ", ".join(str(p) for p in paths)
        )
        for key in report.failed:
            print(f"failed: {out / 'cases' / (key + '.error.json')}")
        for path in report.damaged:
            print(f"recomputed (the stored result was damaged): {path}")
    return 0 if not report.failed else 3


def _run_calibration(args: argparse.Namespace) -> int:
    from slamrel.outputs import resumable_directory
    from slamrel.studies.calibration import (
        calibration_summary,
        calibration_tasks,
        write_calibration,
    )
    from slamrel.studies.sweep import load_results, run_sweep

    if args.worlds == list(PAPER_WORLDS):
        args.worlds = list(WORLDS)  # the default of pose-only is the paper's worlds
    other = [w for w in args.worlds if w not in WORLDS]
    if other:  # an option mistake: exit 2 like argparse
        print(
            f"slamrel study: error: --worlds: {', '.join(other)}: the verdict calibration runs "
            f"on the built-in worlds ({', '.join(WORLDS)})",
            file=sys.stderr,
        )
        return 2
    worlds = args.worlds
    out = resumable_directory(args.output, kind="verdict-calibration")
    broken = args.runs if args.broken_runs is None else args.broken_runs
    tasks = calibration_tasks(
        worlds, args.noise, list(range(args.runs)), broken_seeds=list(range(broken))
    )

    def progress(line: str) -> None:
        if not args.quiet:
            print(f"study: {line}", file=sys.stderr, flush=True)

    report = run_sweep(
        tasks, out / "cases", workers=args.workers, scheduler=args.scheduler, progress=progress
    )
    summary = calibration_summary(load_results(out / "cases", tasks))
    paths = write_calibration(out, summary)
    if not args.quiet:
        print("\n".join(summary.lines()))
        print(
            f"study verdict-calibration: {len(tasks)} cases ({report.ran} run now, "
            f"{report.skipped} already done, {len(report.failed)} failed) -> "
            + ", ".join(str(p) for p in paths)
        )
        for key in report.failed:
            print(f"failed: {out / 'cases' / (key + '.error.json')}")
        for path in report.damaged:
            print(f"recomputed (the stored result was damaged): {path}")
    return 0 if not report.failed else 3
