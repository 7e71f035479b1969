"""``slamrel ape``/``rpe`` against ``evo_ape``/``evo_rpe``, and ``evaluate`` on 10^5 poses.

1. Whole processes on small real files (the TUM RGB-D sequences and the ROS 1 bag of
   ``../shared/data``): each command line run by slamrel (``python -m slamrel ape|rpe ...``)
   and by evo (``evo_ape|evo_rpe ...`` of ``benchmarks/.venv-evo``, created on first use),
   best of ``--repeat`` runs each; the ratio evo / slamrel per case and its median over the
   cases. Target: median ≥ 2×. The printed rmse of both is checked to agree to 6 digits.
2. ``slamrel evaluate`` on 10^5 poses (TUM, consecutive relations) as a whole process vs
   ``evo_rpe`` run twice (translation part and rotation angle):
   :func:`bench_startup.bench_evaluate`. Target: ≥ 50×.

Run: ``python benchmarks/bench_evo.py [--repeat 3] [--poses 100000]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_relation_metric import ensure_evo  # noqa: E402
from bench_startup import bench_evaluate, env, evo_rmse  # noqa: E402

DATA = Path(os.environ.get("SLAMREL_DATA", HERE.parent.parent / "shared" / "data"))
TUM = DATA / "tum_rgbd"
FR1 = [str(TUM / "freiburg1_xyz-groundtruth.txt"), str(TUM / "freiburg1_xyz-rgbdslam.txt")]
FR2 = [str(TUM / "fr2_desk_groundtruth.txt"), str(TUM / "fr2_desk_ORB.txt")]
BAG = [str(DATA / "rosbag" / "ROS_example.bag"), "groundtruth", "ORB-SLAM"]

# (metric, kind, arguments)
CASES = [
    ("ape", "tum", [*FR1]),
    ("ape", "tum", [*FR1, "-a"]),
    ("ape", "tum", [*FR2, "-as"]),
    ("rpe", "tum", [*FR1]),
    ("rpe", "tum", [*FR2, "-d", "0.5", "-u", "m"]),
    ("rpe", "tum", [*FR2, "-d", "10", "--all_pairs", "-r", "angle_deg"]),
    ("ape", "bag", [*BAG, "-a"]),
    ("rpe", "bag", [*BAG, "-d", "1", "-u", "m"]),
]


def timed(argv: list[str], repeat: int) -> tuple[float, str]:
    """Best wall time of ``repeat`` whole-process runs [s] and the last run's stdout."""
    best, out = float("inf"), ""
    for _ in range(repeat):
        start = time.perf_counter()
        r = subprocess.run(argv, capture_output=True, text=True, env=env(), check=False)
        best = min(best, time.perf_counter() - start)
        if r.returncode:
            raise RuntimeError(f"{' '.join(argv)} failed: {r.stderr.strip()[-500:]}")
        out = r.stdout
    return best, out


def bench_commands(evo_bin: Path, repeat: int) -> list[float]:
    """Print one line per case; return the ratios evo / slamrel."""
    print(f"{'command line':58s}{'slamrel [s]':>12s}{'evo [s]':>9s}{'ratio':>7s}  rmse")
    ratios = []
    for metric, kind, args in CASES:
        ours, text = timed([sys.executable, "-m", "slamrel", metric, kind, *args], repeat)
        evo_cmd = [str(evo_bin / f"evo_{metric}"), kind, *args, "--no_warnings"]
        theirs, evo_text = timed(evo_cmd, repeat)
        a, b = evo_rmse(text), evo_rmse(evo_text)
        same = "equal" if f"{a:.6f}" == f"{b:.6f}" else f"DIFFER {a:.6f} vs {b:.6f}"
        shown = " ".join(Path(x).name if "/" in x else x for x in args)
        ratios.append(theirs / ours)
        print(f"{metric} {kind} {shown:50s}{ours:12.3f}{theirs:9.3f}{theirs / ours:7.2f}  {same}")
    return ratios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--poses", type=int, default=100_000)
    args = parser.parse_args()
    python = ensure_evo()
    if python is None:
        sys.exit("evo is not available (benchmarks/.venv-evo could not be created)")
    ratios = bench_commands(python.parent, args.repeat)
    med = statistics.median(ratios)
    print(
        f"\nmedian ratio evo / slamrel over {len(ratios)} command lines: {med:.2f}x "
        f"(min {min(ratios):.2f}x); target >= 2x: {'met' if med >= 2 else 'MISSED'}"
    )
    ev = bench_evaluate(args.poses, True)
    if "evo_s" not in ev:
        print("evo_rpe failed: the 10^5-pose ratio was not measured")
        return
    ratio = ev["evo_s"] / ev["slamrel_s"]
    print(
        f"\nslamrel evaluate, {args.poses} poses, whole process: {ev['slamrel_s']:.3f} s; "
        f"evo_rpe trans_part + angle_rad: {ev['evo_s']:.2f} s (rmse {ev['evo_rmse_trans']:.6f} "
        f"vs {ev['slamrel_rmse_trans']:.6f} m)\nratio {ratio:.1f}x; target >= 50x: "
        f"{'met' if ratio >= 50 else 'MISSED'}"
    )


if __name__ == "__main__":
    main()
