"""Start-up cost of every ``slamrel`` command, and ``slamrel evaluate`` as a process vs evo_rpe.

1. Per command: wall time of ``slamrel CMD --help`` as a whole process (what a user waits for
   before any work), and the import cost of the library modules the command's run function
   imports (``python -c "import ..."`` as a process), both minus a bare ``python -c pass``,
   measured in the same run. Target: ``slamrel --help`` < 0.3 s (whole process).
2. ``slamrel evaluate REF.tum EST.tum`` (consecutive relations generated from the
   reference) on 10^5 poses, as a whole process, vs ``evo_rpe tum`` run twice (translation
   part and rotation angle, delta 1 frame), evo in its own venv ``benchmarks/.venv-evo``
   (created on first use, as in ``bench_relation_metric.py``). Target: ≥ 50× faster. The
   RMSEs printed by both are checked to agree.

Run: ``python benchmarks/bench_startup.py`` (``--no-evo`` skips part 2's baseline).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from bench_relation_metric import ensure_evo, random_trajectory  # noqa: E402

from relation_metric.trajectory import Trajectory  # noqa: E402
from slamrel.formats.trajectories import write_trajectory  # noqa: E402

# The library modules each command's run function imports (its work, not its parser).
WORK_IMPORTS = {
    "run": "slamrel.pipeline",
    "evaluate": "relation_metric.evaluate, slamrel.formats.trajectories, relation_metric.relations, "
    "slamrel.formats.results",
    "recover": "recovery.bundle, recovery.recover, slamrel.formats.trajectories, "
    "slamrel.formats.results",
    "relations": "relation_metric.relations, slamrel.formats.trajectories",
    "map-compare": "landmark_graph.map_compare, landmark_graph.maps, landmark_graph.landmark_association",
    "review": "slamrel.review.page, landmark_graph.maps, landmark_graph.landmark_association",
    "simulate": "slamrel.simulation.bundles, slamrel.simulation.worlds, recovery.bundle",
    "slam": "slamrel.backends.ekf_slam, recovery.bundle, slamrel.formats.trajectories",
    "compare": "slamrel.report.tables",
    "solve": "slamrel.backends.least_squares, slamrel.formats.g2o, slamrel.formats.isam, "
    "slamrel.formats.trajectories, slamrel.formats.landmark_csv",
    "example": "slamrel.simulation.example, relation_metric.relations, slamrel.formats.trajectories",
    "traj": "slamrel.evaluation, slamrel.formats.bags, slamrel.trajinfo",
    "ape": "slamrel.evo_metrics, slamrel.formats.results",
    "rpe": "slamrel.evo_metrics, slamrel.formats.results",
    "nees": "relation_metric.consistency, slamrel.formats.covariances, slamrel.evaluation",
}
HEAVY = ("matplotlib", "scipy.stats", "scipy.optimize", "scipy.spatial", "slamrel.pipeline")


PYCACHE = tempfile.mkdtemp(prefix="slamrel-bench-pycache-")


def env() -> dict[str, str]:
    """The processes' environment: bytecode cached (in a temporary folder), as an installed
    package runs; ``PYTHONDONTWRITEBYTECODE`` would make every process compile slamrel's
    modules again (about 0.05 s), which no installed copy does. evo's venv has its own
    bytecode from installation."""
    out = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    out.pop("PYTHONDONTWRITEBYTECODE", None)
    out["PYTHONPYCACHEPREFIX"] = PYCACHE
    return out


def process_time(argv: list[str], repeat: int = 5) -> float:
    """Best wall time of a whole process over ``repeat`` runs [s]."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(argv, capture_output=True, env=env(), check=True)
        best = min(best, time.perf_counter() - start)
    return best


def heavy_after(code: str) -> list[str]:
    probe = f"import sys, json\n{code}\nprint(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env(), check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def bench_commands() -> list[tuple[str, float, float, str]]:
    bare = process_time([sys.executable, "-c", "pass"])
    cli = [sys.executable, "-m", "slamrel"]
    rows = [("(bare python -c pass)", bare, 0.0, "")]
    rows.append(("slamrel --help", process_time([*cli, "--help"]), 0.0, ""))
    for cmd, modules in WORK_IMPORTS.items():
        argv = [*cli, *(["import", "isam"] if cmd == "import" else [cmd]), "--help"]
        t_help = process_time(argv)
        t_work = process_time([sys.executable, "-c", f"import {modules}"], repeat=3) - bare
        rows.append(
            (f"slamrel {cmd} --help", t_help, t_work, ", ".join(heavy_after(f"import {modules}")))
        )
    return rows


