"""Issue 38: what the robust update costs on clean runs and buys on broken ones.

For every run, the trajectory is recovered (the default smoother) with each ``--robust``
choice and scored by its mean translational error on the global relations of
``slamrel run``'s default relation sets (:func:`slamrel.pipeline.default_relations`, drawn
from the ground truth). Printed per run: each choice's error [m], its share of measurements
down-weighted and of information taken, and the best choice; then, per kind of run, the mean
ratio of each choice's error to the best choice's and the largest.

Runs: the reference EKF-SLAM (``slamrel run WORLD --noise N --seed S``), the calibration's
healthy-by-construction bundles (exact models, ``joint`` map) and the same with each of the
calibration's faults (:data:`slamrel.studies.calibration.FAULTS`), and the independent
textbook EKF-SLAM of ``tests/clients`` (``--client``).

    PYTHONPATH=. nice python benchmarks/robust_default.py --seeds 0 1 --faults
    PYTHONPATH=. nice python benchmarks/robust_default.py --noises b --seeds 0 --healthy
    PYTHONPATH=. nice python benchmarks/robust_default.py --worlds --seeds 0 1 2 --client
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

from recovery.bundle import Bundle
from recovery.recover import recover
from relation_metric.evaluate import evaluate
from relation_metric.relations import RelationSet
from slamrel.pipeline import default_relations, simulate_run_input
from slamrel.simulation.healthy import healthy_bundle
from slamrel.studies.calibration import FAULTS, broken_bundle

#: ``--robust`` choices measured: label → (kind, threshold or None for the kind's default).
CHOICES: dict[str, tuple[str | None, float | None]] = {
    "none": (None, None),
    "redesc-1.75": ("redescending", 1.75),  # the default before issue 38
    "huber": ("huber", None),
    "cauchy": ("cauchy", None),
    # sqrt(chi2_2(0.999)): the default on logs without heavy tails
    "redesc-3.72": ("redescending", 3.717),
}

#: Healthy runs: the reference EKF-SLAM's, and healthy by construction (exact models).
KINDS = ("reference", "exact")


def score(bundle: Bundle, relations: RelationSet, kind: str | None, c: float | None) -> dict:
    """Error [m] on ``relations`` and the robust weights' counts of one recovery."""
    rec = recover(bundle, robust=kind, robust_threshold=c)
    err = float(evaluate(relations, rec.trajectory).translation.abs.mean)
    return {
        "err": err,
        "down": rec.counts.downweighted_fraction,
        "loss": rec.counts.downweight_loss,
    }


def runs(args: argparse.Namespace) -> Iterator[tuple[str, str, Bundle]]:
    """``(kind of run, name, bundle)`` for every run measured."""
    for world in args.worlds:
        for noise in args.noises:
            for seed in args.seeds:
                if "reference" in args.healthy:
                    inp = simulate_run_input(world, noise=noise, seed=seed)
                    yield "reference EKF-SLAM", f"{world}/{noise}/{seed}", inp.bundle
                hb = healthy_bundle(world, seed, "joint", noise=noise, odometry=None)
                if "exact" in args.healthy:
                    yield "healthy (exact models)", f"{world}/{noise}/{seed}", hb
                for fault in args.faults:
                    fkind, value = FAULTS[fault]
                    if fkind == "map":
                        b = healthy_bundle(
                            world, seed, "joint", noise=noise, odometry=None, error_scale=value
                        )
                    else:
                        b = broken_bundle(hb, fault, seed=seed)
                    yield f"broken: {fault}", f"{world}/{noise}/{seed}", b
    if args.client:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from clients.measure import export
        from clients.textbook_ekfslam import run

        with TemporaryDirectory() as tmp:
            for seed in args.seeds:
                bundle, _ = export(run(seed), Path(tmp) / str(seed))
                yield "textbook client", f"seed {seed}", bundle


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worlds", nargs="*", default=["simple1", "complex1"])
    ap.add_argument("--noises", nargs="+", default=["a", "b", "c"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--faults", nargs="*", default=list(FAULTS), choices=list(FAULTS))
    ap.add_argument("--healthy", nargs="*", default=["reference", "exact"], choices=KINDS)
    ap.add_argument("--client", action="store_true", help="also the textbook client")
    args = ap.parse_args()
    ratios: dict[str, dict[str, list[float]]] = {}
    downs: dict[str, dict[str, list[float]]] = {}
    print("run".ljust(44) + "".join(f"{c:>13}" for c in CHOICES) + "   down-weighted (3.72; 1.75)")
    for kind, name, bundle in runs(args):
        if bundle.groundtruth is None:
            continue
        rel = default_relations(bundle.groundtruth).sets["global"]
        res = {label: score(bundle, rel, k, c) for label, (k, c) in CHOICES.items()}
        best = min(r["err"] for r in res.values())
        for label, r in res.items():
            ratios.setdefault(kind, {}).setdefault(label, []).append(r["err"] / best)
            downs.setdefault(kind, {}).setdefault(label, []).append(r["down"])
        cells = "".join(f"{r['err']:>13.4f}" for r in res.values())
        d, o = res["redesc-3.72"], res["redesc-1.75"]
        print(
            f"{kind + ' ' + name:<44}{cells}   {d['down']:.4f} ({d['loss']:.5f} info), "
            f"1.75: {o['down']:.3f} ({o['loss']:.3f})"
        )
        sys.stdout.flush()
    print("\nmean (max) error over the best choice's, and mean share down-weighted:")
    print("kind of run".ljust(26) + "".join(f"{c:>20}" for c in CHOICES))
    for kind, by in ratios.items():
        cells = "".join(
            f"{np.mean(v):>9.4f} ({max(v):.3f}) {np.mean(downs[kind][k]):>4.2f}"
            for k, v in by.items()
        )
        print(f"{kind:<26}{cells}")
    print(f"\nredesc-3.72: c = sqrt(chi2_2(0.999)) = {math.sqrt(-2 * math.log(1e-3)):.4f}")


if __name__ == "__main__":
    main()
