"""The bundle recorder (slamrel.formats.recorder): what a running filter reports is what the
reader reads back, and the worked example of docs/bundle.md runs and recovers its truth.

Oracles: the textbook client's own arrays (its controls, readings, associations, map and
online estimate, kept by the client apart from the recorder), and hand-computed poses.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from clients.export import recorder_for, write_recorded_bundle
from clients.textbook_ekfslam import Config, run

from relation_metric.errors import InputError
from slamrel.formats.bundle import read_bundle, read_online

ROOT = Path(__file__).resolve().parents[1]
QUIRKS = dict(mount=(0.3, 0.1, math.radians(5.0)), motion_noise="control",
              initial_variance=0.0, dropout=0.005)  # fmt: skip


def test_recorded_bundle_reads_back_as_the_client_ran(tmp_path: Path) -> None:
    cfg = Config(steps=120, **QUIRKS)  # type: ignore[arg-type]
    rec = recorder_for(cfg)
    r = run(0, cfg, recorder=rec)
    root = write_recorded_bundle(r, rec, tmp_path / "b")
    with pytest.raises(InputError, match="skip_invalid_measurements=True"):
        read_bundle(root)
    with pytest.warns(UserWarning):
        b = read_bundle(root, skip_invalid_measurements=True)
    # the controls as the client drew them (row 0 opens the log), the stated step covariance
    assert np.array_equal(b.controls, np.column_stack((r.times, r.controls)))
    assert b.step_covariances is not None
    assert np.array_equal(b.step_covariances[1:], np.repeat(cfg.step_covariance()[None], 120, 0))
    # the readings the filter used, with its associations; the dropouts skipped and counted
    zero = np.loadtxt(root / "measurements.csv", delimiter=",", skiprows=1, usecols=1) == 0.0
    assert b.skipped_invalid == int(zero.sum()) > 0
    assert np.array_equal(b.measurement_times, r.meas_t)
    assert np.array_equal(b.measurements[:, 0], r.meas_z[:, 0])
    turn = np.angle(np.exp(1j * (b.measurements[:, 1] - r.meas_z[:, 1])))  # bearings wrapped
    assert np.abs(turn).max() < 1e-12
    assert np.array_equal(b.measurement_landmarks[b.measurement_associated],
                          r.meas_assoc[r.meas_assoc >= 0])  # fmt: skip
    # the map and its joint covariance; the zero start; the mount; the online estimate
    xy, marg, joint = r.client_map()
    assert np.array_equal(b.map_xy, xy) and np.array_equal(b.map_covariance, joint)
    assert np.array_equal(b.map_marginals, marg)
    assert not b.initial_covariance.any() and b.sensor.mount == cfg.mount
    with pytest.warns(UserWarning, match="zero or singular"):
        on = read_online(root / "online.csv")
    assert np.array_equal(on.trajectory.poses, r.online)
    assert on.covariances is not None and not on.covariances[0].any()


def _docs_example() -> str:
    text = (ROOT / "docs" / "bundle.md").read_text()
    block = text.split("### Recording a bundle from a running filter")[1]
    return re.search(r"```python\n(.*?)```", block, re.S).group(1)  # type: ignore[union-attr]


def test_docs_worked_example_runs_and_recovers_its_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The example's robot drives 50 steps of 0.1 m straight ahead with noise-free readings
    of a sensor 20 cm ahead: its last pose is [5, 0, 0] (by hand)."""
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(_docs_example(), "docs/bundle.md", "exec"), {})
    finally:
        os.chdir(cwd)
    last = np.array(capsys.readouterr().out.strip(" []\n").split(), dtype=float)
    assert np.allclose(last, [5.0, 0.0, 0.0], atol=1e-9)
    b = read_bundle(tmp_path / "my-run")
    assert b.sensor.mount == (0.2, 0.0, 0.0) and not b.initial_covariance.any()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recorded_quirky_client_recovers_better_than_online(seed: int, tmp_path: Path) -> None:
    """Issue 38's acceptance on the textbook client with its values as written (a zero
    initial covariance, zero and singular online covariances, range-0 dropouts, a per-step
    control covariance, a sensor mount): accepted with counted warnings, and the recovered
    error on 2,000 global relations of the truth is at most the client's online error.

    Measured (seeds 0, 1, 2): recovered / online 0.954, 0.868, 0.869; recovered / true-map
    floor 1.377, 1.514, 1.382 — above issue 23's 1.3 (the client's map holds 35-42 landmarks
    for 12 true ones; the same bundle with the equivalent sigma model recovers the same).
    """
    from clients.export import online, true_map_bundle
    from clients.measure import scorer

    from recovery.recover import recover
    from slamrel.cli import main

    cfg = Config(**QUIRKS)  # type: ignore[arg-type]
    rec = recorder_for(cfg)
    r = run(seed, cfg, recorder=rec)
    root = write_recorded_bundle(r, rec, tmp_path / "b")
    with pytest.warns(UserWarning) as caught:
        b = read_bundle(root, skip_invalid_measurements=True)
    assert any("skipped_invalid" in str(w.message) for w in caught) and b.skipped_invalid > 0
    score = scorer(r)
    recovered = score(recover(b).trajectory)
    assert recovered <= score(online(r))
    assert score(recover(true_map_bundle(b, r), map_mode="ignore").trajectory) < recovered
    if seed == 0:  # `run` reports with and without ground truth
        argv = ["run", str(root), "-q", "--skip-invalid-measurements", "-o"]
        assert main([*argv, str(tmp_path / "with")]) == 0
        for f in ("groundtruth.csv", "landmarks_groundtruth.csv"):
            (root / f).unlink()
        assert main([*argv, str(tmp_path / "without")]) == 0
        assert (tmp_path / "without" / "report.html").is_file()
