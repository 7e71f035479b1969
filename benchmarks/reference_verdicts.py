"""The verdict on healthy runs of the reference EKF-SLAM (issue 36), per lamp, with its causes.

``slamrel run WORLD --noise N --seed S`` for every world × noise × seed (seeds not tuned on:
default 10–19), judged as the main job judges it (the map prior ``auto``: the reference
EKF-SLAM's bundles state ``map_source: log``, so the smoother de-conditions the map). Each run
is one task of the resumable sweep (``slamrel.studies.sweep``) in ``--output``; the summary
prints the overall green/amber/red counts, the counts per lamp, and the runs that are not green
with the quantities the lamps judged (recovered and online NEES ``q``, map ``q``, NIS ``q``).

``--compare-priors K``: on the first K runs, recover under both map priors and check that the
trajectory is bit for bit the same and the accuracy (mean translational error on the global
relations) moves by less than 1 %. ``--consistency-before-after``: each run judged also with the
consistency lamp's ``n_eff`` of the NEES sequence alone (before the map's shared error counted).

``--rigid-removed``: per filter (``--jacobians``), the map's error split by
:func:`recovery.anchoring.rigid_split` into a rigid motion of the whole map and the rest, with
the NEES of each (``/3`` and ``/(2n − 3)``) and of maps drawn from the map's own covariance
(the oracle: ≈ 1); then the run recovered again on the map with its rigid part removed
(``RigidSplit.remove``): the recovered consistency ``q`` and the mean absolute position error
of the recovered poses before and after. A diagnostic of issue 36 (how much of the recovered
overconfidence is the map's unobservable gauge), not a fix.

    nice python benchmarks/reference_verdicts.py -o /tmp/rigid-oc --worlds simple1,complex1 \
        --noise a,c --seeds 30-34 --jacobians oc --rigid-removed --workers 2

    nice python benchmarks/reference_verdicts.py -o /tmp/refverdicts --seeds 10-19 --workers 2
"""

from __future__ import annotations

import argparse
import collections
import itertools
import json
import sys
from dataclasses import replace
from pathlib import Path

from slamrel.constants import NOISE_NAMES, WORLDS
from slamrel.studies.sweep import Task, load_results, run_sweep


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def compare_priors(world: str, noise: str, seed: int) -> dict[str, float | bool]:
    """Both map priors on one reference run: same trajectory? accuracy change, NEES ratio."""
    import numpy as np

    from slamrel.pipeline import run_pipeline

    out: dict[str, dict[str, float]] = {}
    poses = {}
    for prior in ("independent", "deconditioned"):
        r = run_pipeline(world, noise=noise, seed=seed, map_prior=prior)
        poses[prior] = r.recovery_result.trajectory.poses  # type: ignore[union-attr]
        ev = r.evaluations["recovered"]["global"]
        out[prior] = {
            "global": float(ev.translation.abs.mean),
            "nees": float(r.nees["recovered"].summary.mean),
        }
    same = bool(np.array_equal(poses["independent"], poses["deconditioned"]))
    g0, g1 = out["independent"]["global"], out["deconditioned"]["global"]
    return {
        "same_trajectory": same,
        "global_independent": g0,
        "global_deconditioned": g1,
        "accuracy_change": abs(g1 - g0) / g0,
        "nees_independent": out["independent"]["nees"],
        "nees_deconditioned": out["deconditioned"]["nees"],
    }


def jacobians_case(world: str, noise: str, seed: int, jacobians: str, iterations: int = 1) -> dict:  # type: ignore[type-arg]
    """The reference run with the EKF-SLAM's ``jacobians`` and ``iterations`` (``fej``: first-estimate, FEJ-EKF;
    ``oc``: observability-constrained, OC-EKF), judged."""
    from slamrel.pipeline import score_bundle, simulate_run_input
    from slamrel.studies.calibration import judged_case

    inp = simulate_run_input(
        world, noise=noise, seed=seed, jacobians=jacobians, iterations=iterations
    )  # type: ignore[arg-type]
    inp = replace(inp, name=f"{inp.name} ({jacobians})")
    result = score_bundle(inp, seed=seed)
    case = judged_case(result, f"reference EKF-SLAM healthy ({jacobians})")
    evs = result.evaluations.get("recovered")
    ev = None if evs is None else evs.get("global")
    case["accuracy"] = None if ev is None else float(ev.translation.abs.mean)
    return case


