"""Batch evaluation of many runs: ``slamrel evaluate`` per run through the resumable sweep.

A batch is a list of :class:`~slamrel.formats.manifest.BatchRun` (a manifest file, or a folder
of run folders: :func:`runs_in_folder`). Each run is one :class:`~slamrel.studies.sweep.Task`
(:func:`evaluate_run`, keyed by its options and the SHA-256 of its input files, so an
edited file is scored again), run in processes or on Dask and stored atomically: a killed
batch resumes where it stopped. Each task also writes the run's per-relation CSV, keyed
like its result (``cases/NAME-<hash>.csv``), before its result is stored;
:func:`publish_per_relation` copies it to ``per_relation/NAME.csv`` (the input of
``slamrel compare``).
:func:`batch_table` makes one table over runs: a row per run and, per (dataset, algorithm),
the mean, the sample standard deviation (n − 1), the minimum and maximum over its runs of
each column. The table depends only on the stored results, so an interrupted and resumed
batch writes it byte for byte as an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from relation_metric.errors import InputError
from slamrel.formats.manifest import BatchRun
from slamrel.studies.sweep import Task

__all__ = [
    "BatchRow",
    "BatchTable",
    "runs_in_folder",
    "batch_tasks",
    "publish_per_relation",
    "evaluate_run",
    "batch_table",
    "COLUMNS",
]

#: The numeric columns of the table: relations scored and left unassociated, the warnings the
#: run's evaluation gave (their text is in its result file), the relation errors (abs).
COLUMNS = (
    "relations",
    "unassociated",
    "warnings",
    "trans_mean",
    "trans_rmse",
    "rot_mean",
    "rot_rmse",
)
#: With ``ate``: the translation RMSE of the ATE without alignment and after SE/Sim.
ATE_COLUMNS = ("ate_none_rmse", "ate_rigid_rmse", "ate_sim_rmse")
#: With ``drift``: the KITTI devkit's sequence errors (:mod:`relation_metric.drift`).
DRIFT_COLUMNS = ("drift_t_percent", "drift_r_deg_per_m")


def runs_in_folder(folder: str | Path) -> list[BatchRun]:
    """One run per sub-folder of ``folder`` (sorted by name).

    A run folder holds one ``estimate.*`` file and either one ``reference.*`` file
    (trajectory or ``.relations``) or a ``groundtruth.csv`` (the run folder is then a SLAM
    result bundle, its reference). A sub-folder that fits neither is an error naming it.
    """
    root = Path(folder).resolve()
    runs = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        est = sorted(d.glob("estimate.*"))
        ref = sorted(d.glob("reference.*"))
        if len(est) != 1 or len(ref) > 1 or (not ref and not (d / "groundtruth.csv").is_file()):
            raise InputError(
                f"expected one estimate.* file and one reference.* file (or a groundtruth.csv: "
                f"a bundle) in each run folder; found {len(est)} estimate and {len(ref)} "
                "reference file(s)",
                path=d,
            )
        runs.append(BatchRun(d.name, str(ref[0] if ref else d), str(est[0])))
    if not runs:
        raise InputError("no run folder inside; expected one sub-folder per run", path=root)
    return runs


def _digest(path: str) -> str:
    """SHA-256 of a file, or of a bundle's groundtruth.csv."""
    p = Path(path)
    if p.is_dir():
        p = p / "groundtruth.csv"
    try:
        return hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path=p) from None


def batch_tasks(
    runs: Sequence[BatchRun],
    options: dict[str, Any],
    per_relation_dir: str,
    *,
    ate: bool,
    drift: bool = False,
    store_dir: str | None = None,
) -> list[Task]:
    """The sweep's tasks, in run order. ``options``: fields of ``EvaluateOptions``.

    Each task writes its per-relation CSV under a name keyed by everything that changes it
    (``NAME-<hash of inputs, digests and options>.csv`` in ``store_dir``, default
    ``per_relation_dir``); :func:`publish_per_relation` then gives it the run's name.
    """
    tasks = []
    for run in runs:
        kwargs: dict[str, Any] = {
            "reference": run.reference,
            "estimate": run.estimate,
            "options": options,
            "ate": ate,
            "drift": drift,
            "digest": [_digest(run.reference), _digest(run.estimate)],
        }
        blob = json.dumps(kwargs, sort_keys=True, separators=(",", ":"))
        keyed = f"{run.name}-{hashlib.sha256(blob.encode()).hexdigest()[:12]}.csv"
        kwargs["per_relation"] = str(Path(store_dir or per_relation_dir) / keyed)
        function = "slamrel.studies.batch:evaluate_run"
        tasks.append(Task(run.name, function, kwargs, outputs=(kwargs["per_relation"],)))
    return tasks


def publish_per_relation(
    runs: Sequence[BatchRun],
    tasks: Sequence[Task],
    results: Sequence[dict[str, Any] | None],
    per_relation_dir: str | Path,
) -> int:
    """``per_relation_dir/NAME.csv``: each run's per-relation CSV of this batch's options
    (copied from its task's keyed file; rewritten when it differs or was deleted). A run
    without a result has none: a file left from other options is removed. Returns how many
    such stale files were removed."""
    from slamrel.outputs import write_text_atomic

    removed = 0
    for run, task, res in zip(runs, tasks, results, strict=True):
        target = Path(per_relation_dir) / f"{run.name}.csv"
        if res is None:
            if target.is_file():
                target.unlink()
                removed += 1
            continue
        text = Path(task.kwargs["per_relation"]).read_text(encoding="utf-8")
        if not target.is_file() or target.read_text(encoding="utf-8") != text:
            write_text_atomic(target, text)
    return removed


