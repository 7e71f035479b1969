"""Issue 23: slamrel's recovery on PythonRobotics' EKF-SLAM, imported at run time (a table).

Run: ``python3 benchmarks/bench_third_party_client.py [--seeds 0 1 2]``.

Fetches nothing and copies nothing: when a PythonRobotics checkout is present at
``$SLAMREL_PYTHONROBOTICS`` (default ``../shared/peers/PythonRobotics`` beside the project),
its ``SLAM/EKFSLAM/ekf_slam.py`` is imported and its own functions run the simulation and the
filter (``observation``, ``calc_input``, ``ekf_slam``), driven the way its ``main()`` drives
them, with ``np.random.seed(seed)``. Its associations are recorded by wrapping the module's
``search_correspond_landmark_id`` (the function ``ekf_slam`` calls; the wrapper returns its
result unchanged). Worlds: its own four RFID landmarks, and slamrel's loop world of
tests/clients (12 landmarks; the path is PythonRobotics' own v = 1, ω = 0.1 circle). The
runs are exported with tests/clients/export.py (filter settings: its ``Cx``, ``R =
Cx[0:2, 0:2]``, ``P0 = I``) and scored as in benchmarks/client_recovery.py. Without the
folder it prints a skip message and exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from clients.measure import measure, table  # noqa: E402
from clients.textbook_ekfslam import Config, Run, loop_world  # noqa: E402

EXPORTERS = ("odometry", "velocity")


def load_pythonrobotics(root: Path):  # type: ignore[no-untyped-def]
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(root))  # for its `from utils.angle import angle_mod`
    sys.path.insert(0, str(root / "SLAM" / "EKFSLAM"))
    mod = importlib.import_module("ekf_slam")
    mod.show_animation = False  # type: ignore[attr-defined]
    return mod


def run_pythonrobotics(pr, seed: int, landmarks: np.ndarray) -> Run:  # type: ignore[no-untyped-def]
    """Its main() loop, recording what a bundle needs."""
    np.random.seed(seed)  # noqa: NPY002 - its code draws from numpy's global generator
    record: list[tuple[int, float]] = []
    search = pr.search_correspond_landmark_id

    def recording_search(xAug, PAug, zi):  # type: ignore[no-untyped-def]
        j = search(xAug, PAug, zi)
        n = pr.calc_n_lm(xAug)
        nis = math.nan
        if j < n:
            y, S, _ = pr.calc_innovation(
                pr.get_landmark_position_from_state(xAug, j), xAug, PAug, zi, j
            )
            nis = float((y.T @ np.linalg.inv(S) @ y)[0, 0])
        record.append((j, nis))
        return j

    pr.search_correspond_landmark_id = recording_search
    try:
        x_est, p_est = np.zeros((3, 1)), np.eye(3)
        x_true, x_dr = np.zeros((3, 1)), np.zeros((3, 1))
        truth, dr, onl, ctrl = (
            [x_true[:, 0].copy()],
            [x_dr[:, 0].copy()],
            [x_est[:, 0].copy()],
            [np.zeros(2)],
        )
        mt, mz, mtrue = [], [], []
        t, k = 0.0, 0
        with contextlib.redirect_stdout(io.StringIO()):  # its "New LM" prints
            while pr.SIM_TIME >= t:
                t += pr.DT
                k += 1
                u = pr.calc_input()
                x_true, z, x_dr, ud = pr.observation(x_true, x_dr, u, landmarks)
                x_est, p_est = pr.ekf_slam(x_est, p_est, ud, z)
                truth.append(x_true[:, 0].copy())
                dr.append(x_dr[:, 0].copy())
                onl.append(x_est[:3, 0].copy())
                ctrl.append(ud[:, 0].copy())
                for row in z:
                    mt.append(k * pr.DT)
                    mz.append(row[:2])
                    mtrue.append(int(row[2]))
    finally:
        pr.search_correspond_landmark_id = search
    assoc = np.array([j for j, _ in record], dtype=int)
    nis = np.array([v for _, v in record])
    cx = np.sqrt(np.diag(pr.Cx))
    cfg = Config(dt=pr.DT, steps=k, cx=(cx[0], cx[1], cx[2]), reuse_cx_as_r=True)
    new = ~np.isfinite(nis)  # it opens a landmark exactly when no existing one is nearer
    return Run(
        config=cfg,
        landmarks=np.asarray(landmarks, float),
        times=pr.DT * np.arange(k + 1),
        truth=np.array(truth),
        controls=np.array(ctrl),
        dead_reckoning=np.array(dr),
        online=np.array(onl),
        meas_t=np.array(mt),
        meas_z=np.array(mz).reshape(-1, 2),
        meas_true=np.array(mtrue, dtype=int),
        meas_assoc=assoc,
        meas_new=new,
        nis=nis,
        x=x_est[:, 0].copy(),
        P=p_est.copy(),
        initial_covariance=np.eye(3),
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    default = ROOT.parent / "shared" / "peers" / "PythonRobotics"
    root = Path(os.environ.get("SLAMREL_PYTHONROBOTICS", default))
    if not (root / "SLAM" / "EKFSLAM" / "ekf_slam.py").is_file():
        print(f"skipped: no PythonRobotics at {root} (set SLAMREL_PYTHONROBOTICS)")
        return 0
    pr = load_pythonrobotics(root)
    worlds = {
        "pythonrobotics-rfid": np.array([[10.0, -2.0], [15.0, 10.0], [3.0, 15.0], [-5.0, 20.0]]),
        "loop-world": loop_world(radius=10.0),
    }
    with tempfile.TemporaryDirectory() as tmp:
        for name, lms in worlds.items():
            runs = {s: run_pythonrobotics(pr, s, lms) for s in args.seeds}
            for exporter in EXPORTERS:
                rows = {
                    s: measure(r, Path(tmp) / f"{name}-{exporter}-{s}", exporter=exporter)
                    for s, r in runs.items()
                }
                print(f"\n[PythonRobotics ekf_slam, {name} / {exporter}]")
                print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
