"""Speed of the relation metric, against named baselines measured in the same run.

1. Metric throughput: 10^6 index relations through association, errors (translation and
   rotation) and all statistics (abs and sqr) — target < 0.5 s.
2. Consecutive-pair errors (RPE, delta = 1 frame) on 10^5 poses: slamrel vs. evo's
   ``RPE`` (translation part and rotation angle), evo run in its own virtual environment
   (``benchmarks/.venv-evo``, created on first use) — target ≥ 100× faster; the numbers are
   checked to agree.
3. Reading a 10^6-line ``.relations`` file with ``read_relations`` vs. ``np.loadtxt`` —
   target < 1 s.

Run: ``python benchmarks/bench_relation_metric.py`` (add ``--no-evo`` to skip the evo part).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from relation_metric import se2  # noqa: E402
from relation_metric.evaluate import evaluate  # noqa: E402
from relation_metric.relations import RelationSet, generate_relations, read_relations  # noqa: E402
from relation_metric.trajectory import Trajectory  # noqa: E402

EVO_VENV = HERE / ".venv-evo"


def best_of(fn, repeat: int = 3) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def random_trajectory(n: int, seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    steps = np.column_stack((rng.uniform(0.1, 0.5, n - 1), rng.normal(0, 0.02, n - 1), rng.normal(0, 0.1, n - 1)))
    return Trajectory.from_poses(se2.cumulative_compose(steps), dt=0.1)


def bench_throughput() -> dict[str, float]:
    rng = np.random.default_rng(1)
    n = 200_000
    ref = random_trajectory(n)
    est = Trajectory(ref.timestamps, ref.poses + rng.normal(0, [0.01, 0.01, 0.002], (n, 3)))
    m = 1_000_000
    i = rng.integers(0, n, m)
    j = rng.integers(0, n, m)
    rel = RelationSet.from_trajectory_pairs(ref, i, j, key="index")
    rel_t = RelationSet.from_trajectory_pairs(ref, i, j, key="time")
    t_index = best_of(lambda: evaluate(rel, est))
    t_time = best_of(lambda: evaluate(rel_t, est))
    return {"index_relations_s": t_index, "time_relations_s": t_time}


EVO_SCRIPT = textwrap.dedent(
    """
    import json, sys, time
    import numpy as np
    from evo.core import metrics, trajectory
    from evo.core.metrics import PoseRelation, Unit
    poses = np.load(sys.argv[1])
    t = np.arange(poses.shape[0], dtype=float)
    xyz = np.column_stack((poses[:, 0], poses[:, 1], np.zeros(len(poses))))
    def traj(p):
        xyz = np.column_stack((p[:, 0], p[:, 1], np.zeros(len(p))))
        q = np.column_stack((np.cos(p[:, 2] / 2), np.zeros(len(p)), np.zeros(len(p)), np.sin(p[:, 2] / 2)))
        return trajectory.PoseTrajectory3D(xyz, q, t)
    ref = traj(poses)
    est = traj(np.load(sys.argv[2]))
    out = {}
    for name, rel in (("trans", PoseRelation.translation_part), ("rot", PoseRelation.rotation_angle_rad)):
        start = time.perf_counter()
        m = metrics.RPE(rel, delta=1, delta_unit=Unit.frames, all_pairs=False)
        m.process_data((ref, est))
        out[name + "_s"] = time.perf_counter() - start
        np.save(sys.argv[3] + "_" + name + ".npy", m.error)
    print(json.dumps(out))
    """
)


def ensure_evo() -> Path | None:
    python = EVO_VENV / "bin" / "python"
    if python.exists():
        ok = subprocess.run([str(python), "-c", "import evo"], capture_output=True)
        if ok.returncode == 0:
            return python
    print(f"creating {EVO_VENV} with evo (once) ...", flush=True)
    r = subprocess.run([sys.executable, "-m", "venv", str(EVO_VENV)], capture_output=True, text=True)
    if r.returncode:
        print("cannot create the venv:", r.stderr.strip())
        return None
    r = subprocess.run([str(python), "-m", "pip", "install", "-q", "evo", "numpy"], capture_output=True, text=True)
    if r.returncode:
        print("cannot install evo:", r.stderr.strip()[-500:])
        return None
    return python


def bench_evo(n: int = 100_000) -> dict[str, float] | None:
    python = ensure_evo()
    if python is None:
        return None
    rng = np.random.default_rng(2)
    ref = random_trajectory(n, seed=3)
    est = Trajectory(ref.timestamps, ref.poses + rng.normal(0, [0.01, 0.01, 0.002], (n, 3)))
    rel = generate_relations(ref, "consecutive", key="index")
    t_ours = best_of(lambda: evaluate(rel, est))
    ev = evaluate(rel, est)
    with tempfile.TemporaryDirectory() as tmp:
        np.save(Path(tmp) / "ref.npy", ref.poses)
        np.save(Path(tmp) / "est.npy", est.poses)
        script = Path(tmp) / "evo_rpe.py"
        script.write_text(EVO_SCRIPT)
        r = subprocess.run(
            [str(python), str(script), str(Path(tmp) / "ref.npy"), str(Path(tmp) / "est.npy"), str(Path(tmp) / "err")],
            capture_output=True,
            text=True,
        )
        if r.returncode:
            print("evo failed:", r.stderr.strip()[-800:])
            return None
        evo_t = json.loads(r.stdout.strip().splitlines()[-1])
        evo_trans = np.load(Path(tmp) / "err_trans.npy")
        evo_rot = np.load(Path(tmp) / "err_rot.npy")
    trans_diff = float(np.abs(evo_trans - ev.errors.translation).max())
    rot_diff = float(np.abs(evo_rot - ev.errors.rotation).max())
    evo_total = evo_t["trans_s"] + evo_t["rot_s"]
    return {
        "slamrel_s": t_ours,
        "evo_trans_s": evo_t["trans_s"],
        "evo_rot_s": evo_t["rot_s"],
        "ratio": evo_total / t_ours,
        "max_abs_diff_trans": trans_diff,
        "max_abs_diff_rot": rot_diff,
    }


def bench_read(m: int = 1_000_000) -> dict[str, float]:
    rng = np.random.default_rng(4)
    t1 = np.sort(rng.uniform(1.134e9, 1.135e9, m))
    t2 = t1 + rng.uniform(0.1, 1.0, m)
    rows = np.column_stack((t1, t2, rng.normal(size=(m, 2)), np.zeros((m, 3)), rng.normal(size=m)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.relations"
        np.savetxt(path, rows, fmt="%.6f", header="t1 t2 x y z roll pitch yaw")
        start = time.perf_counter()
        read_relations(path)  # first call: includes importing pandas
        cold = time.perf_counter() - start
        warm = best_of(lambda: read_relations(path))
        base = best_of(lambda: np.loadtxt(path, comments="#"), repeat=1)
    return {"read_relations_cold_s": cold, "read_relations_warm_s": warm, "np_loadtxt_s": base}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-evo", action="store_true")
    args = parser.parse_args()
    thr = bench_throughput()
    print(f"[1] 10^6 relations, all statistics: {thr['index_relations_s']:.3f} s (index), "
          f"{thr['time_relations_s']:.3f} s (timestamps, nearest-pose association)   target < 0.5 s")
    if not args.no_evo:
        evo = bench_evo()
        if evo is not None:
            print(f"[2] RPE on 10^5 poses: slamrel {evo['slamrel_s']:.4f} s, evo {evo['evo_trans_s']:.3f} s "
                  f"(trans) + {evo['evo_rot_s']:.3f} s (rot): ratio evo/slamrel = {evo['ratio']:.0f}x   "
                  f"target >= 100x; max |diff| trans {evo['max_abs_diff_trans']:.2e} m, "
                  f"rot {evo['max_abs_diff_rot']:.2e} rad")
    rd = bench_read()
    print(f"[3] read a 10^6-line .relations file: {rd['read_relations_warm_s']:.3f} s warm, "
          f"{rd['read_relations_cold_s']:.3f} s cold (with the pandas import); np.loadtxt "
          f"{rd['np_loadtxt_s']:.3f} s: ratio {rd['np_loadtxt_s'] / rd['read_relations_warm_s']:.1f}x   target < 1 s")


if __name__ == "__main__":
    main()
