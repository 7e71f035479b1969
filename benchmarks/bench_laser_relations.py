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
    python benchmarks/bench_laser_relations.py --whole [SEED ...] [--mit]

``--whole`` times the **whole command** instead, as a user runs it: each world written as a
CARMEN log (``FLASER``, 361 beams, ranges in mm) with its true pairs as a ``.relations``
file, then ``python -m slamrel relations align LOG --at PAIRS`` run as a child process for
each aligner; CPU seconds are the child's user + sys (``RUSAGE_CHILDREN``: start-up,
imports, reading, chain, search, ICP, flags, writing). ``--mit`` adds ``mit-csail.clf`` at
the authors' 1,172 pairs (``$SLAMREL_DATA/freiburg``). Pairs per CPU-second of the global
aligner against today's (``--aligner icp``) in the same run.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

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


def write_world(seed: int, folder: Path) -> tuple[Path, Path, int]:
    """Corridor world ``seed`` as a CARMEN log and its true pairs as a ``.relations`` file."""
    from relation_metric.relations import RelationSet
    from slamrel.formats.relations import write_relations

    _, log = corridor_log(seed)
    s = log.scans
    pairs, _ = true_pairs(log.truth, s.timestamps, seed=seed)
    ranges = np.where(np.isfinite(s.ranges), s.ranges, 81.91)
    path = folder / f"corridor{seed}.clf"
    with open(path, "w") as f:
        for k in range(s.timestamps.size):
            r = " ".join(f"{v:.3f}" for v in ranges[k])
            x, y, t = s.laser_pose[k]
            f.write(
                f"FLASER {ranges.shape[1]} {r} {x:.6f} {y:.6f} {t:.6f} {x:.6f} {y:.6f} "
                f"{t:.6f} {s.timestamps[k]:.6f} bench {s.timestamps[k]:.6f}\n"
            )
    t = s.timestamps
    truth = between(log.truth[pairs[:, 0]], log.truth[pairs[:, 1]])
    rel = folder / f"corridor{seed}.relations"
    write_relations(rel, RelationSet(t[pairs[:, 0]], t[pairs[:, 1]], truth))
    return path, rel, len(pairs)


def whole_command(log: Path, pairs: Path, aligner: str, out: Path) -> float:
    """CPU seconds (user + sys) of ``slamrel relations align`` as a child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = [sys.executable, "-m", "slamrel", "relations", "align", str(log), "--at", str(pairs)]
    cmd += ["-o", str(out), "--aligner", aligner, "-q"]
    subprocess.run(cmd, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


ROOT = Path(__file__).resolve().parent.parent


def main_whole(args: list[str]) -> None:
    """``--whole``: pairs per CPU-second of the whole command (module docstring)."""
    seeds = [int(a) for a in args if a.isdigit()] or [103, 104, 105]
    aligners = ("global", "icp")
    total = {a: [0, 0.0] for a in aligners}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        runs = [(f"seed {seed}", *write_world(seed, folder)) for seed in seeds]
        if "--mit" in args:
            data = Path(os.environ.get("SLAMREL_DATA", ROOT.parent / "shared" / "data"))
            fr = data / "freiburg"
            n = sum(1 for line in open(fr / "mit-csail.relations") if line.strip())
            runs.append(("mit-csail", fr / "mit-csail.clf", fr / "mit-csail.relations", n))
        for name, log, rel, n in runs:
            line = f"{name:10s} {n:5d} pairs"
            for a in aligners:
                cpu = whole_command(log, rel, a, folder / f"out-{a}.relations")
                total[a][0] += n
                total[a][1] += cpu
                line += f"   {a}: {cpu:6.2f} CPU-s {n / cpu:6.1f} pairs/CPU-s"
            print(line, flush=True)
    speed = {a: total[a][0] / total[a][1] for a in aligners}
    print(
        f"all        {total['global'][0]:5d} pairs   global {speed['global']:.1f} pairs/CPU-s, "
        f"icp {speed['icp']:.1f}; ratio global/icp (baseline: today's aligner, whole "
        f"command): {speed['global'] / speed['icp']:.2f}"
    )


def main() -> None:
    if "--whole" in sys.argv[1:]:
        main_whole(sys.argv[1:])
        return
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
