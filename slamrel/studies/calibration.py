"""Is the verdict right? Its calibration on runs whose truth is known.

Every lamp of the verdict (:mod:`slamrel.report.verdict`) judges a quantity against what
correct models produce. This study checks that on two kinds of run:

* **healthy by construction** (:func:`slamrel.simulation.healthy.healthy_bundle`): the log of
  a simulated world with its exact noise models and true associations, a map whose error is
  drawn from exactly the covariance the bundle states (joint, or per-landmark marginals only);
  every lamp should be green;
* **broken** (:data:`FAULTS`), the same bundles with one fault each: wrong associations
  (1 % and 5 % of the measurements given another landmark in view), the stated noise
  mis-scaled (standard deviations × 0.1 and × 10, the log unchanged), a corrupted map (its
  error three times what the covariance states); a consistency, map–log or map lamp should
  be red.

Each case is a pure task of the resumable sweep (:mod:`slamrel.studies.sweep`): its result is
the verdict's levels per lamp and the raw quantities they judged (JSON), so a study runs in a
pool of processes or on Dask and resumes after an interruption. :func:`calibration_summary`
gives the rates the acceptance asks for: all-green per healthy run and per lamp, red per
broken run and per fault.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from slamrel.report.verdict import LEVELS
from slamrel.studies.sweep import Task

__all__ = [
    "FAULTS",
    "HEALTHY",
    "REFERENCE",
    "TEXTBOOK",
    "RED_LAMPS",
    "CalibrationSummary",
    "broken_bundle",
    "calibration_case",
    "calibration_summary",
    "calibration_tasks",
    "class_rates",
    "judged_case",
    "reference_case",
    "write_calibration",
]

#: The faults of the broken runs: name → (kind, parameter).
FAULTS: dict[str, tuple[str, float]] = {
    "associations-1%": ("associations", 0.01),
    "associations-5%": ("associations", 0.05),
    "noise-x0.1": ("noise", 0.1),
    "noise-x10": ("noise", 10.0),
    "map-x3": ("map", 3.0),
}

#: The lamps (verdict line ``key``) one of which must be red on a broken run.
RED_LAMPS = ("consistency", "excursions", "map_log", "map_consistency", "measurements")

#: The classes of healthy runs whose verdict rates are reported one by one: healthy by
#: construction (:func:`calibration_case`), the reference EKF-SLAM's own runs
#: (:func:`reference_case`) and an independent textbook EKF-SLAM's (run outside the package:
#: ``benchmarks/client_verdicts.py``, the test).
HEALTHY = "healthy by construction"
REFERENCE = "reference EKF-SLAM healthy"
TEXTBOOK = "textbook EKF-SLAM healthy"

_FAULT_STREAM = 0xFA_0024
#: Seconds either side of a measurement within which another measured landmark is "in view".
IN_VIEW = 1.0


def broken_bundle(bundle: Bundle, fault: str, *, seed: int = 0) -> Bundle:
    """``bundle`` with one of the :data:`FAULTS` (``"map-x3"`` is drawn by the generator:
    :func:`calibration_case` passes ``error_scale``; here it returns the bundle unchanged).

    ``associations-f``: a seeded fraction ``f`` of the associated measurements is given
    another landmark in view (:func:`_wrong_associations`). (Confusing a landmark with its
    nearest neighbour, often closer than the sensor noise in these dense worlds, is invisible
    to every statistic and harmless: measured, docs/verdict.md; not counted as broken.)
    ``noise-xs``: the stated standard deviations of the sensor and of the motion model are
    multiplied by ``s``; the log is not changed.
    """
    kind, value = FAULTS[fault]
    if kind == "associations":
        return _wrong_associations(bundle, value, np.random.default_rng([_FAULT_STREAM, seed]))
    if kind == "noise":
        return _scaled_noise(bundle, value)
    return bundle


def _wrong_associations(bundle: Bundle, fraction: float, rng: np.random.Generator) -> Bundle:
    """A seeded ``fraction`` of the associated measurements given another landmark *in view*:
    one the log measured within :data:`IN_VIEW` seconds of it (the confusion a data
    association makes between landmarks in one scan), chosen at random; a measurement with
    no other landmark in view keeps its own."""
    t = bundle.measurement_times
    lm = bundle.measurement_landmarks.copy()
    assoc = np.flatnonzero(bundle.measurement_associated)
    pick = np.sort(rng.choice(assoc, int(round(fraction * assoc.size)), replace=False))
    lo = np.searchsorted(t, t[pick] - IN_VIEW, side="left")
    hi = np.searchsorted(t, t[pick] + IN_VIEW, side="right")
    draws = rng.random(pick.size)
    for k, (i, a, b) in enumerate(zip(pick, lo, hi)):  # ≤ a few hundred picks
        window = bundle.measurement_landmarks[a:b][bundle.measurement_associated[a:b]]
        others = np.unique(window[window != bundle.measurement_landmarks[i]])
        if others.size:
            lm[i] = others[int(draws[k] * others.size)]
    return replace(bundle, measurement_landmarks=lm)


def _scaled_noise(bundle: Bundle, scale: float) -> Bundle:
    m, s = bundle.motion, bundle.sensor
    motion = MotionModel(
        m.type,
        sigma=None if m.sigma is None else tuple(scale * v for v in m.sigma),
        alpha=None if m.alpha is None else tuple(scale * v for v in m.alpha),
        integration=m.integration,
        control_stamp=m.control_stamp,
        pose_noise_frame=m.pose_noise_frame,
        pose_noise=None
        if m.pose_noise is None
        else tuple(tuple(scale**2 * v for v in row) for row in m.pose_noise),
    )
    sensor = SensorModel(scale * s.sigma_range, scale * s.sigma_bearing, s.type)
    return replace(bundle, motion=motion, sensor=sensor)


def calibration_case(
    world: str, noise: str, seed: int, form: str, fault: str = "none"
) -> dict[str, Any]:
    """One case of the study (a sweep task): build the run, score it, judge it.

    Returns the JSON ``{"levels": {lamp: level}, "values": {lamp: number}, "overall": level}``
    of :func:`slamrel.report.verdict.run_verdict` on the run's result.
    """
    from slamrel.pipeline import RunInput, score_bundle
    from slamrel.simulation.healthy import healthy_bundle

    scale = FAULTS[fault][1] if fault != "none" and FAULTS[fault][0] == "map" else 1.0
    bundle = healthy_bundle(world, seed, form, noise=noise, odometry=None, error_scale=scale)
    if fault != "none":
        bundle = broken_bundle(bundle, fault, seed=seed)
    name = f"{world}/{noise}/{seed}/{form}/{fault}"
    result = score_bundle(RunInput(bundle, name=name), clock_search=False)  # levels only
    return judged_case(result, HEALTHY if fault == "none" else f"broken: {fault}")


def reference_case(world: str, noise: str, seed: int) -> dict[str, Any]:
    """One run of the reference EKF-SLAM (``slamrel run WORLD --noise N --seed S``), judged:
    the same JSON as :func:`calibration_case`. No expectation: an EKF-SLAM can be genuinely
    inconsistent, and the study reports what its lamps say."""
    from slamrel.pipeline import run_pipeline

    return judged_case(run_pipeline(world, noise=noise, seed=seed, clock_search=False), REFERENCE)


def judged_case(result: Any, kind: str) -> dict[str, Any]:
    """The JSON of a case of the class ``kind``: the verdict's overall level, and its levels and
    measures by lamp (a case of a class run elsewhere, e.g. ``benchmarks/client_verdicts.py``
    for :data:`TEXTBOOK`, is judged by this too)."""
    from slamrel.report.verdict import RunFacts, run_verdict

    verdict = run_verdict(RunFacts.of(result))
    return {
        "class": kind,
        "overall": verdict.level,
        "levels": {ln.key: ln.level for ln in verdict.lines},
        "values": {ln.key: ln.measure for ln in verdict.lines},
    }


def calibration_tasks(
    worlds: Sequence[str],
    noises: Sequence[str],
    seeds: Sequence[int],
    forms: Sequence[str] = ("joint", "marginal"),
    faults: Sequence[str] = tuple(FAULTS),
    *,
    broken_seeds: Sequence[int] | None = None,
) -> list[Task]:
    """The study's sweep: healthy runs for every world × noise × seed × form, broken runs
    for every world × noise × broken seed (default: ``seeds``) × form × fault, and the
    reference EKF-SLAM's own runs (:func:`reference_case`) for every world × noise × seed."""
    bs = seeds if broken_seeds is None else broken_seeds
    reference = [
        Task(
            f"ref-{w}-{n}-{sd}",
            "slamrel.studies.calibration:reference_case",
            {"world": w, "noise": n, "seed": sd},
        )
        for w, n, sd in itertools.product(worlds, noises, seeds)
    ]
    cases = [(w, n, s, f, "none") for w, n, s, f in itertools.product(worlds, noises, seeds, forms)]
    cases += list(itertools.product(worlds, noises, bs, forms, faults))
    return [
        Task(
            f"cal-{w}-{n}-{s}-{f}-{x.replace('%', 'pc')}",
            "slamrel.studies.calibration:calibration_case",
            {"world": w, "noise": n, "seed": s, "form": f, "fault": x},
        )
        for w, n, s, f, x in cases
    ] + reference