def evaluate_run(
    reference: str,
    estimate: str,
    options: dict[str, Any],
    ate: bool,
    per_relation: str,
    digest: Sequence[str],
    drift: bool = False,
) -> dict[str, Any]:
    """One run: scored as ``slamrel evaluate`` scores it; its per-relation CSV written.

    Returns the JSON-ready numbers of :data:`COLUMNS` (and :data:`ATE_COLUMNS`,
    :data:`DRIFT_COLUMNS`), the warnings
    the evaluation gave (text, in order: nothing is dropped silently) and ``digest`` (the
    inputs' hashes, part of the task's key).
    """
    from slamrel.evaluation import score_files
    from slamrel.evaluation_options import EvaluateOptions
    from slamrel.formats.results import write_per_relation_csv

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scored = score_files(reference, estimate, EvaluateOptions(**options), ate=ate, drift=drift)
    ev = scored.evaluation
    sets = None if scored.relation_set is None else [scored.relation_set] * len(ev.relations)
    write_per_relation_csv(per_relation, ev, relation_sets=sets)
    res = scored.result
    out: dict[str, Any] = {
        "relations": res["relations"],
        "unassociated": res["unassociated"],
        "trans_mean": ev.translation.abs.mean,
        "trans_rmse": ev.translation.abs.rmse,
        "rot_mean": res["rotation"]["abs"]["mean"],
        "rot_rmse": res["rotation"]["abs"]["rmse"],
        "warnings": [str(w.message) for w in caught],
        "digest": list(digest),
    }
    if ate:
        a = res["ate"]
        rigid, sim = ("se3", "sim3") if "se3" in a else ("se2", "sim2")
        out["ate_none_rmse"] = a["none"]["translation"]["rmse"]
        out["ate_rigid_rmse"] = a[rigid]["translation"]["rmse"]
        out["ate_sim_rmse"] = a[sim]["translation"]["rmse"]
    if drift:
        out["drift_t_percent"] = res["kitti_drift"]["translation_percent"]
        out["drift_r_deg_per_m"] = res["kitti_drift"]["rotation_deg_per_m"]
    return out


def _number(result: dict[str, Any], column: str) -> float:
    """A table cell from a stored result: NaN for None (no value), a count for a list."""
    value = result[column]
    if isinstance(value, list):
        return float(len(value))
    return float("nan") if value is None else float(value)


@dataclass(frozen=True)
class BatchRow:
    """One row of the batch table: a run (``kind="run"``) or a statistic over a group's
    runs (``kind`` = ``mean``, ``std``, ``min``, ``max``; ``name`` = the run count)."""

    kind: str
    name: str
    dataset: str
    algorithm: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class BatchTable:
    """The batch table: ``columns`` and the rows, runs first (in run order), then per
    (dataset, algorithm) group in first-appearance order its statistics."""

    columns: tuple[str, ...]
    rows: tuple[BatchRow, ...]
    failed: tuple[str, ...]

    def csv(self) -> str:
        """As CSV: ``kind,name,dataset,algorithm,<columns>``; numbers ``%.17g``; names
        quoted as RFC 4180 says (a name with ``,`` shifts no column)."""
        from slamrel.formats.text import NUMBER_FORMAT
        from slamrel.report.tables import csv_field

        lines = [",".join(("kind", "name", "dataset", "algorithm", *self.columns))]
        for r in self.rows:
            nums = ["" if math.isnan(v) else NUMBER_FORMAT % v for v in r.values]
            words = (csv_field(w) for w in (r.kind, r.name, r.dataset, r.algorithm))
            lines.append(",".join((*words, *nums)))
        return "\n".join(lines) + "\n"

    def markdown(self) -> str:
        """As a Markdown table (6 significant digits), the failed runs listed below it;
        names escaped (a ``|`` ends no cell)."""
        from slamrel.report.tables import markdown_cell

        head = ("kind", "name", "dataset", "algorithm", *self.columns)
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in self.rows:
            nums = ["" if math.isnan(v) else f"{v:.6g}" for v in r.values]
            words = (markdown_cell(w) for w in (r.kind, r.name, r.dataset, r.algorithm))
            lines.append("| " + " | ".join((*words, *nums)) + " |")
        if self.failed:
            lines += ["", "Failed runs (no row): " + ", ".join(map(markdown_cell, self.failed))]
        return "\n".join(lines) + "\n"


def batch_table(
    runs: Sequence[BatchRun],
    results: Sequence[dict[str, Any] | None],
    *,
    ate: bool,
    drift: bool = False,
) -> BatchTable:
    """The table over runs from their stored results (``None``: the run failed)."""
    import numpy as np

    columns = COLUMNS + (ATE_COLUMNS if ate else ()) + (DRIFT_COLUMNS if drift else ())
    rows: list[BatchRow] = []
    groups: dict[tuple[str, str], list[tuple[float, ...]]] = {}
    failed = []
    for run, res in zip(runs, results, strict=True):
        if res is None:
            failed.append(run.name)
            continue
        vals = tuple(_number(res, c) for c in columns)
        rows.append(BatchRow("run", run.name, run.dataset, run.algorithm, vals))
        groups.setdefault((run.dataset, run.algorithm), []).append(vals)
    for (dataset, algorithm), group in groups.items():
        a = np.asarray(group, dtype=np.float64)
        n = a.shape[0]
        std = a.std(axis=0, ddof=1) if n > 1 else np.full(a.shape[1], np.nan)
        for kind, v in (
            ("mean", a.mean(axis=0)),
            ("std", std),
            ("min", a.min(axis=0)),
            ("max", a.max(axis=0)),
        ):
            rows.append(BatchRow(kind, str(n), dataset, algorithm, tuple(map(float, v))))
    return BatchTable(columns, tuple(rows), tuple(failed))
