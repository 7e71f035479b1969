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
* **NEES excursions** — runs of at least :data:`MIN_EXCURSION` consecutive steps with NEES
  above the 95 % band (:func:`nees_excursions`, no merging of runs): green none, amber
  covering < 10 % of the steps, red ≥ 10 %. Not the recovery's NEES *blow-ups* of the
  map–log section (:class:`recovery.recover.NeesBlowup`: beyond the 99.99 % single-pose
  bound for at least ``max_outlier_run`` poses, merged across shorter gaps): an excursion
  says the covariance is somewhat optimistic, a blow-up that the estimate is lost;
* **map edge error** — mean absolute edge-length error of the Delaunay mesh over the
  association cut-off ``c``: green ``≤ 0.1 c``, amber ``≤ 0.3 c``, red above;
* **map OSPA** — OSPA over ``c``: green ``≤ 0.25 c``, amber ``≤ 0.5 c``, red above;
* **gated / robust fractions** of the recovery's measurements: green ``≤ 1 %``, amber
  ``≤ 5 %``, red above (a large gated fraction is a finding about the map).

The overall level is the worst of the lines; "how sure" states the evidence (relations,
poses, matched landmarks). The verdict judges typed results (:class:`RunFacts`, read from a
:class:`slamrel.pipeline.RunResult`), the same the tables and ``metrics.json`` are written from.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.consistency import NeesSummary, flag_runs

if TYPE_CHECKING:
    from recovery.recover import RecoveryCounts
    from slamrel.pipeline import MapSummary, RunResult

__all__ = [
    "Judgement",
    "Verdict",
    "RunFacts",
    "run_verdict",
    "nees_excursions",
    "MIN_EXCURSION",
    "LEVELS",
]

LEVELS = ("green", "amber", "red")
#: Shortest run of consecutive steps above the 95 % NEES band that counts as an excursion.
MIN_EXCURSION = 3


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


@dataclass(frozen=True)
class RunFacts:
    """What the verdict judges: typed parts of a run's results (:meth:`of`).

    Attributes
    ----------
    main : str
        The main estimate (``recovered``, else ``online``, else ``dead_reckoning``).
    translation_errors : mapping of str → float
        Per estimate, the mean absolute translation relation error over all relation sets [m].
    relations : int
        Relations the main estimate was scored on (associated: unassociated ones are not).
    nees : NeesSummary or None
        The main estimate's NEES summary (3 dof), when it has covariances.
    nees_values : ndarray, shape (steps,), or None
        Its per-step NEES (for the excursions).
    map : MapSummary or None
        The landmark-map comparison, when the bundle has the true landmarks.
    counts : RecoveryCounts or None
        The recovery's measurement counts (``None`` when no recovery ran).
    poses : int or None
        Poses of the recovered trajectory.
    unassociated : int or None
        Relations generated for the main estimate that could not be scored (no pose near an
        end); ``None``: not known.
    """

    main: str
    translation_errors: Mapping[str, float]
    relations: int
    nees: NeesSummary | None = None
    nees_values: NDArray[np.float64] | None = None
    map: MapSummary | None = None
    counts: RecoveryCounts | None = None
    poses: int | None = None
    unassociated: int | None = None

    @classmethod
    def of(cls, result: RunResult) -> RunFacts:
        main = result.main_estimate
        rec = result.recovery_result
        curve = result.nees.get(main)
        scored = result.evaluations[main]["all"]
        return cls(
            main=main,
            translation_errors={
                k: evs["all"].translation["abs"].mean for k, evs in result.evaluations.items()
            },
            relations=int(scored.valid.sum()),
            nees=None if curve is None else curve.summary,
            nees_values=None if curve is None else curve.values,
            map=result.map_summary,
            counts=None if rec is None else rec.counts,
            poses=None if rec is None else len(rec.trajectory),
            unassociated=int((~scored.valid).sum()),
        )


def nees_excursions(nees: ArrayLike, high: float, *, min_length: int = MIN_EXCURSION) -> list[int]:
    """Lengths of the runs of ≥ ``min_length`` consecutive values above ``high`` (no merging)."""
    st, en = flag_runs(np.asarray(nees, dtype=np.float64) > high, min_length)
    return (en - st + 1).tolist()


