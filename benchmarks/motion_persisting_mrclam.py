"""The odometry's persisting error on MRCLAM (docs/recovery.md, "Real data: MRCLAM").

Per robot of a dataset: :func:`slamrel.importers.mrclam.fit_motion_persisting` on the
importer's controls (calibrated, split at gaps), the velocity model's ``α1 / α3`` fitted over
1 s and over 5 s windows (:func:`~slamrel.importers.mrclam.fit_noise`) and each less the
persisting error's share at its window (:func:`~slamrel.importers.mrclam.white_alpha`, the
controls' median period): were the Gauss–Markov error all that persists, the two white
columns would agree. Prints a Markdown table.

    SLAMREL_DATA=../shared/data PYTHONPATH=. nice python benchmarks/motion_persisting_mrclam.py
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from slamrel.importers.mrclam import (
    calibrate_odometry,
    fit_motion_persisting,
    fit_noise,
    read_mrclam_robot,
    resample_controls,
    white_alpha,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", default="MRCLAM_Dataset7")
    ap.add_argument("--max-lag", type=int, default=30)
    args = ap.parse_args()
    d = Path(os.environ.get("SLAMREL_DATA", "../shared/data")) / "mrclam" / args.dataset
    lms = np.loadtxt(d / "Landmark_Groundtruth.dat")[:, :3]
    print("| robot | σ speed scale | τ [s] | σ turn [rad/m] | τ [s] | moved windows | "
          "α1 / α3 over 1 s | white α1 / α3 | α1 / α3 over 5 s | 5 s less its share |")  # fmt: skip
    print("|" + " --- |" * 10)
    for robot in range(1, 6):
        r = read_mrclam_robot(d, robot)
        r = replace(r, controls=resample_controls(calibrate_odometry(r).apply(r.controls)))
        fit = fit_motion_persisting(r, max_lag=args.max_lag)
        if fit is None:
            print(f"| {robot} | not fitted |" + " |" * 8)
            continue
        p = fit.persisting
        period = float(np.median(np.diff(r.controls[:, 0])))
        cols = []
        for window in (1.0, 5.0):
            a = fit_noise(r, lms, window=window).alpha
            w, clipped = white_alpha(a, p, window=window, period=period)
            cols += [f"{a[0]:.2f} / {a[2]:.2f}",
                     f"{w[0]:.2f} / {w[2]:.2f}" + (" (clipped)" if clipped else "")]  # fmt: skip
        print(f"| {robot} | {p.sigma_scale:.3f} | {p.time_constant_scale:.1f} | "
              f"{p.sigma_turn:.3f} | {p.time_constant_turn:.1f} | {fit.windows} | "
              + " | ".join(cols) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
