"""``slamrel ape``/``rpe`` against ``evo_ape``/``evo_rpe``, and ``evaluate`` on 10^5 poses.

1. Whole processes on small real files (the TUM RGB-D sequences and the ROS 1 bag of
   ``../shared/data``): each command line run by slamrel (``python -m slamrel ape|rpe ...``)
   and by evo (``evo_ape|evo_rpe ...`` of ``benchmarks/.venv-evo``, created on first use),
   best of ``--repeat`` runs each, in wall time and in CPU time (user + system of the
   process, from ``getrusage``: on a shared, loaded machine the wall time also counts the
   waiting); the ratio evo / slamrel per case and its median over the cases. Target: median
   ≥ 2×. The printed rmse of both is checked to agree to 6 digits.
2. ``slamrel evaluate`` on 10^5 poses (TUM, consecutive relations) as a whole process vs
   ``evo_rpe`` run twice (translation part and rotation angle), the files of
   :func:`bench_startup.bench_evaluate`, wall and CPU time as above. Target: ≥ 50×.

Run: ``python benchmarks/bench_evo.py [--repeat 3] [--poses 100000]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import numpy as np  # noqa: E402
from bench_relation_metric import ensure_evo, random_trajectory  # noqa: E402
from bench_startup import env, evo_rmse  # noqa: E402

sys.path.insert(0, str(HERE.parent))
from relation_metric.trajectory import Trajectory  # noqa: E402
from slamrel.formats.trajectories import write_trajectory  # noqa: E402

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


def _children_cpu() -> float:
    u = resource.getrusage(resource.RUSAGE_CHILDREN)
    return u.ru_utime + u.ru_stime


def timed(argv: list[str], repeat: int) -> tuple[float, float, str]:
    """Best wall and best CPU time of ``repeat`` whole-process runs [s], the last stdout."""
    best, best_cpu, out = float("inf"), float("inf"), ""
    for _ in range(repeat):
        cpu0, start = _children_cpu(), time.perf_counter()
        r = subprocess.run(argv, capture_output=True, text=True, env=env(), check=False)
        best = min(best, time.perf_counter() - start)
        best_cpu = min(best_cpu, _children_cpu() - cpu0)
        if r.returncode:
            raise RuntimeError(f"{' '.join(argv)} failed: {r.stderr.strip()[-500:]}")
        out = r.stdout
    return best, best_cpu, out


def bench_commands(evo_bin: Path, repeat: int) -> tuple[list[float], list[float]]:
    """Print one line per case; return the ratios evo / slamrel, wall and CPU."""
    print("wall and CPU [s], slamrel then evo; ratios evo / slamrel")
    ratios: tuple[list[float], list[float]] = ([], [])
    for metric, kind, args in CASES:
        ours, ours_cpu, text = timed([sys.executable, "-m", "slamrel", metric, kind, *args], repeat)
        evo_cmd = [str(evo_bin / f"evo_{metric}"), kind, *args, "--no_warnings"]
        theirs, theirs_cpu, evo_text = timed(evo_cmd, repeat)
        a, b = evo_rmse(text), evo_rmse(evo_text)
        same = "equal" if f"{a:.6f}" == f"{b:.6f}" else f"DIFFER {a:.6f} vs {b:.6f}"
        shown = " ".join(Path(x).name[:12] if "/" in x else x for x in args)
        ratios[0].append(theirs / ours)
        ratios[1].append(theirs_cpu / ours_cpu)
        print(
            f"{metric} {kind} {shown:44s} wall {ours:.3f} {theirs:.3f} ({theirs / ours:.2f}x)"
            f"  cpu {ours_cpu:.3f} {theirs_cpu:.3f} ({theirs_cpu / ours_cpu:.2f}x)  rmse {same}"
        )
    return ratios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--poses", type=int, default=100_000)
    args = parser.parse_args()
    python = ensure_evo()
    if python is None:
        sys.exit("evo is not available (benchmarks/.venv-evo could not be created)")
    for what, ratios in zip(("wall", "CPU"), bench_commands(python.parent, args.repeat)):
        med = statistics.median(ratios)
        print(
            f"median {what} ratio evo / slamrel over {len(ratios)} command lines: {med:.2f}x "
            f"(min {min(ratios):.2f}x); target >= 2x: {'met' if med >= 2 else 'MISSED'}"
        )
    bench_evaluate(python.parent, args.poses, args.repeat)


def bench_evaluate(evo_bin: Path, n: int, repeat: int) -> None:
    """``slamrel evaluate`` vs ``evo_rpe`` (trans_part + angle_rad) on ``n`` poses."""
    rng = np.random.default_rng(2)
    ref = random_trajectory(n, seed=3)
    est = Trajectory(ref.timestamps, ref.poses + rng.normal(0, [0.01, 0.01, 0.002], (n, 3)))
    with tempfile.TemporaryDirectory() as tmp:
        rp, ep = Path(tmp) / "ref.tum", Path(tmp) / "est.tum"
        write_trajectory(rp, ref, format="tum")
        write_trajectory(ep, est, format="tum")
        argv = [sys.executable, "-m", "slamrel", "evaluate", str(rp), str(ep)]
        wall, cpu, text = timed(argv, repeat)
        evo_wall = evo_cpu = 0.0
        rmse = []
        for part in ("trans_part", "angle_rad"):
            w, c, out = timed([str(evo_bin / "evo_rpe"), "tum", str(rp), str(ep), "-r", part], 1)
            evo_wall, evo_cpu = evo_wall + w, evo_cpu + c
            rmse.append(evo_rmse(out))
    row = next(x for x in text.splitlines() if x.startswith("translation abs"))
    print(
        f"\nslamrel evaluate, {n} poses: wall {wall:.3f} s, cpu {cpu:.3f} s (rmse "
        f"{float(row.split()[-2]):.6f} m); evo_rpe trans_part + angle_rad: wall {evo_wall:.2f} s, "
        f"cpu {evo_cpu:.2f} s (rmse {rmse[0]:.6f} m, {rmse[1]:.6f} rad)"
    )
    for what, r in (("wall", evo_wall / wall), ("CPU", evo_cpu / cpu)):
        print(f"{what} ratio {r:.1f}x; target >= 50x: {'met' if r >= 50 else 'MISSED'}")


if __name__ == "__main__":
    main()
