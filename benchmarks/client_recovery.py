"""Issue 23: slamrel's recovery on an independent, textbook EKF-SLAM client (a table).

Run: ``python3 benchmarks/client_recovery.py [--seeds 0 1 2] [--configs default proper cx-as-r]
[--exporters odometry velocity velocity-lag velocity-euler]``.

The client is tests/clients/textbook_ekfslam.py (Probabilistic Robotics Tables 10.1/10.2 in
the PythonRobotics structure; no code of slamrel's EKF-SLAM or recovery). Each run is
exported as a result bundle, read back with ``read_bundle`` and scored: the mean translational
error [m] on 2,000 global relations of the client's online estimate, of ``recover`` for every
method × map_mode, and of localisation in the true map (the floor, smoother + ignore). Also
the client's association error rate (against each client landmark's majority truth), its
landmark count (true landmarks seen) and its mean NIS over updates of existing landmarks.

Configurations of the client: ``default`` (improper landmark init, R = the true sensor
noise), ``proper`` (Jacobian-based init), ``cx-as-r`` (R = Cx[0:2, 0:2], PythonRobotics'
habit). Exporters: ``odometry`` (the client's dead reckoning, sigma from Cx), ``velocity``
(today's velocity model, stamps converted, σ_v, σ_ω from Cx), ``velocity-lag`` (the
client's end-of-interval stamps written unconverted), ``velocity-euler`` (the client's own
model; needs the wt-motion reader, reported as unavailable otherwise), ``recorded`` (what
the client reported to slamrel's BundleRecorder as it ran, its values as written; issue 38:
``--configs quirks --exporters recorded``).

Acceptance (issue 23): smoother/joint ≤ online and ≤ 1.3 × floor in every seed.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from clients.export import recorder_for  # noqa: E402
from clients.measure import DEFAULT, FLOOR_FACTOR, measure, table  # noqa: E402
from clients.textbook_ekfslam import Config, run  # noqa: E402

from relation_metric.errors import InputError  # noqa: E402

CONFIGS = {
    "default": Config(),
    "proper": Config(init="proper"),
    "cx-as-r": Config(reuse_cx_as_r=True),
    "proper+cx-as-r": Config(init="proper", reuse_cx_as_r=True),
    # issue 38: what third-party filters write (a sensor mount, a per-step control covariance,
    # a zero initial covariance, range-0 dropouts); exported by the "recorded" exporter
    "quirks": Config(
        mount=(0.3, 0.1, math.radians(5.0)),
        motion_noise="control",
        initial_variance=0.0,
        dropout=0.005,
    ),
}
EXPORTERS = ("odometry", "velocity", "velocity-lag", "velocity-euler", "recorded")


def verdict(rows: dict[int, dict[str, object]]) -> str:
    bad = [
        s
        for s, r in rows.items()
        if not (
            float(r[DEFAULT]) <= float(r["online"])  # type: ignore[arg-type]
            and float(r[DEFAULT]) <= FLOOR_FACTOR * float(r["floor"])  # type: ignore[arg-type]
        )
    ]
    return "acceptance met" if not bad else f"acceptance MISSED in seed(s) {bad}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    ap.add_argument("--exporters", nargs="+", default=list(EXPORTERS), choices=EXPORTERS)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.configs:
            cfg = CONFIGS[name]  # the recorder only listens: the run is the same with it
            runs = {s: run(s, cfg, recorder=recorder_for(cfg)) for s in args.seeds}
            for exporter in args.exporters:
                t0 = time.perf_counter()
                try:
                    rows = {
                        s: measure(r, Path(tmp) / f"{name}-{exporter}-{s}", exporter=exporter)
                        for s, r in runs.items()
                    }
                except InputError as exc:
                    print(f"\n[{name} / {exporter}] not readable by this slamrel: {exc}")
                    continue
                print(
                    f"\n[{name} / {exporter}]  {verdict(rows)}  ({time.perf_counter() - t0:.1f} s)"
                )
                print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
