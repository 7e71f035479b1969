"""Acceptance of issue 37 on simulated corridor worlds: reference relations from the log's
odometry only, at the true pairs, by the guess-independent aligner (``--aligner global``)
and by today's aligner (``--aligner icp``: ICP from the guess, a correlative search where
it is lost) as the named baseline, timed in the same run (CPU seconds,
``time.process_time``, the whole pipeline: scan preparation, chain, search, ICP, flags).

Per world and pooled: flagged share; gross (> 10 cm or > 2° from the truth) among the
unflagged; recall of the flags on the gross ones; flag precision (the share of flagged
pairs that are gross); unflagged median and 99th percentile (translation, rotation); loop
pairs usable (unflagged and not gross); pairs per CPU-second.

    python benchmarks/bench_laser_relations.py [SEED ...]      (default: seeds 101-104)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from relation_metric.se2 import between
from slamrel.scans.global_align import align_scans_global
from slamrel.scans.proposals import Proposals
from slamrel.scans.relations import align_scans, guesses_from_poses
from slamrel.simulation.corridors import corridor_log, true_pairs


def run(seed: int, aligner: str) -> dict[str, np.ndarray | float]:
    _, log = corridor_log(seed)
    scans = log.scans
    pairs, kind = true_pairs(log.truth, scans.timestamps, seed=seed)
    t = scans.timestamps
    prop = Proposals(pairs, t[pairs[:, 0]], t[pairs[:, 1]], kind, np.zeros(len(pairs)))
    t0 = time.process_time()
    if aligner == "global":
        res, _ = align_scans_global(scans, prop, scans.laser_pose)
    else:
        res = align_scans(scans, prop, guesses_from_poses(scans.laser_pose, prop))
    cpu = time.process_time() - t0
    truth = between(log.truth[pairs[:, 0]], log.truth[pairs[:, 1]])
    e = between(truth, res.delta)
    return {
        "et": np.hypot(e[:, 0], e[:, 1]),
        "er": np.abs(e[:, 2]),
        "flag": res.flagged,
        "loop": kind == "loop",
        "cpu": cpu,
    }


def summary(name: str, r: dict) -> str:
    et, er, flag = r["et"], r["er"], r["flag"]
    gross = (et > 0.10) | (er > np.radians(2.0))
    ok = ~flag
    n = et.size
    caught = (gross & flag).sum() / max(gross.sum(), 1)
    prec = (gross & flag).sum() / max(flag.sum(), 1)
    med_t = np.median(et[ok]) * 1e3 if ok.any() else np.nan
    p99_t = np.percentile(et[ok], 99) * 1e2 if ok.any() else np.nan
    med_r = np.degrees(np.median(er[ok])) if ok.any() else np.nan
    p99_r = np.degrees(np.percentile(er[ok], 99)) if ok.any() else np.nan
    loops = r["loop"]
    return (
        f"{name:14s} {n:4d} pairs ({loops.sum():3d} loop)  flagged {flag.mean():6.1%}  "
        f"gross {gross.mean():6.1%}  unflagged gross {(gross & ok).sum() / max(ok.sum(), 1):6.2%}  "
        f"recall {caught:6.1%}  precision {prec:5.2f}  unflagged median {med_t:5.2f} mm "
        f"{med_r:5.3f}°  p99 {p99_t:5.2f} cm {p99_r:5.3f}°  loops usable "
        f"{(ok & ~gross & loops).sum() / max(loops.sum(), 1):6.1%}  "
        f"{n / r['cpu']:6.1f} pairs/CPU-s"
    )


def main() -> None:
    seeds = [int(a) for a in sys.argv[1:]] or [101, 102, 103, 104]
    aligners = ("global", "icp")
    pooled: dict[str, list[dict]] = {a: [] for a in aligners}
    for seed in seeds:
        for a in aligners:
            r = run(seed, a)
            pooled[a].append(r)
            print(summary(f"seed {seed} {a}", r), flush=True)
    for a in aligners:
        rs = pooled[a]
        cat = {k: np.concatenate([r[k] for r in rs]) for k in ("et", "er", "flag", "loop")}
        cat["cpu"] = sum(r["cpu"] for r in rs)
        print(summary(f"pooled {a}", cat))
    speed = {
        a: sum(len(r["et"]) for r in pooled[a]) / sum(r["cpu"] for r in pooled[a]) for a in aligners
    }
    print(
        f"speed ratio global/icp (baseline: today's aligner): {speed['global'] / speed['icp']:.2f}"
    )


if __name__ == "__main__":
    main()