@dataclass(frozen=True)
class CalibrationSummary:
    """The rates of a calibration study.

    Attributes
    ----------
    healthy_runs : int
    healthy_all_green : float
        Fraction of the healthy runs whose every lamp is green.
    healthy_green_by_lamp : dict of str → float
        Per lamp, the fraction of the healthy runs (that have the lamp) where it is green.
    broken_runs : dict of str → int
        Per fault, its runs.
    broken_red : dict of str → float
        Per fault, the fraction of its runs with a red lamp among :data:`RED_LAMPS`.
    red_by_lamp : dict of str → dict of str → float
        Per fault, per lamp, the fraction of its runs where that lamp is red.
    reference_runs : int
        Runs of the reference EKF-SLAM.
    reference_levels : dict of str → dict of str → float
        Per lamp, the fraction of those runs at each level (no expectation: what it is).
    reference_q : dict of str → list of float
        Per NEES-type lamp (``consistency``, ``online_consistency``, ``map_log``,
        ``map_consistency``), its ``q`` over the reference runs.
    classes : dict of str → dict of str → int
        Per class of run (:func:`class_rates`), its runs and how many were green, amber, red.
    """

    healthy_runs: int
    healthy_all_green: float
    healthy_green_by_lamp: dict[str, float]
    broken_runs: dict[str, int]
    broken_red: dict[str, float]
    red_by_lamp: dict[str, dict[str, float]]
    reference_runs: int = 0
    reference_levels: dict[str, dict[str, float]] = field(default_factory=dict)
    reference_q: dict[str, list[float]] = field(default_factory=dict)
    classes: dict[str, dict[str, int]] = field(default_factory=dict)

    def lines(self) -> list[str]:
        """The summary as text, one line per rate."""
        out = [
            f"class {k}: {c['runs']} runs, green {c['green']}, amber {c['amber']}, red {c['red']}"
            for k, c in self.classes.items()
        ]
        out += [
            f"healthy: {self.healthy_runs} runs, all green {100 * self.healthy_all_green:.0f} %"
            " (green per lamp: "
            + ", ".join(f"{k} {100 * v:.0f} %" for k, v in self.healthy_green_by_lamp.items())
            + ")"
        ]
        for fault, n in self.broken_runs.items():
            lamps = ", ".join(
                f"{k} {100 * v:.0f} %" for k, v in self.red_by_lamp[fault].items() if v > 0
            )
            out.append(
                f"{fault}: {n} runs, red {100 * self.broken_red[fault]:.0f} % ({lamps or 'none'})"
            )
        if self.reference_runs:
            parts = []
            for lamp, lv in self.reference_levels.items():
                shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in lv.items() if v > 0)
                q = self.reference_q.get(lamp)
                rng = f"; q {min(q):.2f}–{max(q):.2f}" if q else ""
                parts.append(f"{lamp} ({shares}{rng})")
            out.append(
                f"reference EKF-SLAM: {self.reference_runs} runs, judged as they are: "
                + "; ".join(parts)
            )
        return out


