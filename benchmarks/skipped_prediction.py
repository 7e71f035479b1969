"""Issue 38: a filter that skips prediction on some control rows, its bundle logging them all.

Some EKF-SLAMs skip the prediction step on a few control rows (e.g. while their map is
empty), so that the robot's motion over those rows never enters their state, while the
exporter writes every control row to ``controls.csv`` as the robot drove it. The bundle then
states a motion the filter did not apply. This measures what that does to ``slamrel run``:
the reference EKF-SLAM on the default simulated run (simple1, noise a, seed 0), with its first
``K`` predictions skipped (the filter stays where it was and goes on), then the usual run on
the bundle with every control row. Printed per ``K``: the recovered trajectory's mean
translational error on the global relations [m], the warnings raised, and the verdict's
map–log lamp. ``--as-applied``: the bundle states the motion the filter applied instead (the
skipped rows' increments zero; the simulated run uses the odometry model, whose rows are the
filter's steps).

    PYTHONPATH=. nice python benchmarks/skipped_prediction.py --skips 0 1 2 3 5
    PYTHONPATH=. nice python benchmarks/skipped_prediction.py --skips 0 1 2 3 5 --as-applied
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from relation_metric import se2
from relation_metric.trajectory import Trajectory
from slamrel.backends import ekf_slam
from slamrel.pipeline import run_pipeline, simulate_run_input
from slamrel.report.verdict import RunFacts, run_verdict


@contextmanager
def skipping_predictions(count: int) -> Iterator[None]:
    """The reference EKF-SLAM with its first ``count`` predictions skipped."""
    original = ekf_slam._Filter.predict
    calls = {"n": 0}

    def predict(self, u, sigma):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] > count:
            original(self, u, sigma)

    ekf_slam._Filter.predict = predict  # type: ignore[method-assign]
    try:
        yield
    finally:
        ekf_slam._Filter.predict = original  # type: ignore[method-assign]


def as_applied(odometry: Trajectory, count: int) -> Trajectory:
    """The odometry with its first ``count`` increments zero (the motion a filter that skipped
    those predictions applied): poses ``1..count`` at pose 0, the rest moved with them."""
    if count == 0:
        return odometry
    p = odometry.poses
    rest = se2.compose(p[0], se2.between(p[count], p[count:]))
    return Trajectory(odometry.timestamps, np.vstack([np.repeat(p[:1], count, axis=0), rest]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skips", nargs="+", type=int, default=[0, 1, 2, 3, 5])
    ap.add_argument("--world", default="simple1")
    ap.add_argument("--noise", default="a")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--as-applied", action="store_true", help="state the motion applied")
    args = ap.parse_args()
    print(f"{'skipped':>8} {'global [m]':>11}  map-log lamp  warnings")
    for k in args.skips:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with skipping_predictions(k):
                inp = simulate_run_input(args.world, noise=args.noise, seed=args.seed)
            if args.as_applied:
                assert inp.bundle.odometry is not None
                odo = as_applied(inp.bundle.odometry, k)
                inp = replace(inp, bundle=replace(inp.bundle, odometry=odo))
            result = run_pipeline(inp)
        err = float(result.evaluations["recovered"]["global"].translation.abs.mean)
        lamp = next(j.level for j in run_verdict(RunFacts.of(result)).lines if j.key == "map_log")
        names = sorted({type(w.message).__name__ for w in caught}) or ["none"]
        print(f"{k:>8} {err:>11.4f}  {lamp:<12}  {', '.join(names)}")


if __name__ == "__main__":
    main()
