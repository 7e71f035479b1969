"""Issue 25, "nothing lost at the edges": valid but degenerate inputs are scored (or refused
with a clear error before any output), and the work is bounded before memory runs out."""

from __future__ import annotations

import dataclasses
import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import landmark_graph.set_distances as sd
from recovery.bundle import Bundle
from relation_metric.trajectory import Trajectory
from slamrel.cli import main
from slamrel.formats.bundle import write_bundle
from slamrel.simulation.bundles import simulate_bundle


@pytest.fixture(scope="module")
def base() -> Bundle:
    return simulate_bundle(3, steps=120)


def _without_measurements(b: Bundle) -> Bundle:
    return dataclasses.replace(
        b,
        measurement_times=np.zeros(0),
        measurements=np.zeros((0, 2)),
        measurement_landmarks=np.zeros(0, np.int64),
        measurement_associated=np.zeros(0, bool),
        measurement_lines=None,
    )


def _without_landmarks(b: Bundle) -> Bundle:
    return dataclasses.replace(
        _without_measurements(b),
        map_ids=np.zeros(0, np.int64),
        map_xy=np.zeros((0, 2)),
        map_marginals=np.zeros((0, 2, 2)),
    )


def _one_landmark(b: Bundle) -> Bundle:
    keep = b.measurement_landmarks == b.map_ids[0]
    assert b.landmarks_groundtruth is not None
    ids, xy = b.landmarks_groundtruth
    return dataclasses.replace(
        b,
        measurement_times=b.measurement_times[keep],
        measurements=b.measurements[keep],
        measurement_landmarks=b.measurement_landmarks[keep],
        measurement_associated=b.measurement_associated[keep],
        measurement_lines=None,
        map_ids=b.map_ids[:1],
        map_xy=b.map_xy[:1],
        map_marginals=b.map_marginals[:1],
        landmarks_groundtruth=(ids[:1], xy[:1]),
    )


def _recover(folder: Path, tmp: Path) -> tuple[int, dict]:
    rc = main(["recover", str(folder), "-o", str(tmp / "t.txt"), "--report", str(tmp / "r.json"),
               "-q"])  # fmt: skip
    return rc, json.loads((tmp / "r.json").read_text()) if rc == 0 else {}


# ------------------------------------------------------------- nothing observed: dead reckoning


@pytest.mark.parametrize("make", [_without_measurements, _without_landmarks])
def test_nothing_observed_is_scored_as_dead_reckoning(tmp_path, base, make, capsys):
    write_bundle(tmp_path / "b", make(base))
    rc, report = _recover(tmp_path / "b", tmp_path)
    assert rc == 0
    assert report["poses"] == 120 and report["measurements"]["used"] == 0
    assert "dead reckoning" in report["dead_reckoning"]
    assert "no measurements" in report["dead_reckoning"]
    assert main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "t2.txt")]) == 0
    assert "note: nothing was observed" in capsys.readouterr().out
    # the reference EKF-SLAM runs on such a log too
    assert main(["slam", str(tmp_path / "b"), "-o", str(tmp_path / "s"), "-q"]) == 0
    # and run scores it, saying so
    assert main(["run", str(tmp_path / "b"), "-o", str(tmp_path / "r"), "-q"]) == 0
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert any("Nothing was observed" in n for n in metrics["notes"])
    assert metrics["recovery"]["dead_reckoning"] == report["dead_reckoning"]


def test_an_observed_run_has_no_dead_reckoning_key(tmp_path, base):
    write_bundle(tmp_path / "b", base)
    rc, report = _recover(tmp_path / "b", tmp_path)
    assert rc == 0 and "dead_reckoning" not in report


def test_one_landmark_map_says_what_is_not_computed(tmp_path, base):
    write_bundle(tmp_path / "b", _one_landmark(base))
    assert main(["run", str(tmp_path / "b"), "-o", str(tmp_path / "r"), "-q"]) == 0
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    mesh = m["map"]["mesh"]
    assert mesh["triangles"] == 0 and "a triangle needs 3" in mesh["not_computed"]
    assert m["map"]["ospa"]["value"] is not None  # OSPA needs no mesh
    assert any(n.startswith("No mesh triangles") for n in m["notes"])


# --------------------------------------------------------------- ground truth off the log


def _shifted_truth(b: Bundle, dt: float) -> Bundle:
    gt = b.groundtruth
    assert gt is not None
    return dataclasses.replace(b, groundtruth=Trajectory(gt.timestamps + dt, gt.poses))


def test_recover_with_ground_truth_off_the_log_scores_what_it_can(tmp_path, base, capsys):
    write_bundle(tmp_path / "b", _shifted_truth(base, 1000.0))
    rc, report = _recover(tmp_path / "b", tmp_path)
    assert rc == 0
    assert report["nees"] is None and report["nees_truth_frame"] is None  # no NEES
    assert "does not cover the log's start" in report["nees_frame"]["frame"]
    assert main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "t2.txt")]) == 0
    assert "no NEES: no recovered pose after the first lies at a ground-truth time" in (
        capsys.readouterr().out
    )


