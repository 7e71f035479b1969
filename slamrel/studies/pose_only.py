"""The study of Hu, Huang & Dissanayake ("Evaluation of Pose Only SLAM", IROS 2010), reproduced.

Worlds × noise types × Monte Carlo runs × methods, each case a pure function of
``(world, noise, seed, method, options)`` (:func:`run_case`), run as a resumable sweep
(:mod:`slamrel.studies.sweep`). Methods:

* ``full`` — full least squares (poses and landmarks);
* ``m1``, ``m2`` — pose-only least squares, Method 1 / Method 2
  (:func:`slamrel.backends.pose_only.pose_only_least_squares`);
* ``toro`` — TORO (:mod:`slamrel.backends.toro_optimiser`, written from Grisetti et al.
  2007) on the Method 2 pose graph, its covariance that of the spherical graph at its
  estimate.

Per case: NEES1 (trajectory, joint covariance, gate ``χ²₀.₉₅(3(N−1))``); the paper's NEES2
(χ² of the relative-pose constraints at the estimate) and NEES3 (χ² of all the original
odometry and observations, landmarks fitted to the fixed poses), neither using ground
truth; the landmark NEES against the true landmarks (slamrel's own check, formerly shown
as "map NEES (2 / 3)"); RMS position and heading errors, run time. :func:`summary_rows`
aggregates them into the analogues of the paper's Tables II/III, written as Markdown, CSV
and LaTeX by :func:`write_tables`; :func:`write_figures` draws the Fig. 1 analogue (pose
errors and 2σ bounds, Method 1 vs Method 2) and a Fig. 2 analogue (NEES1 of every run
against its gate).
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from relation_metric import se2
from relation_metric.consistency import nees1, nees2
from relation_metric.errors import InputError
from slamrel.backends.graph import PoseGraph
from slamrel.backends.least_squares import joint_covariance, solve_graph
from slamrel.backends.pose_only import (
    LandmarkLog,
    data_chi2,
    full_graph,
    landmarks_given_poses,
    odometry_graph,
    pose_only_least_squares,
    relative_pose_chi2,
)
from slamrel.backends.toro_optimiser import spherical_information, toro_optimize
from slamrel.constants import POSE_ONLY_METHODS as METHODS
from slamrel.formats.text import write_text_atomic
from slamrel.simulation.worlds import make_world
from slamrel.studies.sweep import Task

__all__ = [
    "METHODS",
    "run_case",
    "study_tasks",
    "summary_rows",
    "write_tables",
    "write_figures",
    "findings",
    "write_findings",
]

METHOD_NAMES = {
    "full": "full LS",
    "m1": "pose-only M1",
    "m2": "pose-only M2",
    "toro": "TORO (M2)",
}


def _errors(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return se2.minus(truth, est)


def run_case(
    world: str,
    noise: str,
    seed: int,
    method: str,
    *,
    pair_start: str = "truth",
    min_common: int = 5,
    toro_iterations: int = 100,
    toro_rules: str = "papers",
    details: bool = False,
) -> dict[str, Any]:
    """One case of the study (pure: the same inputs give the same numbers).

    Parameters
    ----------
    world, noise, seed :
        :func:`slamrel.simulation.worlds.make_world`.
    method : {"full", "m1", "m2", "toro"}
    pair_start : {"truth", "odometry", "align"}
        Where the pose-only pair least squares starts (the paper: truth).
    min_common : int
        Method 2's ``k``.
    toro_iterations : int
    toro_rules : {"papers", "toro"}
        :func:`~slamrel.backends.toro_optimiser.toro_optimize`'s ``rules``. The default
        here is the papers' update, which the cases stored before ``toro_rules`` existed
        (keyed without it) were computed with; :func:`study_tasks` asks for TORO's own.
    details : bool
        Also return per-pose errors and standard deviations (for the Fig. 1 analogue).

    Returns
    -------
    dict
        ``nees1``, ``gate1``; the paper's ``nees2`` (χ² of the relative-pose constraints
        the method optimised, at its estimate: the odometry for full LS, the pose graph
        for the others; :func:`~slamrel.backends.pose_only.relative_pose_chi2`) and
        ``nees3`` (χ² of all odometry and observations, landmarks fitted to the fixed
        poses; :func:`~slamrel.backends.pose_only.data_chi2`) with ``dof2``, ``dof3`` —
        neither uses ground truth; ``landmark_nees``, ``landmark_gate`` (the estimated
        map's NEES against the *true* landmarks: slamrel's, not the paper's), ``rmse_xy``,
        ``rmse_theta``, ``seconds``, ``poses``, ``constraints`` (and ``errors``, ``sigma``
        with ``details``).
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    w = make_world(world, noise=noise, seed=seed)
    log = LandmarkLog.from_world(w)
    n = len(w.truth)
    t0 = time.perf_counter()
    constraints = 0
    if method == "full":
        g, ids = full_graph(log)
        sol = solve_graph(g)
        poses = np.asarray(sol.poses)
        cov = joint_covariance(g, sol, poses=np.arange(n), landmarks=np.arange(ids.size))
        pose_cov = cov[3:, 3:][: 3 * (n - 1), : 3 * (n - 1)]
        lm, lm_cov = np.asarray(sol.landmarks), cov[3 * n :, 3 * n :]
        constraints = int(g.pp_i.size + g.pl_k.size)
        relative = odometry_graph(log)
    else:
        po = pose_only_least_squares(
            log,
            method=1 if method == "m1" else 2,
            min_common=min_common,
            start=pair_start,  # type: ignore[arg-type]
            truth=w.truth,
        )
        graph, solution = po.graph, po.solution
        constraints = int(graph.pp_i.size)
        relative = po.graph
        if method == "toro":
            tree = toro_optimize(graph, iterations=toro_iterations, rules=toro_rules)  # type: ignore[arg-type]
            graph = PoseGraph(
                tree.poses,
                np.empty((0, 2)),
                graph.pp_i,
                graph.pp_j,
                graph.pp_z,
                spherical_information(graph.pp_info),
            )
            solution = type(solution)(
                poses=tree.poses,
                landmarks=np.empty((0, 2)),
                cost=tree.cost,
                iterations=tree.iterations,
                converged=True,
                linear_solver="none (TORO: stochastic gradient descent)",
                faster_solver=None,
            )
        poses = np.asarray(solution.poses)
        full_cov = joint_covariance(graph, solution)
        pose_cov = full_cov[3:, 3:]
        lm, lm_cov, ids = landmarks_given_poses(log, poses, full_cov)
    seconds = time.perf_counter() - t0
    t1 = nees1(poses, w.truth.poses, pose_cov)
    t2 = nees2(lm, w.landmarks[ids], lm_cov)
    c2 = relative_pose_chi2(relative, poses)
    c3 = data_chi2(log, poses)
    e = _errors(poses, w.truth.poses)
    out: dict[str, Any] = {
        "world": world,
        "noise": noise,
        "seed": int(seed),
        "method": method,
        "poses": n,
        "constraints": constraints,
        "nees1": t1.value,
        "gate1": t1.gate,
        "nees2": c2.value,
        "dof2": c2.dof,
        "nees3": c3.value,
        "dof3": c3.dof,
        "landmark_nees": t2.value,
        "landmark_gate": t2.gate,
        "rmse_xy": float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
        "rmse_theta": float(np.sqrt(np.mean(e[:, 2] ** 2))),
        "seconds": seconds,
    }
    if details:
        var = np.concatenate(([0.0, 0.0, 0.0], np.diag(pose_cov))).reshape(n, 3)
        out["errors"] = e.tolist()
        out["sigma"] = np.sqrt(np.maximum(var, 0.0)).tolist()
    return out


def study_tasks(
    worlds: Sequence[str],
    noises: Sequence[str],
    runs: int,
    methods: Sequence[str] = METHODS,
    *,
    pair_start: str = "truth",
    min_common: int = 5,
    toro_iterations: int = 100,
    toro_rules: str = "toro",
) -> list[Task]:
    """The sweep's tasks, in table order; run 0 of each world/noise keeps per-pose details.
    ``toro_rules`` is in the TORO tasks' keys only when it is not ``"papers"``, so that the
    cases stored before it existed are found again with ``"papers"``."""
    tasks = []
    for world in worlds:
        for noise in noises:
            for seed in range(runs):
                for method in methods:
                    kwargs: dict[str, Any] = {
                        "world": world,
                        "noise": noise,
                        "seed": seed,
                        "method": method,
                        "pair_start": pair_start,
                        "min_common": min_common,
                        "details": seed == 0,
                    }
                    if method == "toro":
                        kwargs["toro_iterations"] = toro_iterations
                        if toro_rules != "papers":
                            kwargs["toro_rules"] = toro_rules
                    tasks.append(
                        Task(
                            f"{world}_{noise}_{seed:04d}_{method}",
                            "slamrel.studies.pose_only:run_case",
                            kwargs,
                        )
                    )
    return tasks


COLUMNS = (
    ("world", "world"),
    ("noise", "noise"),
    ("method", "method"),
    ("runs", "runs"),
    ("nees1_mean", "NEES1 mean"),
    ("nees1_ci", "NEES1 ±95%"),
    ("gate1", "NEES1 gate"),
    ("nees1_under", "runs under gate"),
    ("nees2_mean", "NEES2 mean"),
    ("nees2_ci", "NEES2 ±95%"),
    ("dof2", "NEES2 dof"),
    ("nees3_mean", "NEES3 mean"),
    ("nees3_ci", "NEES3 ±95%"),
    ("dof3", "NEES3 dof"),
    ("landmark_nees_mean", "landmark NEES vs truth"),
    ("landmark_gate", "landmark gate"),
    ("landmark_under", "landmark runs under gate"),
    ("rmse_xy", "RMS position error [m]"),
    ("rmse_xy_ci", "RMS position ±95%"),
    ("rmse_theta", "RMS heading error [rad]"),
    ("seconds", "time [s]"),
)
"""Table columns (key, header). ``±95%``: half-width of the 95 % Student-t interval of the
mean over the runs (0 for one run: no interval)."""

RUN_METRICS = ("nees1", "nees2", "nees3", "landmark_nees", "rmse_xy", "rmse_theta")
"""Per-run values kept in each summary row (``row["per_run"][metric]``, by seed) for the
paired comparisons of :func:`findings`."""


def interval_half_width(values: ArrayLike, level: float = 0.95) -> float:
    """Half-width of the Student-t interval of the mean, ``t_{(1+level)/2, n−1} s / √n``
    (``s`` with ``n − 1``); 0 for fewer than 2 values."""
    from scipy.stats import t as student_t

    v = np.asarray(values, dtype=np.float64)
    if v.size < 2:
        return 0.0
    return float(student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))


