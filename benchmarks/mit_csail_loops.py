"""``relations align``'s own pairs on ``mit-csail.clf``, with and without the overlap test.

    PYTHONPATH=. python benchmarks/mit_csail_loops.py [DATA] [--min-overlap F ...]

Runs ``slamrel relations align mit-csail.clf --loops --loop-min-overlap F`` (the log's
odometry as guesses, every other option at its default) for F = 0 (every loop candidate)
and each F given (default: the command's default, 0.3), and reports from the quality
report: relations reported (written and failed), the flagged share, the failed ones, and
the same for the loop relations (a row is a consecutive pair when its two times are two
consecutive keyframes of :func:`slamrel.scans.proposals.consecutive_pairs` on the log's
poses, which is how the command proposes them; the others are loop pairs), with the
unflagged loop relations (what a reviewer would accept) and the command's CPU time
(``RUSAGE_CHILDREN``). ``DATA`` defaults to ``$SLAMREL_DATA`` or ``../shared/data``.
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from slamrel.commands.relations import LOOP_MIN_OVERLAP
from slamrel.formats.laser import read_laser_scans
from slamrel.scans.proposals import consecutive_pairs

ROOT = Path(__file__).resolve().parent.parent


def _run(log: Path, min_overlap: float, out: Path) -> tuple[list[dict[str, str]], str, float]:
    """The quality report's rows, the command's summary and its CPU time."""
    rep = out / f"r{min_overlap:g}.csv"
    argv = [sys.executable, "-m", "slamrel", "relations", "align", str(log), "--loops"]
    argv += ["--loop-min-overlap", str(min_overlap), "-o", str(out / "o.relations")]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(
        [*argv, "--report", str(rep)], check=True, capture_output=True, text=True, cwd=ROOT
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    with open(rep, newline="") as fh:
        return list(csv.DictReader(fh)), done.stdout.strip(), cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = os.environ.get("SLAMREL_DATA", str(ROOT.parent / "shared" / "data"))
    ap.add_argument("data", nargs="?", default=default)
    ap.add_argument("--min-overlap", type=float, nargs="+", default=[LOOP_MIN_OVERLAP])
    args = ap.parse_args()
    log = Path(args.data) / "freiburg" / "mit-csail.clf"
    scans = read_laser_scans(str(log))
    cons = consecutive_pairs(
        scans.laser_pose, scans.timestamps, distance=0.5, angle=0.3, spacing="travel"
    )
    consecutive = set(zip(np.round(cons.t1, 6).tolist(), np.round(cons.t2, 6).tolist()))
    with tempfile.TemporaryDirectory() as tmp:
        for f in (0.0, *args.min_overlap):
            rows, said, cpu = _run(log, f, Path(tmp))
            t = [(round(float(r["t1"]), 6), round(float(r["t2"]), 6)) for r in rows]
            loop = np.array([p not in consecutive for p in t], dtype=bool)
            flagged = np.array([r["flags"] != "" for r in rows], dtype=bool)
            failed = np.array(["failed" in r["flags"] for r in rows], dtype=bool)
            print(
                f"--loop-min-overlap {f:g}: {len(rows)} relations reported, {flagged.sum()} "
                f"flagged ({100 * flagged.mean():.1f} %), {failed.sum()} failed; loop "
                f"relations {loop.sum()}, {flagged[loop].sum()} flagged, "
                f"{(loop & ~flagged).sum()} unflagged; consecutive {(~loop).sum()}, "
                f"{flagged[~loop].sum()} flagged; {cpu:.0f} CPU-s"
            )
            print("  " + said.replace("\n", "\n  "))


if __name__ == "__main__":
    main()
