"""Before/after check: run the front door with fixed seeds and hash what it writes.

Runs, in a temporary folder (or ``--outputs DIR``), with fixed seeds:

- ``slamrel run`` (default world ``simple1``, seed 1);
- ``slamrel simulate simple1`` + ``slamrel slam`` (a simulated SLAM bundle), then
  ``slamrel recover`` on it with ``--method filter``, ``smoother`` and ``batch``;
- ``slamrel import isam`` on Victoria Park, then ``slamrel solve`` on the graph;
- ``slamrel map-compare`` of the simulated EKF-SLAM map against its true map;
- ``slamrel evaluate`` of Freiburg run 08 (metricEvaluator mode, weights 1,1,0,0,0,0).

and prints one SHA-256 per output file. Files that embed times or versions
(``report.html``, ``slamrel-output.json``) are skipped; JSON files are hashed after
dropping wall-clock/version keys (none are written today) and re-serialising with sorted keys.

Usage::

    python benchmarks/output_hashes.py                      # print the hashes
    python benchmarks/output_hashes.py --write benchmarks/output_hashes.json
    python benchmarks/output_hashes.py --check benchmarks/output_hashes.json
    python benchmarks/output_hashes.py --outputs /tmp/after --tolerance 1e-9 --against /tmp/before

``--against DIR`` (a folder written earlier with ``--outputs``) compares the outputs number by
number and prints the largest absolute difference per file; ``--tolerance`` is the largest
difference still called rounding. Real data is found through ``$SLAMREL_DATA`` (default
``../shared/data`` beside the project root, as in tests/conftest.py). Runtime ~15 s.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SKIPPED = {"report.html", "slamrel-output.json"}
# Keys holding wall-clock times or versions, dropped from JSON before hashing.
VOLATILE_KEYS = {"version", "created", "elapsed", "elapsed_seconds", "wall_time", "runtime"}
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)", re.I)


def data_root() -> Path:
    """``$SLAMREL_DATA``, or ``../shared/data`` beside the project root."""
    return Path(os.environ.get("SLAMREL_DATA", ROOT.parent / "shared" / "data"))


def commands(data: Path) -> list[list[str]]:
    """The slamrel command lines, in order, relative to the output folder."""
    fr = data / "freiburg"
    return [
        ["run", "-o", "run", "--seed", "1", "-q"],
        ["simulate", "simple1", "--seed", "2", "-o", "sim", "-q"],
        ["slam", "sim", "-o", "slam", "--seed", "3", "-q"],
        *(
            ["recover", "slam", "--method", m, "-o", f"recover_{m}.txt"]
            + ["--covariances", f"recover_{m}.npy", "--report", f"recover_{m}.json", "-q"]
            for m in ("filter", "smoother", "batch")
        ),
        ["import", "isam", str(data / "victoria_park" / "victoria_park.txt"), "-o", "vp.g2o"]
        + ["--noise", "covariance"]  # GTSAM's copy stores covariances
        + ["-q"],
        ["solve", "vp.g2o", "-o", "vp_solve", "-q"],
        ["map-compare", "slam/map.csv", "slam/landmarks_groundtruth.csv", "--seed", "1"]
        + ["--json", "map_compare.json", "--per-edge", "map_compare.csv", "-q"],
        ["evaluate", str(fr / "mit-csail.relations"), str(fr / "benchmarks" / "08" / "test.log")]
        + ["--odometry", str(fr / "mit-csail.clf"), "--mode", "metricevaluator"]
        + ["--weights", "1,1,0,0,0,0", "--json", "evaluate.json"]
        + ["--per-relation", "evaluate.csv", "-q"],
    ]


def run_all(out: Path, data: Path) -> None:
    """Run every command in ``out`` with this checkout's code first on the path."""
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    env["MPLBACKEND"] = "Agg"
    for argv in commands(data):
        proc = subprocess.run(
            [sys.executable, "-m", "slamrel.cli", *argv],
            cwd=out,
            env=env,
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0:
            raise SystemExit(f"slamrel {' '.join(argv)} exited {proc.returncode}:\n{proc.stderr}")


def _clean(obj):
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items() if k not in VOLATILE_KEYS}
    if isinstance(obj, list):
        return [_clean(v) for v in obj]
    return obj