def test_ground_truth_starting_late_does_not_invent_a_start_frame(tmp_path, base):
    b = dataclasses.replace(_shifted_truth(base, 6.0), initial_pose=np.array([1.0, 2.0, 0.5]))
    write_bundle(tmp_path / "b", b)
    rc, report = _recover(tmp_path / "b", tmp_path)
    assert rc == 0
    assert report["nees_frame"]["anchoring"] is None  # not anchored on a clamped pose
    assert "does not cover the log's start" in report["nees_frame"]["frame"]


def test_run_refuses_ground_truth_off_the_log_before_any_output(tmp_path, base, capsys):
    write_bundle(tmp_path / "b", _shifted_truth(base, -1000.0))
    assert main(["run", str(tmp_path / "b"), "-o", str(tmp_path / "r"), "-q"]) == 3
    err = capsys.readouterr().err
    assert str(tmp_path / "b" / "groundtruth.csv") in err and "do not overlap" in err
    assert not (tmp_path / "r").exists()


# ------------------------------------------------------------------------------- overflow


def test_noise_scale_whose_square_overflows_is_a_usage_error(tmp_path, capsys):
    for cmd in (["run", "simple1"], ["simulate", "simple1"]):
        with pytest.raises(SystemExit) as info:
            main([*cmd, "--noise-scale", "1e300", "-o", str(tmp_path / "x")])
        assert info.value.code == 2
    assert "expected a noise scale in [1e-06, 1e+06]" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("model", "key", "value"),
    [
        ("motion_model", "sigma_v", 1e308),
        ("motion_model", "sigma_omega", 1e200),
        ("sensor_model", "sigma_range", 1e300),
    ],
)
def test_bundle_noise_whose_square_overflows_names_the_field(
    tmp_path, base, capsys, model, key, value
):
    write_bundle(tmp_path / "b", base)
    p = tmp_path / "b" / "bundle.json"
    doc = json.loads(p.read_text())
    doc[model][key] = value
    p.write_text(json.dumps(doc, indent=1))
    assert main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "t.txt"), "-q"]) == 3
    err = capsys.readouterr().err
    assert f"{p}:" in err and f"{model}.{key}" in err and "at most 1e+30" in err
    assert not (tmp_path / "t.txt").exists()


def test_map_compare_cutoff_beyond_float64_is_a_usage_error(tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["map-compare", "a.csv", "b.csv", "--cutoff", "1e300"])
    assert info.value.code == 2


# ------------------------------------------------------------------ damaged study results


SMALL = ["--worlds", "hu-simple1", "--noise", "a", "--methods", "full,m1,m2", "--runs", "1"]