def summary_rows(results: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (world, noise, method), in the order first met (Tables II/III analogue)."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in results:
        res = r["result"] if "result" in r else r
        groups.setdefault((res["world"], res["noise"], res["method"]), []).append(res)
    rows = []
    for (world, noise, method), rs in groups.items():
        col = {m: np.array([r[m] for r in rs], dtype=np.float64) for m in RUN_METRICS}
        rows.append(
            {
                "world": world,
                "noise": noise,
                "method": METHOD_NAMES.get(method, method),
                "runs": len(rs),
                "nees1_mean": float(col["nees1"].mean()),
                "nees1_ci": interval_half_width(col["nees1"]),
                "gate1": float(rs[0]["gate1"]),
                "nees1_under": int(np.sum(col["nees1"] <= rs[0]["gate1"])),
                "nees2_mean": float(col["nees2"].mean()),
                "nees2_ci": interval_half_width(col["nees2"]),
                "dof2": float(np.mean([r["dof2"] for r in rs])),
                "nees3_mean": float(col["nees3"].mean()),
                "nees3_ci": interval_half_width(col["nees3"]),
                "dof3": float(np.mean([r["dof3"] for r in rs])),
                "landmark_nees_mean": float(col["landmark_nees"].mean()),
                "landmark_gate": float(np.mean([r["landmark_gate"] for r in rs])),
                "landmark_under": int(sum(r["landmark_nees"] <= r["landmark_gate"] for r in rs)),
                "rmse_xy": float(col["rmse_xy"].mean()),
                "rmse_xy_ci": interval_half_width(col["rmse_xy"]),
                "rmse_theta": float(col["rmse_theta"].mean()),
                "seconds": float(np.mean([r["seconds"] for r in rs])),
                "per_run": {
                    m: dict(zip((int(r["seed"]) for r in rs), col[m].tolist())) for m in RUN_METRICS
                },
            }
        )
    return rows


def _fmt(key: str, v: Any) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, int):
        return str(v)
    if key.startswith("rmse"):
        return f"{v:.3f}"
    if key.startswith("dof"):
        return f"{v:.0f}"
    if key == "seconds":
        return f"{v:.2f}"
    return f"{v:.1f}"