def content(path: Path) -> bytes:
    """The bytes hashed for ``path`` (JSON cleaned and canonicalised)."""
    if path.suffix == ".json":
        obj = _clean(json.loads(path.read_text()))
        return json.dumps(obj, sort_keys=True, indent=1).encode()
    return path.read_bytes()


def outputs(out: Path) -> list[Path]:
    """Output files, sorted, skipping inputs-by-copy and volatile files."""
    return sorted(p for p in out.rglob("*") if p.is_file() and p.name not in SKIPPED)


def hashes(out: Path) -> dict[str, str]:
    """SHA-256 of every output file, keyed by its path relative to ``out``."""
    return {
        p.relative_to(out).as_posix(): hashlib.sha256(content(p)).hexdigest() for p in outputs(out)
    }


def numbers(path: Path) -> tuple[np.ndarray, list[str]]:
    """The numbers of a file (flattened) and its non-numeric skeleton."""
    if path.suffix == ".npy":
        return np.load(path).ravel().astype(float), []
    text = content(path).decode(errors="replace")
    values = [float(m) for m in NUMBER.findall(text)]
    return np.array(values, dtype=float), NUMBER.split(text)


def largest_difference(before: Path, after: Path) -> str:
    """Largest absolute numeric difference between two versions of a file, as text."""
    if before.suffix in {".png", ".svg", ".pdf"}:
        return "image differs (not compared numerically)"
    a, sa = numbers(before)
    b, sb = numbers(after)
    if a.shape != b.shape or sa != sb:
        return f"structure differs ({a.size} vs {b.size} numbers)"
    both_nan = np.isnan(a) & np.isnan(b)
    with np.errstate(invalid="ignore"):
        diff = np.where(both_nan | (a == b), 0.0, np.abs(a - b))
    if not diff.size or not np.any(diff):
        return "numbers equal (formatting differs)"
    k = int(np.nanargmax(diff))
    return (
        f"max |diff| {float(diff[k]):.3g} at number {k} ({float(a[k]):.17g} -> {float(b[k]):.17g})"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", metavar="FILE", help="store the hashes as JSON")
    parser.add_argument("--check", metavar="FILE", help="compare with stored hashes")
    parser.add_argument("--outputs", metavar="DIR", help="keep the outputs in DIR")
    parser.add_argument("--against", metavar="DIR", help="outputs kept earlier: compare numbers")
    parser.add_argument("--tolerance", type=float, default=0.0, help="rounding bound (--against)")
    args = parser.parse_args(argv)

    data = data_root()
    if not data.exists():
        parser.error(f"real data not found at {data}: set SLAMREL_DATA")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.outputs) if args.outputs else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        if any(out.iterdir()):
            parser.error(f"{out}: the output folder must be empty")
        run_all(out, data)
        got = hashes(out)
        status = 0
        if args.write:
            Path(args.write).write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
        if args.check:
            want = json.loads(Path(args.check).read_text())
            differ = sorted(k for k in want.keys() & got.keys() if want[k] != got[k])
            for k in sorted(want.keys() - got.keys()):
                print(f"missing: {k}")
            for k in sorted(got.keys() - want.keys()):
                print(f"new: {k}")
            for k in differ:
                print(f"differs: {k}")
            status = int(bool(differ or want.keys() ^ got.keys()))
            print("identical" if not status else f"{len(differ)} file(s) differ")
        if args.against:
            base = Path(args.against)
            for k in sorted(got):
                if not (base / k).exists():
                    print(f"{k}: not in {base}")
                elif content(base / k) != content(out / k):
                    verdict = largest_difference(base / k, out / k)
                    print(f"{k}: {verdict}")
                    m = re.match(r"max \|diff\| (\S+)", verdict)
                    if not m or float(m.group(1)) > args.tolerance:
                        status = 1
            print("within tolerance" if not status else "beyond tolerance")
        if not (args.write or args.check or args.against):
            for k, v in got.items():
                print(f"{v}  {k}")
    return status


if __name__ == "__main__":
    sys.exit(main())
