"""Score a client's run: its online estimate, every recovery, and the true-map floor.

The error of an estimate is the mean translational error on 2,000 global relations of the
ground truth (``generate_relations(groundtruth, "global", count=2000, seed=0)``,
``evaluate(...).translation.abs.mean``), in metres.

The floor is localisation in the true map: the bundle with ``map.csv`` replaced by the true
landmarks (exact, no covariance), each association mapped to the true landmark of the
client's landmark (:func:`clients.export.true_map_bundle`), recovered with the default
method and ``map_mode="ignore"``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from clients.export import (
    groundtruth,
    online,
    true_map_bundle,
    velocity_bundle,
    write_odometry_bundle,
    write_recorded_bundle,
    write_velocity_euler_bundle,
)
from clients.textbook_ekfslam import Run
from recovery.bundle import Bundle
from recovery.recover import recover
from relation_metric.errors import InputError
from relation_metric.evaluate import evaluate
from relation_metric.relations import generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.formats.bundle import read_bundle, write_bundle

METHODS = ("filter", "smoother", "batch")
MAP_MODES = ("joint", "marginal", "ignore")
DEFAULT = "smoother/joint"
#: issue 23's acceptance: default ≤ online and ≤ FLOOR_FACTOR × floor
FLOOR_FACTOR = 1.3
COLUMNS = ("online", *(f"{m}/{mm}" for m in METHODS for mm in MAP_MODES), "floor")


def velocity_euler_supported(bundle: Bundle) -> bool:
    """Did the reader understand the client's own motion model (branch wt-motion)?"""
    return getattr(bundle.motion, "integration", None) == "euler"


def export(run: Run, directory: Path, exporter: str = "auto") -> tuple[Bundle, str]:
    """Write the run as a bundle and read it back; returns the bundle and the exporter used.

    ``exporter``: ``"odometry"`` (the fallback), ``"velocity"`` (today's velocity model,
    stamps converted), ``"velocity-lag"`` (the client's stamps written as they are),
    ``"velocity-euler"`` (the client's own model, wt-motion keys), ``"recorded"`` (what the
    client reported to its :class:`~slamrel.formats.recorder.BundleRecorder`, its values as
    written; invalid readings skipped and counted), or ``"auto"``: the client's own model when
    the reader understands it, else the odometry fallback.
    """
    root = Path(directory)
    if exporter == "recorded":  # what the client reported to its BundleRecorder as it ran
        if run.recorder is None:
            raise ValueError("the run has no recorder: run(..., recorder=recorder_for(cfg))")
        path = write_recorded_bundle(run, run.recorder, root / "recorded")
        return read_bundle(path, skip_invalid_measurements=True), exporter
    if exporter in ("auto", "velocity-euler"):
        path = write_velocity_euler_bundle(run, root / "velocity-euler")
        try:
            bundle = read_bundle(path)
        except InputError:
            if exporter == "velocity-euler":
                raise
        else:
            if velocity_euler_supported(bundle) or exporter == "velocity-euler":
                return bundle, "velocity-euler"
        exporter = "odometry"
    if exporter == "odometry":
        return read_bundle(write_odometry_bundle(run, root / "odometry")), exporter
    if exporter in ("velocity", "velocity-lag"):
        write_bundle(root / exporter, velocity_bundle(run, shift=exporter == "velocity"))
        return read_bundle(root / exporter), exporter
    raise ValueError(f"unknown exporter {exporter!r}")


def scorer(run: Run) -> Callable[[Trajectory], float]:
    relations = generate_relations(groundtruth(run), "global", count=2000, seed=0)

    def score(estimate: Trajectory) -> float:
        return float(evaluate(relations, estimate).translation.abs.mean)

    return score


def measure(
    run: Run,
    directory: Path,
    *,
    exporter: str = "auto",
    columns: Sequence[str] = COLUMNS,
) -> dict[str, object]:
    """Errors [m] of ``columns`` for one run, its association statistics and the exporter."""
    bundle, used = export(run, directory, exporter)
    score = scorer(run)
    out: dict[str, object] = {"exporter": used}
    for col in columns:
        if col == "online":
            out[col] = score(online(run))
        elif col == "floor":
            out[col] = score(recover(true_map_bundle(bundle, run), map_mode="ignore").trajectory)
        else:
            method, map_mode = col.split("/")
            out[col] = score(recover(bundle, method=method, map_mode=map_mode).trajectory)
    out.update(run.association_stats())
    return out


def table(rows: dict[int, dict[str, object]], columns: Sequence[str] = COLUMNS) -> str:
    """A plain-text table: one row per seed, errors in metres, then the acceptance ratios."""
    head = ["seed", *columns, "dflt/onl", "dflt/floor", "assoc err", "lm (true)", "NIS", "export"]
    lines = ["  ".join(f"{h:>14}" for h in head)]
    for seed, r in rows.items():
        cells = [f"{seed:>14}"] + [f"{float(r[c]):>14.3f}" for c in columns]  # type: ignore[arg-type]
        d = float(r[DEFAULT])  # type: ignore[arg-type]
        cells += [
            f"{d / float(r['online']):>14.2f}" if "online" in r else f"{'':>14}",  # type: ignore[arg-type]
            f"{d / float(r['floor']):>14.2f}" if "floor" in r else f"{'':>14}",  # type: ignore[arg-type]
            f"{100 * float(r['error_rate']):>13.2f}%",  # type: ignore[arg-type]
            f"{r['client_landmarks']:>9} ({r['true_landmarks_seen']})",
            f"{float(r['mean_nis']):>14.2f}",  # type: ignore[arg-type]
            f"{r['exporter']:>14}",
        ]
        lines.append("  ".join(cells))
    return "\n".join(lines)