def write_tables(
    directory: str | Path, rows: Sequence[dict[str, Any]], *, timing: bool = False
) -> list[Path]:
    """``table.md``, ``table.csv``, ``table.tex`` (atomic writes); time column with ``timing``.

    Without ``timing`` the tables depend only on the cases' inputs, so a resumed study gives
    the same files byte for byte as an uninterrupted one.
    """
    cols = [c for c in COLUMNS if timing or c[0] != "seconds"]
    out = Path(directory)
    cells = [[_fmt(k, row[k]) for k, _ in cols] for row in rows]
    md = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join(c) + " |" for c in cells]
    buf = io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow([k for k, _ in cols])
    wr.writerows(cells)

    def tex(s: str) -> str:
        return s.replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")

    lines = [
        r"\begin{tabular}{" + "l" * 3 + "r" * (len(cols) - 3) + "}",
        r"\hline",
        " & ".join(tex(h) for _, h in cols) + r" \\",
        r"\hline",
    ]
    lines += [" & ".join(tex(c) for c in row) + r" \\" for row in cells]
    lines += [r"\hline", r"\end{tabular}"]
    paths = [out / "table.md", out / "table.csv", out / "table.tex"]
    for p, text in zip(paths, ("\n".join(md) + "\n", buf.getvalue(), "\n".join(lines) + "\n")):
        write_text_atomic(p, text)
    return paths