def evo_rmse(text: str) -> float:
    m = re.search(r"rmse\s+([0-9.eE+-]+)", text)
    return float(m.group(1)) if m else float("nan")


def bench_evaluate(n: int, use_evo: bool) -> dict[str, float]:
    rng = np.random.default_rng(2)
    ref = random_trajectory(n, seed=3)
    est = Trajectory(ref.timestamps, ref.poses + rng.normal(0, [0.01, 0.01, 0.002], (n, 3)))
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        rp, ep, js = Path(tmp) / "ref.tum", Path(tmp) / "est.tum", Path(tmp) / "r.json"
        write_trajectory(rp, ref, format="tum")
        write_trajectory(ep, est, format="tum")
        argv = [sys.executable, "-m", "slamrel", "evaluate", str(rp), str(ep), "-q"]
        out["slamrel_s"] = process_time(argv, repeat=3)
        subprocess.run([*argv, "--json", str(js)], env=env(), check=True)
        res = json.loads(js.read_text())
        out["slamrel_rmse_trans"] = res["translation"]["abs"]["rmse"]
        out["slamrel_rmse_rot"] = res["rotation"]["abs"]["rmse"]
        python = ensure_evo() if use_evo else None
        if python is None:
            return out
        evo_rpe = str(python.parent / "evo_rpe")
        total = 0.0
        for part, key in (("trans_part", "trans"), ("angle_rad", "rot")):
            argv = [evo_rpe, "tum", str(rp), str(ep), "-r", part, "--delta", "1", "-u", "f"]
            start = time.perf_counter()
            r = subprocess.run(argv, capture_output=True, text=True)
            total += time.perf_counter() - start
            if r.returncode:
                print("evo_rpe failed:", r.stderr.strip()[-500:])
                return out
            out[f"evo_rmse_{key}"] = evo_rmse(r.stdout)
        out["evo_s"] = total
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-evo", action="store_true")
    parser.add_argument("--poses", type=int, default=100_000)
    args = parser.parse_args()
    print(
        f"{'process':28s}{'wall [s]':>10s}{'work imports [s]':>18s}  heavy modules the work imports"
    )
    for name, t_help, t_work, heavy in bench_commands():
        work = f"{t_work:18.3f}" if t_work else " " * 18
        print(f"{name:28s}{t_help:10.3f}{work}  {heavy}")
    help_t = process_time([sys.executable, "-m", "slamrel", "--help"])
    print(
        f"\nslamrel --help: {help_t:.3f} s; target < 0.3 s: {'met' if help_t < 0.3 else 'MISSED'}"
    )
    ev = bench_evaluate(args.poses, not args.no_evo)
    print(
        f"\nslamrel evaluate, {args.poses} poses (TUM, consecutive), whole process: "
        f"{ev['slamrel_s']:.3f} s (rmse {ev['slamrel_rmse_trans']:.6f} m, "
        f"{ev['slamrel_rmse_rot']:.6f} rad)"
    )
    if "evo_s" in ev:
        ratio = ev["evo_s"] / ev["slamrel_s"]
        agree = np.isclose(
            ev["evo_rmse_trans"], ev["slamrel_rmse_trans"], rtol=1e-4
        ) and np.isclose(ev["evo_rmse_rot"], ev["slamrel_rmse_rot"], rtol=1e-4)
        print(
            f"evo_rpe trans_part + angle_rad (two processes): {ev['evo_s']:.2f} s (rmse "
            f"{ev['evo_rmse_trans']:.6f} m, {ev['evo_rmse_rot']:.6f} rad; "
            f"{'agree' if agree else 'DISAGREE'})\nratio {ratio:.1f}x; target >= 50x: "
            f"{'met' if ratio >= 50 else 'MISSED'}"
        )
    else:
        print("evo unavailable: ratio not measured")


if __name__ == "__main__":
    main()