@pytest.mark.slow
def test_study_resumes_over_a_damaged_case_file(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "pose-only", "-o", str(out), "-q", *SMALL]) == 0
    cases = sorted((out / "cases").glob("*.json"))
    assert cases
    good = cases[0].read_text()
    cases[0].write_text(good[: len(good) // 2])  # cut off
    cases[-1].write_text("[1, 2]")  # valid JSON, not a record
    capsys.readouterr()
    assert main(["study", "pose-only", "-o", str(out), *SMALL]) == 0
    cap = capsys.readouterr()
    for c in (cases[0], cases[-1]):
        assert f"recomputed (the stored result was damaged): {c}" in cap.out
        assert f"damaged result {c}" in cap.err
    new, old = json.loads(cases[0].read_text()), json.loads(good)  # recomputed: whole again
    assert new["key"] == old["key"] and new["result"].keys() == old["result"].keys()
    assert new["result"]["constraints"] == old["result"]["constraints"]


def test_load_results_names_a_damaged_file(tmp_path):
    from relation_metric.errors import InputError
    from slamrel.studies.sweep import Task, load_results

    t = Task("x", "math:hypot", {})
    (tmp_path / f"{t.key}.json").write_text("{")
    with pytest.raises(InputError, match="damaged study result: not valid JSON") as info:
        load_results(tmp_path, [t])
    assert str(tmp_path / f"{t.key}.json") in str(info.value)


# ------------------------------------------------------------------------ bounded resources


def test_simulate_refuses_a_rate_beyond_the_row_limit_before_building(tmp_path, capsys):
    """An option mistake (exit 2, like argparse), said in the option's words, before any work;
    the limit itself (rows = rate × measurement steps, simple1 has 84) by hand."""
    assert main(["simulate", "simple1", "--rate", "1000000", "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "argument --rate: 1000000 control steps" in err
    assert "above the limit of 1000000 control rows" in err
    assert f"at most {1_000_000 // 84}" in err
    assert not (tmp_path / "b").exists()
    assert main(["run", "simple1", "--rate", "1000000", "-o", str(tmp_path / "r"), "-q"]) == 2
    assert not (tmp_path / "r").exists()
    # the limit itself is accepted, one more is not
    assert main(["simulate", "simple1", "--rate", "11905", "-o", str(tmp_path / "b")]) == 2
    from relation_metric.errors import InputError
    from slamrel.simulation.worlds import make_world

    with pytest.raises(InputError, match="84000000 control rows"):  # the library's own check
        make_world("simple1", rate=1_000_000)


def test_sparse_ospa_equals_the_dense_assignment():
    rng = np.random.default_rng(7)
    for _ in range(60):
        m, n = rng.integers(0, 50, 2)
        x, y = rng.uniform(0, 10, (m, 2)), rng.uniform(0, 10, (n, 2))
        c, p = float(rng.uniform(0.3, 3.0)), float(rng.choice([1.0, 2.0, 3.0]))
        dense = sd._log_sum_exp(sd._optimal_terms(x, y, c, p)[0])
        xx, yy = (x, y) if m <= n else (y, x)
        sparse = sd._log_sum_exp(sd._within_cutoff_terms(xx, yy, c, p)) if min(m, n) else -np.inf
        assert sparse == pytest.approx(dense, rel=1e-12, abs=1e-12)


def test_ospa_of_any_order_stays_finite():
    """c^p beyond float64 (10^1000) no longer matters: OSPA is computed in units of c. Two
    pairs √2 apart, both within c: OSPA = (mean d^p)^(1/p) = √2 for every p."""
    for p in (1.0, 2.0, 1000.0):
        assert sd.ospa(np.zeros((2, 2)), np.ones((2, 2)), c=10.0, p=p) == pytest.approx(
            np.sqrt(2.0), rel=1e-12
        )


def _map_csv(path: Path, ids: np.ndarray, xy: np.ndarray) -> None:
    rows = "\n".join(f"{i},{x:.6f},{y:.6f}" for i, (x, y) in zip(ids, xy, strict=True))
    path.write_text("landmark,x,y\n" + rows + "\n")


def test_map_compare_on_many_landmarks_stays_small(tmp_path):
    """3,000 against 3,200 landmarks: the dense assignment's distance matrix alone is 77 MB
    (it was 3.2 GB, 9.0 GB peak, at 20,000); the within-c pairs need a few MB."""
    rng = np.random.default_rng(1)
    n = 3200
    ref = rng.uniform(0, 550, (n, 2))
    est = ref[:3000] + rng.normal(0, 0.1, (3000, 2))
    _map_csv(tmp_path / "ref.csv", np.arange(n), ref)
    _map_csv(tmp_path / "est.csv", np.arange(3000), est)
    tracemalloc.start()
    try:
        rc = main(["map-compare", str(tmp_path / "est.csv"), str(tmp_path / "ref.csv"),
                   "--json", str(tmp_path / "m.json"), "-q"])  # fmt: skip
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rc == 0
    assert peak < 60e6, peak
    m = json.loads((tmp_path / "m.json").read_text())
    assert m["association"]["matched"] == 3000
    # 200 unmatched at c² = 1 each and 3000 matched at ~2 σ² = 0.02: OSPA ≈ √(260 / 3200)
    assert m["ospa"]["value"] == pytest.approx(np.sqrt(260 / 3200), rel=0.05)


def test_a_joint_problem_beyond_memory_is_refused_before_any_work(
    monkeypatch: pytest.MonkeyPatch, tmp_path, capsys
) -> None:
    """The smoother's and batch's dense map terms are 4 x (3N x r) doubles: beyond the memory
    budget (half the machine's memory) they are refused with the sizes, before the filter runs,
    instead of the out-of-memory killer ending the process (10^5 steps, 2,000 landmarks: 41 GB);
    the filter needs no such arrays and still runs."""
    import recovery.batch_refinement as rb
    from recovery.recover import recover
    from relation_metric.errors import InputError
    from slamrel.formats.bundle import read_bundle

    bundle_dir = Path(__file__).resolve().parents[1] / "data" / "sim-bundle"
    b = read_bundle(bundle_dir)
    monkeypatch.setattr(rb, "memory_budget", lambda: 1000.0)  # bytes
    with pytest.raises(InputError, match="would need") as info:
        recover(b, method="smoother")
    text = str(info.value)
    m = b.map_xy.shape[0]
    assert f"x {2 * m} map directions" in text and "(method filter)" in text
    n = int(text.split("3 x ")[1].split(" poses")[0])  # the recovery grid's poses
    assert n >= len(b.groundtruth)  # type: ignore[arg-type]
    assert f"need {8 * 4 * 3 * n * 2 * m / 2**30:.1f} GiB" in text  # by hand
    assert recover(b, method="filter").trajectory is not None
    assert main(["recover", str(bundle_dir), "-o", str(tmp_path / "r.txt")]) == 3
    assert "would need" in capsys.readouterr().err and not (tmp_path / "r.txt").exists()