def write_figures(directory: str | Path, results: Sequence[dict[str, Any]]) -> list[Path]:
    """Fig. 1 analogue (errors and ±2σ of M1 vs M2, run 0) and Fig. 2 (NEES1 of every run)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slamrel.formats.text import write_bytes_atomic
    from slamrel.report.html import figure_png

    res = [r["result"] if "result" in r else r for r in results]
    out = Path(directory)
    paths = []
    detailed = [r for r in res if "errors" in r and r["method"] in ("m1", "m2")]
    if detailed:
        first = (detailed[0]["world"], detailed[0]["noise"])
        pair = [r for r in detailed if (r["world"], r["noise"]) == first]
        fig, axes = plt.subplots(3, len(pair), figsize=(5 * len(pair), 7), squeeze=False)
        for c, r in enumerate(sorted(pair, key=lambda r: r["method"])):
            e, s = np.asarray(r["errors"]), np.asarray(r["sigma"])
            for k, label in enumerate(("x [m]", "y [m]", "θ [rad]")):
                ax = axes[k, c]
                ax.plot(e[:, k], lw=1, label="error")
                ax.plot(2 * s[:, k], "r--", lw=0.8, label="±2σ")
                ax.plot(-2 * s[:, k], "r--", lw=0.8)
                ax.set_ylabel(label)
            axes[0, c].set_title(f"{METHOD_NAMES[r['method']]} — {first[0]} / noise {first[1]}")
            axes[-1, c].set_xlabel("pose")
        axes[0, 0].legend(loc="upper left")
        fig.tight_layout()
        paths.append(out / "fig1_sigma_bounds.png")
        write_bytes_atomic(paths[-1], figure_png(fig, dpi=90))
    cases = sorted({(r["world"], r["noise"]) for r in res})
    if cases:
        fig, axes = plt.subplots(1, len(cases), figsize=(3.2 * len(cases), 3.5), squeeze=False)
        methods = [m for m in METHODS if any(r["method"] == m for r in res)]
        for c, case in enumerate(cases):
            ax = axes[0, c]
            sel = [r for r in res if (r["world"], r["noise"]) == case]
            for k, m in enumerate(methods):
                v = [r["nees1"] for r in sel if r["method"] == m]
                ax.scatter(np.full(len(v), k), v, s=10)
            ax.axhline(sel[0]["gate1"], color="r", ls="--", lw=0.8)
            ax.set_yscale("log")
            ax.set_xticks(range(len(methods)), methods)
            ax.set_title(f"{case[0]} / {case[1]}", fontsize=9)
        axes[0, 0].set_ylabel("NEES1 (gate dashed)")
        fig.tight_layout()
        paths.append(out / "fig2_nees1.png")
        write_bytes_atomic(paths[-1], figure_png(fig, dpi=90))
    return paths


Verdict = bool | None
"""A finding holds (True), does not hold (False) or is not decided by the runs (None)."""


def _paired(
    a: dict[str, Any], b: dict[str, Any], metric: str, factor: float = 1.0
) -> tuple[Verdict, str]:
    """Whether ``a[metric] < factor · b[metric]``, judged on the paired per-run differences
    ``d = factor · b − a`` (same seeds): True when the 95 % interval of their mean is above
    0, False when below, None when it contains 0 (or with fewer than 2 common runs)."""
    ra, rb = a["per_run"][metric], b["per_run"][metric]
    seeds = sorted(set(ra) & set(rb))
    d = np.array([factor * rb[k] - ra[k] for k in seeds])
    if d.size < 2:
        return None, f"{d.size} paired run(s)"
    mean, half = float(d.mean()), interval_half_width(d)
    verdict: Verdict = True if mean - half > 0 else False if mean + half < 0 else None
    return verdict, f"paired difference {mean:.3g} ± {half:.2g} over {d.size} runs"


#: summary rows by (world, noise), then by method name
_Groups = dict[tuple[str, str], dict[str, dict[str, Any]]]


def findings(rows: Sequence[dict[str, Any]]) -> list[tuple[str, Verdict, str]]:
    """The paper's qualitative findings checked on :func:`summary_rows`.

    A comparison between two methods is judged per world/noise group on the paired per-run
    differences (same seeds) with a 95 % Student-t interval: it *holds* in a group when the
    interval is on the finding's side of 0, *fails* when it is on the other side, and is
    *undecided* when it contains 0 — one run's noise never decides a finding.

    Returns
    -------
    list of (finding, verdict, evidence)
        Only findings whose methods are in ``rows``. ``verdict``: True when it holds in
        every group, False when it fails in some group, None otherwise.
    """
    by: _Groups = {}
    for r in rows:
        by.setdefault((r["world"], r["noise"]), {})[r["method"]] = r
    full, m1, m2, toro = (METHOD_NAMES[m] for m in METHODS)
    out: list[tuple[str, Verdict, str]] = []

    def compare(title: str, lo: str, hi: str, metric: str, show: Any, factor: float = 1.0) -> None:
        groups = {k: v for k, v in by.items() if lo in v and hi in v}
        if not groups:
            return
        verdicts, ev = [], []
        for (w, n), v in groups.items():
            verdict, how = _paired(v[lo], v[hi], metric, factor)
            verdicts.append(verdict)
            word = {True: "holds", False: "fails", None: "undecided"}[verdict]
            ev.append(f"{w}/{n}: {show(v)} ({word}: {how})")
        verdict, head = _combine(verdicts)
        out.append((title, verdict, f"{head}. " + "; ".join(ev)))

    out.extend(_gate_finding(by, full, m2))
    compare(
        "pose-only M2 is far more accurate than M1 (RMS position error at most half)",
        m2,
        m1,
        "rmse_xy",
        lambda v: f"M1 {_ci(v[m1], 'rmse_xy', '.3f')} m, M2 {_ci(v[m2], 'rmse_xy', '.3f')} m",
        factor=0.5,
    )
    compare(
        "TORO is less consistent than pose-only LS (higher NEES1)",
        m2,
        toro,
        "nees1",
        lambda v: f"M2 {_ci(v[m2], 'nees1', '.0f')}, TORO {_ci(v[toro], 'nees1', '.0f')}",
    )
    for metric, label in (("nees2", "NEES2"), ("nees3", "NEES3")):
        compare(
            f"{label} orders full LS below pose-only M2",
            full,
            m2,
            metric,
            lambda v, k=metric: f"full {_ci(v[full], k, '.0f')}, M2 {_ci(v[m2], k, '.0f')}",
        )
        compare(
            f"{label} orders pose-only M2 below TORO",
            m2,
            toro,
            metric,
            lambda v, k=metric: f"M2 {_ci(v[m2], k, '.0f')}, TORO {_ci(v[toro], k, '.0f')}",
        )
    out.extend(_noise_c_finding(by, toro))
    return out


def _combine(verdicts: list[Verdict]) -> tuple[Verdict, str]:
    """One verdict from the groups': fails if it fails in one, undecided if undecided in one."""
    n_fail = sum(v is False for v in verdicts)
    n_open = sum(v is None for v in verdicts)
    if n_fail:
        return False, f"fails in {n_fail}/{len(verdicts)} groups"
    if n_open:
        return None, f"undecided in {n_open}/{len(verdicts)} groups"
    return True, "holds in all groups"


