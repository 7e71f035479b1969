"""The measurements' clock offset (recovery.clock_offset) and the verdict's cause sentence.

Oracles: logs whose measurement stamps were moved by a known offset (the offset comes back
with its sign, and the verdict names it); the same logs unmoved (nothing to name, the lamp
green); broken runs whose map–log lamp is red for another reason (an offset that only nudges
the NIS is not named); MRCLAM robot 2 with its raw odometry, 0.25 s late against the ground
truth by the importer's own calibration (slow, real data).
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import require_data

from recovery.clock_offset import TRIM, clock_offset, trimmed_nis
from slamrel.pipeline import RunInput, score_bundle
from slamrel.report.verdict import RunFacts, run_verdict
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world

SETTINGS = {"robust": "redescending", "max_outlier_run": 10}


def _log(world: str, noise: str, seed: int, shift: float):
    """A velocity-driven world's log (true map), every measurement stamped ``shift`` late."""
    b = world_bundle(make_world(world, noise=noise, seed=seed, rate=5))
    return replace(b, measurement_times=b.measurement_times + shift)


def test_trimmed_mean_of_chi2_2_is_its_closed_form(rng):
    """``E[min(χ²₂, b)] = 2 (1 − e^{−b/2})`` against 10⁶ draws."""
    v = rng.chisquare(2, 1_000_000)
    assert trimmed_nis(v).mean() == pytest.approx(2 * (1 - np.exp(-TRIM / 2)), abs=0.006)
    assert TRIM == pytest.approx(-2 * np.log(1e-3))


@pytest.mark.parametrize(
    ("world", "seed", "shift"),
    [
        ("simple1", 0, 0.3),
        ("simple1", 2, -0.2),
        pytest.param("complex1", 1, 0.3, marks=pytest.mark.slow),
        pytest.param("complex1", 0, -0.2, marks=pytest.mark.slow),
    ],
)
def test_a_known_offset_comes_back_with_its_sign(world, seed, shift):
    """Stamped ``shift`` late, the log agrees best restamped by about ``−shift``, and the
    restamped NIS are what the unmoved log gives."""
    c = clock_offset(_log(world, "a", seed, shift), **SETTINGS)
    assert c is not None
    assert c.offset == pytest.approx(-shift, abs=0.05)
    assert c.significant and c.explained > 0.03
    unmoved = clock_offset(_log(world, "a", seed, 0.0), **SETTINGS)
    assert unmoved is not None
    # restamped by −shift the log is (to the search's resolution) the unmoved one
    assert c.trimmed_at_offset == pytest.approx(unmoved.trimmed, rel=0.01)
    assert c.tail > c.tail_at_offset


def test_the_verdict_names_the_offset_only_where_the_map_log_lamp_shows_it():
    """Moved 0.3 s: the map–log lamp is red and its cause is a clock offset of about −0.3 s
    that makes it greener; unmoved: green, and no search was made."""
    moved = score_bundle(RunInput(_log("simple1", "a", 0, 0.3), name="moved"))
    line = next(ln for ln in run_verdict(RunFacts.of(moved)).lines if ln.key == "map_log")
    assert line.level == "red"
    said = re.search(r"clock offset: .* restamped by ([-+.\d]+) s", line.value)
    assert said is not None and float(said[1]) == pytest.approx(-0.3, abs=0.05)
    assert "heavy tails" not in line.value  # the tail is the offset's
    assert moved.clock_offset is not None
    unmoved = score_bundle(RunInput(_log("simple1", "a", 0, 0.0), name="unmoved"))
    line = next(ln for ln in run_verdict(RunFacts.of(unmoved)).lines if ln.key == "map_log")
    assert line.level == "green" and unmoved.clock_offset is None


@pytest.mark.parametrize(
    "fault", ["noise-x0.1", pytest.param("associations-5%", marks=pytest.mark.slow)]
)
def test_an_offset_that_leaves_a_broken_lamp_as_it_is_is_not_named(fault):
    """A filter told 10× too little noise, or 5 % wrong associations: the search finds some
    offset that lowers the NIS a little (noise × 0.1: by 6 %), the lamp stays red, and the
    cause is not called a clock offset."""
    from slamrel.simulation.healthy import healthy_bundle
    from slamrel.studies.calibration import broken_bundle

    b = broken_bundle(healthy_bundle("simple1", 0, "joint", noise="a", odometry=None), fault)
    result = score_bundle(RunInput(b, name=fault))
    assert result.clock_offset is not None  # searched: the lamp is red
    line = next(ln for ln in run_verdict(RunFacts.of(result)).lines if ln.key == "map_log")
    assert line.level == "red" and "clock offset" not in line.value


@pytest.mark.slow
def test_mrclam_raw_odometry_is_a_quarter_second_late():
    """Robot 2 of dataset 7 imported with its raw odometry (``--no-calibrate``): the importer's
    calibration against the Vicon truth finds the odometry 0.25 s late; the NIS alone find
    the measurements fit it restamped by about −0.25 s, and the verdict says so. The default
    import (calibrated) has no offset to name."""
    from slamrel.importers.mrclam import calibrate_odometry, mrclam_bundle, read_mrclam_robot

    d = require_data("mrclam", "MRCLAM_Dataset7")
    delay = calibrate_odometry(read_mrclam_robot(d, 2)).delay
    raw = score_bundle(RunInput(mrclam_bundle(d, 2, calibrate=False), name="raw"))
    assert raw.clock_offset is not None
    assert raw.clock_offset.offset == pytest.approx(-delay, abs=0.03)
    line = next(ln for ln in run_verdict(RunFacts.of(raw)).lines if ln.key == "map_log")
    assert "clock offset" in line.value
    calibrated = score_bundle(RunInput(mrclam_bundle(d, 2), name="calibrated"))
    c = calibrated.clock_offset
    assert c is None or abs(c.offset) < 0.06
    line = next(ln for ln in run_verdict(RunFacts.of(calibrated)).lines if ln.key == "map_log")
    assert "clock offset" not in line.value


def test_the_module_examples_hold():
    """The docstring example (the trim at the 99.9 % bound, NaN kept) as written."""
    import doctest

    import recovery.clock_offset

    result = doctest.testmod(recovery.clock_offset)
    assert result.attempted > 0 and result.failed == 0
