"""evo's RPE and APE on the TUM RGB-D sequences of ``../shared/data/tum_rgbd``, for parity tests.

Runs evo (``benchmarks/.venv-evo``, created on first use by
:func:`bench_relation_metric.ensure_evo`) through its Python API, the equivalent of::

    evo_rpe tum GT EST --t_max_diff 0.01 --delta D --delta_unit {f,m} --pairs_from_reference \
        --pose_relation {trans_part,angle_rad}
    evo_ape tum GT EST --t_max_diff 0.01 [-a | -as] --pose_relation {trans_part,angle_rad}

and prints, per case, evo's version, the statistics (``get_all_statistics``) and the error
count as JSON (``--arrays DIR`` also saves every error array as ``DIR/<case>.npy``).
Run: ``python benchmarks/evo_reference.py [--data DIR] [--arrays DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

DATA = Path(os.environ.get("SLAMREL_DATA", HERE.parent.parent / "shared" / "data")) / "tum_rgbd"

SEQUENCES = {
    "fr1_xyz": ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    "fr2_desk": ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"),
}
# (name, sequence, metric, delta, unit, align) — align: "" | "se3" | "sim3" (APE only)
CASES = [
    ("fr1_xyz/rpe/1f", "fr1_xyz", "rpe", 1, "frames", ""),
    ("fr1_xyz/rpe/10f", "fr1_xyz", "rpe", 10, "frames", ""),
    ("fr1_xyz/rpe/0.2m", "fr1_xyz", "rpe", 0.2, "meters", ""),
    ("fr1_xyz/ape", "fr1_xyz", "ape", 0, "", ""),
    ("fr1_xyz/ape/se3", "fr1_xyz", "ape", 0, "", "se3"),
    ("fr2_desk/rpe/1f", "fr2_desk", "rpe", 1, "frames", ""),
    ("fr2_desk/rpe/1m", "fr2_desk", "rpe", 1.0, "meters", ""),
    ("fr2_desk/ape/se3", "fr2_desk", "ape", 0, "", "se3"),
    ("fr2_desk/ape/sim3", "fr2_desk", "ape", 0, "", "sim3"),
]
T_MAX_DIFF = 0.01

EVO_SCRIPT = textwrap.dedent(
    """
    import copy, json, sys
    import numpy as np
    import evo
    from evo.core import metrics, sync
    from evo.core.metrics import PoseRelation, Unit
    from evo.tools import file_interface
    data, cases, arrays = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
    out = {"evo_version": evo.__version__}
    for name, (gt, est), metric, delta, unit, align in cases:
        ref = file_interface.read_tum_trajectory_file(data + "/" + gt)
        e = file_interface.read_tum_trajectory_file(data + "/" + est)
        ref, e = sync.associate_trajectories(ref, e, max_diff=%(tmax)r)
        if align:
            e = copy.deepcopy(e)
            e.align(ref, correct_scale=(align == "sim3"))
        res = {}
        for part, rel in (("trans", PoseRelation.translation_part),
                          ("rot", PoseRelation.rotation_angle_rad)):
            if metric == "rpe":
                m = metrics.RPE(rel, delta=delta, delta_unit=Unit[unit], all_pairs=False,
                                pairs_from_reference=True)
            else:
                m = metrics.APE(rel)
            m.process_data((ref, e))
            res[part] = {k: float(v) for k, v in m.get_all_statistics().items()}
            res[part]["count"] = int(m.error.size)
            if arrays:
                np.save(arrays + "/" + name.replace("/", "_") + "_" + part + ".npy", m.error)
        out[name] = res
    print(json.dumps(out))
    """
) % {"tmax": T_MAX_DIFF}


def run_evo(python: str | Path, data: Path = DATA, arrays: str | Path = "") -> dict:
    """Run :data:`EVO_SCRIPT` with ``python`` (a venv with evo); evo's results by case."""
    cases = [(n, SEQUENCES[s], m, d, u, a) for n, s, m, d, u, a in CASES]
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "evo_reference.py"
        script.write_text(EVO_SCRIPT)
        r = subprocess.run(
            [str(python), str(script), str(data), json.dumps(cases), str(arrays)],
            capture_output=True,
            text=True,
            check=False,
        )
    if r.returncode:
        raise RuntimeError("evo failed: " + r.stderr.strip()[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def evo_python() -> Path | None:
    """The evo venv's python when it exists and imports evo (never creates it)."""
    from bench_relation_metric import EVO_VENV

    python = EVO_VENV / "bin" / "python"
    if not python.exists():
        return None
    ok = subprocess.run([str(python), "-c", "import evo"], capture_output=True, check=False)
    return python if ok.returncode == 0 else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--arrays", default="")
    args = parser.parse_args()
    from bench_relation_metric import ensure_evo

    python = ensure_evo()
    if python is None:
        sys.exit("evo is not available")
    print(json.dumps(run_evo(python, args.data, args.arrays), indent=1))


if __name__ == "__main__":
    main()