def _ci(r: dict[str, Any], metric: str, fmt: str) -> str:
    """``mean ± half-width`` of a summary row's metric."""
    mean = r[metric + "_mean"] if metric + "_mean" in r else r[metric]
    return f"{mean:{fmt}} ± {r[metric + '_ci']:.2g}"


def _gate_finding(by: _Groups, full: str, m2: str) -> list[tuple[str, Verdict, str]]:
    """Full LS and pose-only M2 pass the NEES1 gate in more than half the runs of every group
    that has both (none without such a group)."""

    def under(r: dict[str, Any]) -> str:
        return f"{r['nees1_under']}/{r['runs']}"

    groups = {k: v for k, v in by.items() if full in v and m2 in v}
    if not groups:
        return []
    failing = [
        k
        for k, v in groups.items()
        if not all(2 * v[m]["nees1_under"] > v[m]["runs"] for m in (full, m2))
    ]
    gate_ev = "; ".join(
        f"{w}/{n}: full {under(v[full])}, M2 {under(v[m2])}" for (w, n), v in groups.items()
    )
    head = f"fails in {len(failing)}/{len(groups)} groups" if failing else "holds in all groups"
    return [
        (
            "full LS and pose-only M2 pass the NEES1 gate in most runs",
            not failing,
            f"{head}. {gate_ev}",
        )
    ]


