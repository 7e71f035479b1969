"""``slamrel batch``: evaluate many runs (a manifest or a folder of runs) in one resumable job.

Each run is scored as ``slamrel evaluate REFERENCE ESTIMATE`` with the options given here
(:mod:`slamrel.studies.batch`), through the resumable sweep (:mod:`slamrel.studies.sweep`:
worker processes, or Dask with ``--scheduler``). Writes into ``-o DIR`` (reused when run
again: finished runs are skipped): ``cases/`` (one JSON result per run), ``per_relation/``
(each run's per-relation CSV, for ``slamrel compare``), ``table.csv`` and ``table.md`` (a row
per run, then per dataset and algorithm the mean, std, min and max over its runs).
"""

from __future__ import annotations

import argparse
import sys

from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_strategy_arguments,
    add_sync_arguments,
    add_time_window_arguments,
    add_tolerance_argument,
    check_time_window,
)

HELP = "evaluate many runs (a manifest or a folder of runs) into one table, resumably"

DESCRIPTION = (
    "SOURCE is a manifest (CSV: name,reference,estimate[,dataset,algorithm]; paths relative "
    "to the manifest) or a folder with one sub-folder per run holding estimate.* and "
    "reference.* (or groundtruth.csv: a bundle). Each run is scored as slamrel evaluate "
    "scores it, as one task of a resumable sweep: a killed batch, run again with the same "
    "-o, skips the finished runs and writes the same table byte for byte."
)


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("batch", help=HELP, description=DESCRIPTION)
    p.add_argument("source", metavar="SOURCE", help="manifest file or folder of run folders")
    p.add_argument(
        "-o", "--output", required=True, metavar="DIR", help="batch folder (reused to resume)"
    )
    p.add_argument(
        "--workers",
        type=opt.nonnegative_int,
        default=1,
        help="worker processes, or Dask workers with --scheduler local (0: in this process; "
        "default: %(default)s)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on Dask: a scheduler address, or 'local' for a LocalCluster of --workers "
        "workers (default: processes)",
    )
    p.add_argument(
        "--ate",
        action="store_true",
        help="also the ATE translation RMSE without alignment and after SE/Sim alignment",
    )
    p.add_argument(
        "--kitti-drift",
        action="store_true",
        help="also the KITTI drift (translational %%, rotational deg/m; see slamrel evaluate "
        "--help) of each run",
    )
    add_tolerance_argument(p)
    add_sync_arguments(p)
    add_time_window_arguments(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    add_strategy_arguments(p, default="consecutive")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """``slamrel batch``: the runs read, the sweep run, the table written."""
    from pathlib import Path

    from slamrel.evaluation_options import SCORING_OPTIONS, EvaluateOptions
    from slamrel.formats.manifest import read_manifest
    from slamrel.outputs import resumable_directory, write_text_atomic
    from slamrel.studies.batch import (
        batch_table,
        batch_tasks,
        publish_per_relation,
        runs_in_folder,
    )
    from slamrel.studies.sweep import run_sweep, stored_results

    check_time_window(args)
    source = Path(args.source)
    runs = runs_in_folder(source) if source.is_dir() else read_manifest(source)
    options = {n: getattr(args, n) for n in SCORING_OPTIONS if hasattr(args, n)}
    EvaluateOptions(**options)  # the values checked once, before any work
    out = resumable_directory(args.output, kind="evaluate-batch", inputs=[args.source])
    per_relation = out / "per_relation"
    per_relation.mkdir(exist_ok=True)
    # each run's per-relation CSV is stored keyed by its options (cases/NAME-<hash>.csv) and
    # published as per_relation/NAME.csv after the sweep: a rerun with other options or a
    # deleted file never leaves another run's relations there
    tasks = batch_tasks(
        runs,
        options,
        str(per_relation),
        ate=args.ate,
        drift=args.kitti_drift,
        store_dir=str(out / "cases"),
    )

    def progress(line: str) -> None:
        if not args.quiet:
            print(f"batch: {line}", file=sys.stderr, flush=True)

    report = run_sweep(
        tasks, out / "cases", workers=args.workers, scheduler=args.scheduler, progress=progress
    )
    results = stored_results(out / "cases", tasks)
    stale = publish_per_relation(runs, tasks, results, per_relation)
    if stale and not args.quiet:
        print(f"batch: removed {stale} per-relation file(s) of runs without a result now")
    table = batch_table(runs, results, ate=args.ate, drift=args.kitti_drift)
    write_text_atomic(out / "table.csv", table.csv())
    write_text_atomic(out / "table.md", table.markdown())
    if not args.quiet:
        print(
            f"batch: {len(tasks)} runs ({report.ran} run now, {report.skipped} already done, "
            f"{len(report.failed)} failed) -> {out / 'table.csv'}, {out / 'table.md'}, "
            f"{per_relation}"
        )
        for key in report.failed:
            print(f"failed: {out / 'cases' / (key + '.error.json')}")
    return 0 if not report.failed else 3