def calibration_summary(records: Sequence[dict[str, Any]]) -> CalibrationSummary:
    """The rates of the study from its stored records (:func:`slamrel.studies.sweep.
    load_results`: each has the task's ``kwargs`` and its ``result``)."""
    refs = [r["result"] for r in records if r["function"].endswith(":reference_case")]
    records = [r for r in records if not r["function"].endswith(":reference_case")]
    cases = [(r["kwargs"]["fault"], r["result"]) for r in records]
    healthy = [r for f, r in cases if f == "none"]
    lamps = list(dict.fromkeys(k for r in healthy for k in r["levels"] if r["levels"][k] != "info"))
    by_lamp = {
        k: float(np.mean([r["levels"][k] == "green" for r in healthy if k in r["levels"]]))
        for k in lamps
    }
    faults = list(dict.fromkeys(f for f, _ in cases if f != "none"))
    runs, red, red_lamp = {}, {}, {}
    for fault in faults:
        rs = [r for f, r in cases if f == fault]
        runs[fault] = len(rs)
        red[fault] = float(
            np.mean([any(r["levels"].get(k) == "red" for k in RED_LAMPS) for r in rs])
        )
        names = list(dict.fromkeys(k for r in rs for k in r["levels"]))
        red_lamp[fault] = {
            k: float(np.mean([r["levels"].get(k) == "red" for r in rs])) for k in names
        }
    classes = class_rates([*(r for _, r in cases), *refs])
    return CalibrationSummary(
        classes=classes,
        healthy_runs=len(healthy),
        healthy_all_green=float(np.mean([r["overall"] == "green" for r in healthy]))
        if healthy
        else float("nan"),
        healthy_green_by_lamp=by_lamp,
        broken_runs=runs,
        broken_red=red,
        red_by_lamp=red_lamp,
        reference_runs=len(refs),
        reference_levels={
            k: {lv: float(np.mean([r["levels"].get(k) == lv for r in refs])) for lv in LEVELS}
            for k in dict.fromkeys(k for r in refs for k in r["levels"])
            if any(r["levels"].get(k) in LEVELS for r in refs)
        },
        reference_q={
            k: [float(r["values"][k]) for r in refs if k in r["values"]]
            for k in ("consistency", "online_consistency", "map_log", "map_consistency")
            if any(k in r["values"] for r in refs)
        },
    )


