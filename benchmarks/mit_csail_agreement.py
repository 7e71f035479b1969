"""Reference relations on ``mit-csail.clf`` from the log's odometry and from run 08 (issue 37).

    PYTHONPATH=. python benchmarks/mit_csail_agreement.py [DATA]

Runs ``slamrel relations align mit-csail.clf --at mit-csail.relations`` (default aligner)
twice — guesses from the log's own odometry, and from the Freiburg run 08
(``--estimate benchmarks/08/test.log --skip-invalid-poses``) — and reports, from the two
quality reports:

- the flagged share of each (and how many failed: left out of the ``.relations`` file);
- on the pairs both leave unflagged, the disagreement ``‖t(δ_run08⁻¹ ∘ δ_odometry)‖``: its
  95th percentile (acceptance ≤ 1 cm), the count beyond 10 cm and the maximum;
- each set's unflagged relations against the authors' file (median, 95th percentile);
- short cycles (2–4 relations, :func:`slamrel.scans.cycles.find_cycles`) of each set's
  unflagged relations: the median translational closure ``‖t(C)‖`` (acceptance ≤ 1.5 cm),
  and the authors' relations composed along the very same cycles (same pairs, same cycles).

``DATA`` defaults to ``$SLAMREL_DATA`` or ``../shared/data``. No option: the figures of
``benchmarks/README.md`` and ``docs/laser-relations.md`` come from this run as is.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import between
from slamrel.formats.relations import read_relations
from slamrel.scans.cycles import compose_cycles, find_cycles

ROOT = Path(__file__).resolve().parent.parent


def align(log: Path, pairs: Path, out: Path, extra: list[str]) -> float:
    """Run ``relations align`` writing ``out`` (.relations) and ``out.csv``; wall seconds."""
    cmd = [sys.executable, "-m", "slamrel", "relations", "align", str(log), "--at", str(pairs)]
    cmd += ["-o", str(out), "--report", f"{out}.csv", *extra]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return time.perf_counter() - start


def read_report(path: Path) -> tuple[NDArray[np.float64], NDArray[np.float64], list[str]]:
    """Times ``(P, 2)``, relations ``(P, 3)`` and flags of a quality report."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    times = np.array([[float(r["t1"]), float(r["t2"])] for r in rows])
    delta = np.array([[float(r["x"]), float(r["y"]), float(r["theta"])] for r in rows])
    return times, delta, [r["flags"] for r in rows]


def cm(v: NDArray[np.float64], q: float) -> str:
    return f"{100 * float(np.percentile(v, q)):.2f}"


def cycle_closure(
    times: NDArray[np.float64], delta: NDArray[np.float64], authors: NDArray[np.float64]
) -> tuple[int, float, float]:
    """Short cycles of the relations ``delta`` at ``times``: their count and the median
    translational closure of ``delta`` and of ``authors`` along the same cycles [m]."""
    _, node = np.unique(times.ravel(), return_inverse=True)
    node = node.reshape(-1, 2)
    _, edges, signs = find_cycles(node[:, 0], node[:, 1], np.ones(len(node), bool))
    # one cycle is found once per member it is tested for: keep each edge set once
    key = np.sort(np.where(edges >= 0, edges, -1), axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    edges, signs = edges[first], signs[first]
    cov = np.broadcast_to(np.eye(3) * 1e-4, (len(node), 3, 3)).copy()
    ours = compose_cycles(delta, cov, edges, signs)[0]
    theirs = compose_cycles(authors, cov, edges, signs)[0]
    return (
        len(edges),
        float(np.median(np.hypot(ours[:, 0], ours[:, 1]))),
        float(np.median(np.hypot(theirs[:, 0], theirs[:, 1]))),
    )


def main() -> None:
    data = Path(
        sys.argv[1]
        if len(sys.argv) > 1
        else os.environ.get("SLAMREL_DATA", ROOT.parent / "shared" / "data")
    )
    fr = data / "freiburg"
    log, pairs = fr / "mit-csail.clf", fr / "mit-csail.relations"
    authors = read_relations(pairs)
    runs = {
        "odometry": [],
        "run 08": [
            "--estimate",
            str(fr / "benchmarks" / "08" / "test.log"),
            "--skip-invalid-poses",
        ],
    }
    got: dict[str, tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in runs.items():
            out = Path(tmp) / f"{name.replace(' ', '')}.relations"
            secs = align(log, pairs, out, ["-q", *extra])
            times, delta, flags = read_report(Path(f"{out}.csv"))
            flagged = np.array([f != "" for f in flags])
            failed = sum("failed" in f for f in flags)
            got[name] = (times, delta, ~flagged)
            print(
                f"{name}: {len(flags)} pairs, {flagged.sum()} flagged "
                f"({100 * flagged.mean():.1f} %; {failed} failed), {secs:.0f} s wall",
                flush=True,
            )
    # the two runs report the same pairs in the same order (the --at file's)
    (t_o, d_o, ok_o), (t_r, d_r, ok_r) = got["odometry"], got["run 08"]
    assert np.array_equal(t_o, t_r), "the two runs' pairs differ"
    both = ok_o & ok_r
    diff = between(d_r[both], d_o[both])
    dt = np.hypot(diff[:, 0], diff[:, 1])
    dr = np.degrees(np.abs(diff[:, 2]))
    print(
        f"both unflagged: {both.sum()} pairs; odometry vs run 08: median {cm(dt, 50)} cm, "
        f"p95 {cm(dt, 95)} cm / {np.percentile(dr, 95):.3f}°, {(dt > 0.10).sum()} > 10 cm, "
        f"max {100 * dt.max():.1f} cm ({100 * (dt <= 0.01).mean():.1f} % within 1 cm)"
    )
    for name, (times, delta, ok) in got.items():
        # the report keeps the --at file's pairs in its order, at the scans' own times
        off = np.abs(times - np.column_stack((authors.first, authors.second)))
        assert len(times) == len(authors) and off.max() < 0.05, "pairs not in file order"
        auth = authors.delta[:, :3]
        e = between(auth[ok], delta[ok])
        et = np.hypot(e[:, 0], e[:, 1])
        er = np.degrees(np.abs(e[:, 2]))
        n, ours, theirs = cycle_closure(times[ok], delta[ok], auth[ok])
        print(
            f"{name}: {ok.sum()} unflagged vs the authors' median {cm(et, 50)} cm / "
            f"{np.median(er):.3f}°, p95 {cm(et, 95)} cm / {np.percentile(er, 95):.3f}°; "
            f"{n} short cycles of them close to a median {100 * ours:.2f} cm "
            f"(the authors' along the same cycles {100 * theirs:.2f} cm)",
            flush=True,
        )


if __name__ == "__main__":
    main()