def _noise_c_finding(by: _Groups, toro: str) -> list[tuple[str, Verdict, str]]:
    """TORO's mean NEES1 over its gate is highest under noise c in every world (none unless
    every world has TORO under noise c); means only, no interval."""
    worlds = sorted({w for w, _ in by})
    if not (all((w, "c") in by and toro in by[(w, "c")] for w in worlds) and worlds):
        return []

    def ratio(w: str, n: str) -> float:
        r = by[(w, n)][toro]
        return float(r["nees1_mean"] / r["gate1"])

    noises = sorted({n for _, n in by})
    bad = [w for w in worlds if max(noises, key=lambda n: ratio(w, n)) != "c"]
    ev = "; ".join(f"{w}: " + ", ".join(f"{n} {ratio(w, n):.2f}" for n in noises) for w in worlds)
    return [
        (
            "TORO is least consistent under noise c (mean NEES1 / gate; means only)",
            not bad,
            ("holds for every world. " if not bad else f"fails for {', '.join(bad)}. ") + ev,
        )
    ]


def write_findings(directory: str | Path, rows: Sequence[dict[str, Any]]) -> Path:
    """``findings.md``: each finding, whether it holds, and the numbers behind it."""
    lines = [
        "# Hu et al.'s findings, checked on this study",
        "",
        "Comparisons between methods are judged per world/noise group on the paired per-run "
        "differences (same seeds), with 95 % Student-t intervals: *undecided* when the "
        "interval contains no difference.",
        "",
    ]
    for title, verdict, ev in findings(rows):
        word = {True: "holds", False: "does not hold", None: "undecided"}[verdict]
        lines += [f"- **{word}** — {title}.", f"  {ev}", ""]
    path = Path(directory) / "findings.md"
    write_text_atomic(path, "\n".join(lines))
    return path