def class_rates(results: Sequence[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Per class of run (a result's ``class``; broken runs of every fault as one class
    ``broken``), its runs and the counts of its overall levels."""
    out: dict[str, dict[str, int]] = {}
    for r in results:
        kind = str(r.get("class", "?"))
        kind = "broken" if kind.startswith("broken") else kind
        c = out.setdefault(kind, {"runs": 0, **dict.fromkeys(LEVELS, 0)})
        c["runs"] += 1
        c[r["overall"]] = c.get(r["overall"], 0) + 1
    return out


def write_calibration(directory: Any, summary: CalibrationSummary) -> list[Any]:
    """``calibration.md`` (the rates as text) and ``calibration.json`` in ``directory``,
    each written atomically; returns their paths."""
    import json
    from dataclasses import asdict
    from pathlib import Path

    from slamrel.formats.text import write_text_atomic

    out = Path(directory)
    md = out / "calibration.md"
    js = out / "calibration.json"
    write_text_atomic(
        md,
        "# Verdict calibration\n\n"
        "Healthy: every lamp should be green; broken: a lamp among "
        + ", ".join(RED_LAMPS)
        + " should be red (slamrel.studies.calibration).\n\n"
        + "".join(f"- {line}\n" for line in summary.lines()),
    )
    write_text_atomic(js, json.dumps(asdict(summary), indent=2, sort_keys=True) + "\n")
    return [md, js]