def run_verdict(facts: RunFacts) -> Verdict:
    """The verdict of a run from its typed results (:meth:`RunFacts.of` a ``RunResult``)."""
    lines = [
        *_accuracy_lines(facts),
        *_consistency_lines(facts),
        *(_map_lines(facts.map) if facts.map is not None else []),
        *(_measurement_lines(facts.counts) if facts.counts is not None else []),
    ]
    level = max((ln.level for ln in lines), key=LEVELS.index, default="amber")
    return Verdict(level, _evidence(facts), lines)


def _accuracy_lines(facts: RunFacts) -> list[Judgement]:
    """The main estimate against dead reckoning, and the online estimate against it."""
    lines = []
    main, err = facts.main, facts.translation_errors
    ours = err.get(main)
    dr = err.get("dead_reckoning") if main != "dead_reckoning" else None
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
    online = err.get("online") if main != "online" else None
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


def _consistency_lines(facts: RunFacts) -> list[Judgement]:
    """NEES inside the band, and excursions above it, of the main estimate."""
    n, main = facts.nees, facts.main
    if n is None:
        return []
    lines = [
        Judgement(
            f"consistency ({main})",
            f"NEES mean {_g(n.mean)} (dof {n.dof}), {100 * n.inside:.0f} % of steps "
            f"inside [{_g(n.band[0])}, {_g(n.band[1])}]",
            "green" if n.inside >= 0.9 else "amber" if n.inside >= 0.75 else "red",
            "fraction of steps inside the 95 % χ² band; green ≥ 90 %, amber ≥ 75 %, red below",
        )
    ]
    if facts.nees_values is not None:
        v = np.asarray(facts.nees_values, dtype=np.float64)
        runs = nees_excursions(v, float(n.band[1]))
        cover = sum(runs) / v.size if v.size else 0.0
        lines.append(
            Judgement(
                "NEES excursions",
                f"{len(runs)} (longest {max(runs, default=0)} steps, "
                f"{100 * cover:.0f} % of {v.size})",
                "green" if not runs else "amber" if cover < 0.1 else "red",
                f"runs of ≥ {MIN_EXCURSION} steps with NEES above the 95 % band; green none, "
                "amber < 10 % of the steps, red ≥ 10 %",
            )
        )
    return lines


def _map_lines(m: MapSummary) -> list[Judgement]:
    """Map edge error and OSPA, each over the association cut-off ``c``."""
    c, edge = m.cutoff, m.edge.mean
    return [
        Judgement(
            "map edge error",
            f"{_g(edge)} m (c = {_g(c)} m)",
            _level(edge / c, 0.1, 0.3),
            "mean abs edge-length error of the Delaunay mesh; green ≤ 0.1 c, amber ≤ 0.3 c",
        ),
        Judgement(
            "map OSPA",
            f"{_g(m.ospa)} m (c = {_g(c)} m)",
            _level(m.ospa / c, 0.25, 0.5),
            "OSPA of the whole maps; green ≤ 0.25 c, amber ≤ 0.5 c, red above",
        ),
    ]


def _measurement_lines(counts: RecoveryCounts) -> list[Judgement]:
    """The recovery's down-weighted and gated fractions of the measurements."""
    return [
        Judgement(
            f"{what} measurements",
            f"{100 * x:.1f} %",
            _level(x, 0.01, 0.05),
            "fraction of the recovery's measurements; green ≤ 1 %, amber ≤ 5 %, red above",
        )
        for what, x in (
            ("downweighted", counts.downweighted_fraction),
            ("gated", counts.gated_fraction),
        )
    ]


def _evidence(facts: RunFacts) -> str:
    """The evidence sentence: relations (scored, and unassociated when known), poses and
    matched landmarks counted."""
    evidence = [f"{facts.relations} relations"]
    if facts.unassociated is not None:
        evidence[0] = f"{facts.relations} scored relations" + (
            f" ({facts.unassociated} more generated but unassociated, not scored)"
            if facts.unassociated
            else " (all generated relations associated)"
        )
    if facts.poses:
        evidence.append(f"{facts.poses} poses")
    m = facts.map
    if m is not None:
        evidence.append(f"{m.matched} matched landmarks ({m.missed} missed, {m.spurious} spurious)")
    return "Based on " + ", ".join(evidence) + "."