def _position_error(result, groundtruth) -> float:  # type: ignore[no-untyped-def]
    """Mean ‖xy − xy_true‖ of the recovered poses [m] (the reference runs start at the truth)."""
    import numpy as np

    tr = result.recovery_result.trajectory
    truth = groundtruth.poses_at(tr.timestamps)
    return float(np.mean(np.linalg.norm(tr.poses[:, :2] - truth[:, :2], axis=1)))


def rigid_removed_case(world: str, noise: str, seed: int, jacobians: str) -> dict:  # type: ignore[type-arg]
    """One reference run (``jacobians``): its map's :class:`~recovery.anchoring.RigidSplit`
    NEES per dof, the same for maps drawn from the map's covariance (mean of 20 draws), and
    the recovered ``q`` and position error on the map as it is and with its rigid part
    removed."""
    import numpy as np

    from recovery.anchoring import rigid_split, shared_by_id
    from slamrel.pipeline import score_bundle, simulate_run_input
    from slamrel.studies.calibration import judged_case

    inp = simulate_run_input(world, noise=noise, seed=seed, jacobians=jacobians)  # type: ignore[arg-type]
    b = inp.bundle
    assert b.landmarks_groundtruth is not None and b.map_covariance is not None
    rm, rt = shared_by_id(b.map_ids, b.landmarks_groundtruth[0])
    idx = np.column_stack((2 * rm, 2 * rm + 1)).reshape(-1)
    cov = b.map_covariance[np.ix_(idx, idx)]
    truth = b.landmarks_groundtruth[1][rt]
    split = rigid_split(b.map_xy[rm], truth, cov)
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal(np.zeros(idx.size), cov, size=20).reshape(20, -1, 2)
    drawn = [rigid_split(truth + d, truth, cov) for d in draws]
    out: dict = {  # type: ignore[type-arg]
        "landmarks": int(rm.size),
        "rigid": [split.dx, split.dy, split.dtheta],
        "rigid_nees": split.nees_rigid / 3,  # type: ignore[operator]
        "residual_nees": split.nees_residual / split.dof_residual,  # type: ignore[operator]
        "drawn_rigid_nees": float(np.mean([d.nees_rigid for d in drawn])) / 3,  # type: ignore[misc]
        "drawn_residual_nees": float(np.mean([d.nees_residual for d in drawn]))  # type: ignore[misc]
        / split.dof_residual,
    }
    xy, q = split.remove(b.map_xy, b.map_covariance)
    assert q is not None
    m = xy.shape[0]
    marg = q.reshape(m, 2, m, 2)[np.arange(m), :, np.arange(m), :]
    moved = replace(inp, bundle=replace(b, map_xy=xy, map_covariance=q, map_marginals=marg))
    for when, run in (("before", inp), ("after", moved)):
        result = score_bundle(run, seed=seed)
        case = judged_case(result, f"reference EKF-SLAM ({jacobians}, rigid {when})")
        out[when] = {
            "q": case["values"].get("consistency"),
            "level": case["levels"].get("consistency"),
            "position_error": _position_error(result, b.groundtruth),
        }
    return out


