"""The run manifest of ``slamrel batch``: one evaluation a line, as CSV.

::

    name,reference,estimate,dataset,algorithm
    run-000,gt/seq00.tum,orb/seq00.tum,seq00,orb
    run-001,bundles/run1,recovered/run1.tum,sim,recovery

``name``, ``reference`` and ``estimate`` are required; ``dataset`` and ``algorithm`` are
optional columns (defaults ``all`` and ``-``) that group the runs in the
batch table and name them for ``slamrel compare``. ``reference`` is a reference trajectory,
a ``.relations`` file or a SLAM result bundle directory; relative paths are relative to the
manifest's folder (made absolute: they are part of each run's key). Names are unique and
file-name safe (letters, digits, ``-_.``); a blank line or a ``#`` line is skipped. Every
mistake is an :class:`InputError` naming the line.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from relation_metric.arrays import PathLike
from relation_metric.errors import InputError
from slamrel.formats.text import read_source

__all__ = ["BatchRun", "read_manifest", "MANIFEST_COLUMNS", "NAME_PATTERN"]

#: Required columns, then the optional ones.
MANIFEST_COLUMNS = ("name", "reference", "estimate", "dataset", "algorithm")
#: A run's name (it names its per-relation file).
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*\Z")


@dataclass(frozen=True)
class BatchRun:
    """One evaluation of a batch: ``slamrel evaluate REFERENCE ESTIMATE`` named ``name``."""

    name: str
    reference: str
    estimate: str
    dataset: str = "all"
    algorithm: str = "-"


def read_manifest(path: PathLike) -> list[BatchRun]:
    """The runs of a manifest file, in file order (see the module docstring)."""
    src = read_source(path)
    base = Path(src.path).parent
    runs: list[BatchRun] = []
    header: list[str] | None = None
    seen: dict[str, int] = {}
    for number, line in enumerate(src.lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        cells = [c.strip() for c in text.split(",")]
        if header is None:
            header = cells
            missing = [c for c in MANIFEST_COLUMNS[:3] if c not in header]
            unknown = [c for c in header if c not in MANIFEST_COLUMNS]
            if missing or unknown or len(set(header)) != len(header):
                raise InputError(
                    f"expected a header of the columns {', '.join(MANIFEST_COLUMNS[:3])} "
                    f"(and optionally dataset, algorithm), got {text!r}",
                    path=src.path,
                    line=number,
                )
            continue
        if len(cells) != len(header):
            raise InputError(
                f"expected {len(header)} comma-separated fields ({', '.join(header)}), got "
                f"{len(cells)}",
                path=src.path,
                line=number,
            )
        row = dict(zip(header, cells, strict=True))
        name = row["name"]
        if not NAME_PATTERN.match(name):
            raise InputError(
                f"run name {name!r}: expected letters, digits, '-', '_' or '.', starting with "
                "a letter or digit",
                path=src.path,
                line=number,
            )
        if name in seen:
            raise InputError(
                f"run name {name!r} repeats line {seen[name]}; expected unique names",
                path=src.path,
                line=number,
            )
        seen[name] = number
        for col in ("reference", "estimate", "dataset", "algorithm"):
            if col in row and not row[col]:
                raise InputError(f"empty {col}", path=src.path, line=number)
        runs.append(
            BatchRun(
                name=name,
                reference=os.path.abspath(base / row["reference"]),
                estimate=os.path.abspath(base / row["estimate"]),
                dataset=row.get("dataset", "all"),
                algorithm=row.get("algorithm", "-"),
            )
        )
    if not runs:
        raise InputError(
            "no run in the manifest; expected a header line and one run a line", path=src.path
        )
    return runs
