"""``slamrel simulate`` -> ``slamrel slam`` -> ``slamrel evaluate`` on bundles."""

from __future__ import annotations

import json

import numpy as np

from slamrel.cli import main
from slamrel.formats.bundle import read_bundle


def test_simulate_slam_evaluate(tmp_path):
    sim, slam = tmp_path / "sim", tmp_path / "slam"
    assert main(["simulate", "simple1", "--noise", "a", "--seed", "2", "-o", str(sim), "-q"]) == 0
    b = read_bundle(sim)
    assert b.motion.type == "odometry" and b.groundtruth is not None
    np.testing.assert_array_equal(b.map_xy, b.landmarks_groundtruth[1])  # perfect map
    assert main(["slam", str(sim), "-o", str(slam), "--store-online", "-q"]) == 0
    s = read_bundle(slam)
    assert s.map_covariance is not None and s.map_covariance.shape == (2 * s.map_ids.size,) * 2
    assert s.measurement_associated.all()
    # the SLAM map is close to the truth, and the online estimate beats dead reckoning
    true = dict(zip(b.map_ids.tolist(), b.map_xy))
    err = np.hypot(*(s.map_xy - np.array([true[i] for i in s.map_ids.tolist()])).T)
    assert np.median(err) < 0.5
    out = tmp_path / "e.json"
    assert (
        main(
            [
                "evaluate",
                str(slam),
                str(slam / "online.csv"),
                "--strategy",
                "global",
                "--json",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    online = json.loads(out.read_text())["translation"]["abs"]["mean"]
    assert (
        main(
            [
                "evaluate",
                str(slam),
                str(sim / "odometry.csv"),
                "--format",
                "csv",
                "--strategy",
                "global",
                "--json",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    dead = json.loads(out.read_text())["translation"]["abs"]["mean"]
    assert online < 0.5 * dead
    assert main(["slam", str(sim), "-o", str(sim)]) == 3  # never over the input