def _rigid_summary(records: list[dict], jacobians: str) -> list[str]:  # type: ignore[type-arg]
    """Median (max) of each measure over the runs."""
    import numpy as np

    res = [r["result"] for r in records]

    def mm(vals: list[float]) -> str:
        return f"{np.median(vals):.3g} ({np.max(vals):.3g})"

    return [
        f"rigid split, {jacobians}, {len(res)} runs — median (max):",
        f"  map rigid NEES/3 {mm([r['rigid_nees'] for r in res])}; "
        f"residual NEES/(2n-3) {mm([r['residual_nees'] for r in res])}",
        f"  maps drawn from own covariance: rigid {mm([r['drawn_rigid_nees'] for r in res])}; "
        f"residual {mm([r['drawn_residual_nees'] for r in res])}",
        f"  rotation |dθ| deg {mm([abs(np.degrees(r['rigid'][2])) for r in res])}; "
        f"translation m {mm([float(np.hypot(*r['rigid'][:2])) for r in res])}",
        f"  recovered q before {mm([r['before']['q'] for r in res])} -> rigid removed "
        f"{mm([r['after']['q'] for r in res])}",
        "  recovered consistency green/amber/red "
        + " -> rigid removed ".join(
            "/".join(str(sum(r[w]["level"] == lv for r in res)) for lv in ("green", "amber", "red"))
            for w in ("before", "after")
        ),
        "  mean abs position error [m] before "
        f"{np.mean([r['before']['position_error'] for r in res]):.3f} -> rigid removed "
        f"{np.mean([r['after']['position_error'] for r in res]):.3f}",
    ]


def lamp_before_after(world: str, noise: str, seed: int) -> dict:  # type: ignore[type-arg]
    """The reference run judged as :func:`~slamrel.studies.calibration.reference_case`, and
    under ``"before"`` the same run's verdict with the consistency lamp's ``n_eff`` of the NEES
    sequence alone (before the map's shared error was counted, ``RunFacts.nees_law`` None)."""
    from dataclasses import replace

    from slamrel.pipeline import run_pipeline
    from slamrel.report.verdict import RunFacts, run_verdict
    from slamrel.studies.calibration import REFERENCE, judged_case

    result = run_pipeline(world, noise=noise, seed=seed)
    out = judged_case(result, REFERENCE)
    before = run_verdict(replace(RunFacts.of(result), nees_law=None))
    out["before"] = {
        "overall": before.level,
        "levels": {ln.key: ln.level for ln in before.lines},
    }
    return out


def _before_after(records: list[dict]) -> list[str]:  # type: ignore[type-arg]
    """Overall and consistency counts before and after the shared-error ``n_eff``."""
    lines = []
    for when in ("before", "after"):
        res = [r["result"] if when == "after" else r["result"]["before"] for r in records]
        o = collections.Counter(r["overall"] for r in res)
        c = collections.Counter(r["levels"].get("consistency") for r in res)
        lines.append(
            f"{when}: overall "
            + ", ".join(f"{k} {o[k]}" for k in ("green", "amber", "red"))
            + "; recovered consistency "
            + ", ".join(f"{k} {c[k]}" for k in ("green", "amber", "red"))
        )
    return lines


def _summary(records: list[dict], worlds, noises) -> list[str]:  # type: ignore[no-untyped-def]
    lines = []
    overall = collections.Counter(r["result"]["overall"] for r in records)
    lines.append(
        f"runs {len(records)}: overall "
        + ", ".join(f"{k} {overall[k]}" for k in ("green", "amber", "red"))
    )
    lamps = collections.defaultdict(collections.Counter)
    for r in records:
        for k, lv in r["result"]["levels"].items():
            lamps[k][lv] += 1
    for k, c in lamps.items():
        lines.append(f"  {k}: " + ", ".join(f"{lv} {n}" for lv, n in sorted(c.items())))
    for w, n in itertools.product(worlds, noises):
        rs = [r for r in records if r["kwargs"]["world"] == w and r["kwargs"]["noise"] == n]
        c = collections.Counter(r["result"]["overall"] for r in rs)
        lines.append(f"  {w}/{n}: " + ", ".join(f"{k} {c[k]}" for k in ("green", "amber", "red")))
    lines.append("not green (lamp: level q):")
    for r in records:
        res = r["result"]
        if res["overall"] == "green":
            continue
        kw = r["kwargs"]
        bad = {k: lv for k, lv in res["levels"].items() if lv in ("amber", "red")}
        vals = res["values"]
        q = {
            k: vals.get(k)
            for k in ("consistency", "online_consistency", "map_consistency", "map_log")
        }
        lines.append(
            f"  {kw['world']}/{kw['noise']}/{kw['seed']}: {res['overall']}; "
            + ", ".join(f"{k} {lv}" for k, lv in bad.items())
            + "; q "
            + ", ".join(f"{k} {v:.2f}" for k, v in q.items() if isinstance(v, (int, float)))
        )
    return lines


