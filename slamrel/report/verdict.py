"""The verdict that opens a ``slamrel run`` report: how good the run is, and how sure we are.

Each line is a :class:`Judgement`: a quantity, its value, a green/amber/red level and the
rule that gave the level, written next to it on the page. The rules (thresholds are
deliberately simple and stated, not tuned):

* **recovered vs dead reckoning** — ratio ``r`` of the mean absolute translation relation
  errors [m]: green ``r ≤ 0.5`` (at least twice as accurate as odometry alone), amber
  ``r ≤ 1``, red ``r > 1`` (worse than dead reckoning);
* **online vs recovered** (when both exist) — ratio of the same errors: green within a
  factor 2, amber within a factor 4, red beyond (the recovery does not reproduce the run);
* **consistency** — fraction of steps whose NEES lies inside the 95 % χ² band: green
  ``≥ 0.90``, amber ``≥ 0.75``, red below;
* **inconsistent stretches** — runs of at least :data:`MIN_STRETCH` consecutive steps with
  NEES above the band: green none, amber covering < 10 % of the steps, red ≥ 10 %;
* **map edge error** — mean absolute edge-length error of the Delaunay mesh over the
  association cut-off ``c``: green ``≤ 0.1 c``, amber ``≤ 0.3 c``, red above;
* **map OSPA** — OSPA over ``c``: green ``≤ 0.25 c``, amber ``≤ 0.5 c``, red above;
* **gated / robust fractions** of the recovery's measurements: green ``≤ 1 %``, amber
  ``≤ 5 %``, red above (a large gated fraction is a finding about the map).

The overall level is the worst of the lines; "how sure" states the evidence (relations,
poses, matched landmarks).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["Judgement", "Verdict", "run_verdict", "MIN_STRETCH", "LEVELS"]

LEVELS = ("green", "amber", "red")
#: Shortest run of consecutive steps above the NEES band that counts as a stretch.
MIN_STRETCH = 3


@dataclass(frozen=True)
class Judgement:
    """One line of the verdict: ``what`` is ``value`` → ``level`` by ``rule``."""

    what: str
    value: str
    level: str  # one of LEVELS
    rule: str


@dataclass(frozen=True)
class Verdict:
    """The overall level (worst line), the evidence sentence and the lines."""

    level: str
    evidence: str
    lines: Sequence[Judgement]


def _g(x: float) -> str:
    """A number with 3 significant digits, never a numpy repr."""
    return f"{float(x):.3g}"


def _level(x: float, green: float, amber: float) -> str:
    """green when ``x ≤ green``, amber when ``x ≤ amber``, else red."""
    return "green" if x <= green else "amber" if x <= amber else "red"


def _translation(metrics: Mapping[str, Any], key: str) -> float | None:
    part = metrics.get(key)
    if not isinstance(part, Mapping):
        return None
    return float(part["translation"]["abs"]["mean"])


def stretches(nees: ArrayLike, high: float, *, min_length: int = MIN_STRETCH) -> list[int]:
    """Lengths of the runs of ≥ ``min_length`` consecutive values above ``high``."""
    above = np.asarray(nees, dtype=np.float64) > high
    edges = np.diff(np.r_[0, above.astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    lengths = ends - starts
    return lengths[lengths >= min_length].tolist()


def run_verdict(
    metrics: Mapping[str, Any], nees_curves: Mapping[str, ArrayLike] | None = None
) -> Verdict:
    """The verdict of a run from its ``metrics.json`` structure (and per-step NEES curves).

    Parameters
    ----------
    metrics : mapping
        :meth:`slamrel.pipeline.RunResult.metrics`.
    nees_curves : mapping of name → ndarray, shape (steps,), optional
        Per-step NEES of each estimate (for the inconsistent stretches).
    """
    main = str(metrics.get("trajectory_source", "recovered"))
    mp = metrics.get("map")
    lines = [
        *_accuracy_lines(metrics, main),
        *_consistency_lines(metrics.get("nees") or {}, main, nees_curves or {}),
        *(_map_lines(mp) if isinstance(mp, Mapping) else []),
        *_measurement_lines((metrics.get("recovery") or {}).get("measurements") or {}),
    ]
    level = max((ln.level for ln in lines), key=LEVELS.index, default="amber")
    return Verdict(level, _evidence(metrics), lines)


def _accuracy_lines(metrics: Mapping[str, Any], main: str) -> list[Judgement]:
    """The main estimate against dead reckoning, and the online estimate against it."""
    lines = []
    ours = _translation(metrics, "trajectory")
    dr = _translation(metrics, "dead_reckoning")
    if ours is not None and dr is not None and dr > 0:
        r = ours / dr
        lines.append(
            Judgement(
                f"{main} vs dead reckoning",
                f"{_g(ours)} m / {_g(dr)} m = {_g(r)}",
                _level(r, 0.5, 1.0),
                "ratio of the mean abs relation errors in translation; "
                "green ≤ 0.5, amber ≤ 1, red > 1",
            )
        )
    online = _translation(metrics, "online") if main != "online" else None
    if online is not None and ours is not None and ours > 0:
        r = online / ours
        spread = max(r, 1.0 / r) if r > 0 else float("inf")
        lines.append(
            Judgement(
                f"online vs {main}",
                f"{_g(online)} m / {_g(ours)} m = {_g(r)}",
                _level(spread, 2.0, 4.0),
                "ratio of the same errors; green within a factor 2, amber within 4, red beyond",
            )
        )
    return lines


def _consistency_lines(
    nees: Mapping[str, Any], main: str, nees_curves: Mapping[str, ArrayLike]
) -> list[Judgement]:
    """NEES inside the band, and stretches above it, of the main estimate."""
    if main not in nees:
        return []
    n = nees[main]
    inside = float(n["inside"])
    lines = [
        Judgement(
            f"consistency ({main})",
            f"NEES mean {_g(n['mean'])} (dof {n['dof']}), {100 * inside:.0f} % of steps "
            f"inside [{_g(n['band'][0])}, {_g(n['band'][1])}]",
            "green" if inside >= 0.9 else "amber" if inside >= 0.75 else "red",
            "fraction of steps inside the 95 % χ² band; green ≥ 90 %, amber ≥ 75 %, red below",
        )
    ]
    curve = nees_curves.get(main)
    if curve is not None:
        v = np.asarray(curve, dtype=np.float64)
        runs = stretches(v, float(n["band"][1]))
        cover = sum(runs) / v.size if v.size else 0.0
        lines.append(
            Judgement(
                "inconsistent stretches",
                f"{len(runs)} (longest {max(runs, default=0)} steps, "
                f"{100 * cover:.0f} % of {v.size})",
                "green" if not runs else "amber" if cover < 0.1 else "red",
                f"runs of ≥ {MIN_STRETCH} steps with NEES above the band; green none, "
                "amber < 10 % of the steps, red ≥ 10 %",
            )
        )
    return lines


def _map_lines(mp: Mapping[str, Any]) -> list[Judgement]:
    """Map edge error and OSPA, each over the association cut-off ``c``."""
    c = float(mp["ospa"]["c"])
    edge = float(mp["translation"]["abs"]["mean"])
    ospa = float(mp["ospa"]["value"])
    return [
        Judgement(
            "map edge error",
            f"{_g(edge)} m (c = {_g(c)} m)",
            _level(edge / c, 0.1, 0.3),
            "mean abs edge-length error of the Delaunay mesh; green ≤ 0.1 c, amber ≤ 0.3 c",
        ),
        Judgement(
            "map OSPA",
            f"{_g(ospa)} m (c = {_g(c)} m)",
            _level(ospa / c, 0.25, 0.5),
            "OSPA of the whole maps; green ≤ 0.25 c, amber ≤ 0.5 c, red above",
        ),
    ]


def _measurement_lines(meas: Mapping[str, Any]) -> list[Judgement]:
    """The recovery's gated / down-weighted fractions of the measurements."""
    return [
        Judgement(
            key.replace("_fraction", "") + " measurements",
            f"{100 * float(meas[key]):.1f} %",
            _level(float(meas[key]), 0.01, 0.05),
            "fraction of the recovery's measurements; green ≤ 1 %, amber ≤ 5 %, red above",
        )
        for key in sorted(k for k in meas if k.endswith("_fraction"))
    ]


def _evidence(metrics: Mapping[str, Any]) -> str:
    """The evidence sentence: relations, poses and matched landmarks counted."""
    evidence = [f"{(metrics.get('trajectory') or {}).get('relations', 0)} relations"]
    poses = (metrics.get("recovery") or {}).get("poses")
    if poses:
        evidence.append(f"{poses} poses")
    mp = metrics.get("map")
    if isinstance(mp, Mapping):
        a = mp["association"]
        evidence.append(
            f"{a['matched']} matched landmarks ({a['missed']} missed, {a['spurious']} spurious)"
        )
    return "Based on " + ", ".join(evidence) + "."