def _grid_tasks(
    prefix: str,
    function: str,
    worlds: list[str],
    noises: list[str],
    seeds: list[int],
    extra: dict[str, str],
) -> list[Task]:
    """One task ``PREFIX-WORLD-NOISE-SEED`` of this module's ``function`` per world × noise × seed."""
    return [
        Task(
            f"{prefix}-{w}-{n}-{s}",
            f"benchmarks.reference_verdicts:{function}",
            {"world": w, "noise": n, "seed": s, **extra},
        )
        for w, n, s in itertools.product(worlds, noises, seeds)
    ]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--worlds", default=",".join(WORLDS))
    p.add_argument("--noise", default=",".join(NOISE_NAMES))
    p.add_argument("--seeds", type=_seeds, default=_seeds("10-19"))
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--compare-priors", type=int, default=0, metavar="K")
    p.add_argument("--jacobians", choices=("standard", "fej", "oc"), default="standard")
    p.add_argument("--iterations", type=int, default=1, help="iterated EKF updates (1: plain)")
    p.add_argument("--consistency-before-after", action="store_true")
    p.add_argument("--rigid-removed", action="store_true")
    a = p.parse_args(argv)
    worlds, noises = a.worlds.split(","), a.noise.split(",")
    if a.rigid_removed:
        return _rigid_main(a, worlds, noises)
    grid = (worlds, noises, a.seeds)
    tasks = (
        _grid_tasks("ref-before-after", "lamp_before_after", *grid, {})
        if a.consistency_before_after
        else _grid_tasks(
            f"ref-{a.jacobians}" + (f"-it{a.iterations}" if a.iterations > 1 else ""),
            "jacobians_case",
            *grid,
            {"jacobians": a.jacobians, "iterations": a.iterations},
        )
    )
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    run_sweep(tasks, out / "cases", workers=a.workers)
    lines = _summary(load_results(out / "cases", tasks), worlds, noises)
    if a.consistency_before_after:
        lines += _before_after(load_results(out / "cases", tasks))
    if a.compare_priors:
        cmp = [
            Task(f"cmp-{t.kwargs['world']}-{t.kwargs['noise']}-{t.kwargs['seed']}",
                 "benchmarks.reference_verdicts:compare_priors", t.kwargs)
            for t in tasks[:: max(1, len(tasks) // a.compare_priors)][: a.compare_priors]
        ]  # fmt: skip
        run_sweep(cmp, out / "compare", workers=a.workers)
        res = [r["result"] for r in load_results(out / "compare", cmp)]
        lines.append(
            f"priors compared on {len(res)} runs: trajectory identical on "
            f"{sum(r['same_trajectory'] for r in res)}; accuracy change max "
            f"{100 * max(r['accuracy_change'] for r in res):.4f} %; NEES ratio "
            f"{min(r['nees_deconditioned'] / r['nees_independent'] for r in res):.2f}–"
            f"{max(r['nees_deconditioned'] / r['nees_independent'] for r in res):.2f}"
        )
    text = "\n".join(lines)
    print(text)
    (out / "summary.txt").write_text(text + "\n")
    json.dump(
        [r for r in load_results(out / "cases", tasks)], open(out / "records.json", "w"), indent=1
    )
    return 0


def _rigid_main(a: argparse.Namespace, worlds: list[str], noises: list[str]) -> int:
    tasks = _grid_tasks(
        f"rigid-{a.jacobians}",
        "rigid_removed_case",
        worlds,
        noises,
        a.seeds,
        {"jacobians": a.jacobians},
    )
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    run_sweep(tasks, out / "rigid", workers=a.workers)
    records = load_results(out / "rigid", tasks)
    text = "\n".join(_rigid_summary(records, a.jacobians))
    print(text)
    (out / f"rigid-{a.jacobians}.txt").write_text(text + "\n")
    json.dump(records, open(out / f"rigid-{a.jacobians}.json", "w"), indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
