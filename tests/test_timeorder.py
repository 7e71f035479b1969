"""The one time-order rule (relation_metric.timeorder) through every reader that applies it.

Timed poses (estimate, odometry, reference) are sorted and counted, ``--strict`` refuses;
logs that drive a filter (bundle, MRCLAM) sort steps back up to FILTER_TIME_TOLERANCE and
refuse larger ones with file:line and both times; repeated reference times and zero-length
relations are dropped and counted; a bundle is no estimate.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import require_data
from hypothesis import given, settings
from hypothesis import strategies as st
from test_importers_mrclam import HEAD, make_dataset

from relation_metric.errors import InputError
from relation_metric.timeorder import (
    FILTER_TIME_TOLERANCE,
    TimeOrderWarning,
    first_of_each_time,
    sort_by_time,
    steps_back,
)
from slamrel.cli import main
from slamrel.formats.bundle import write_bundle
from slamrel.formats.trajectories import read_trajectory
from slamrel.importers.mrclam import read_mrclam_robot
from slamrel.simulation.bundles import simulate_bundle

# ------------------------------------------------------------------------------- the rule


@settings(max_examples=150, deadline=None)
@given(st.lists(st.integers(0, 40), min_size=0, max_size=40))
def test_sort_by_time_is_a_stable_sort_and_counts_rows_behind_the_latest(ticks):
    t = np.asarray(ticks, dtype=float) * 0.01
    order, report = sort_by_time(t, lines=lambda k: k + 10)
    # oracle: Python's sorted() is stable; a row is out of order when an earlier row is later
    assert order.tolist() == sorted(range(len(ticks)), key=lambda k: ticks[k])
    late = [k for k in range(len(ticks)) if any(ticks[j] > ticks[k] for j in range(k))]
    assert report.out_of_order == len(late)
    assert report.first_line == (late[0] + 10 if late else None)
    back = max((max(ticks[:k]) - ticks[k] for k in late), default=0) * 0.01
    assert report.max_step_back == pytest.approx(back, abs=1e-12)


def test_tolerance_sorts_small_steps_and_refuses_a_larger_one_with_both_times_and_lines():
    t = np.array([0.0, 0.1, 0.3, 0.27, 0.4, 0.35])  # 0.03 and 0.05 s back: within
    order, report = sort_by_time(t, tolerance=0.05)
    assert order.tolist() == [0, 1, 3, 2, 5, 4]
    assert report.out_of_order == 2 and report.max_step_back == pytest.approx(0.05)
    t[5] = 0.2
    with pytest.raises(InputError) as err:
        sort_by_time(t, tolerance=0.05, lines=[3, 4, 5, 6, 7, 8], path="log.csv", what="control")
    msg = str(err.value)
    assert msg.startswith("log.csv:8: time goes backwards by 0.200000 s: control at")
    assert "t = 0.200000 s after t = 0.400000 s (line 7)" in msg and "np." not in msg


def test_first_of_each_time_keeps_the_first():
    assert first_of_each_time([0, 1, 1, 1, 2, 3, 3]).tolist() == [1, 1, 0, 0, 1, 1, 0]
    assert steps_back([]).shape == (0,)


def test_tolerance_constant_fits_mrclam():
    # 5 odometry periods of MRCLAM (100 Hz), under its median measurement spacing (0.23 s)
    assert FILTER_TIME_TOLERANCE == 0.05


# ------------------------------------------------------------- estimates (timed poses)


def _plain(path: Path, t, poses) -> Path:
    rows = "".join(
        f"{a!r} {x!r} {y!r} {th!r}\n"
        for a, (x, y, th) in zip(np.asarray(t, float).tolist(), np.asarray(poses, float).tolist())
    )
    path.write_text("# t x y theta\n" + rows)
    return path


def _walk(rng, n):
    t = np.arange(n) * 0.5
    th = np.cumsum(rng.normal(0, 0.2, n))
    xy = np.cumsum(np.column_stack((np.cos(th), np.sin(th))) * 0.4, axis=0)
    return t, np.column_stack((xy, th))


def _evaluate(capsys, *args):
    code = main(["evaluate", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_out_of_order_estimate_is_associated_and_counted(tmp_path, capsys, rng):
    t, ref = _walk(rng, 40)
    est = ref + rng.normal(0, 0.02, ref.shape)
    _plain(tmp_path / "ref.txt", t, ref)
    _plain(tmp_path / "ordered.txt", t, est)
    perm = np.arange(40)
    for k in (3, 10, 25):  # three disjoint neighbour swaps: three poses out of order
        perm[[k, k + 1]] = perm[[k + 1, k]]
    _plain(tmp_path / "shuffled.txt", t[perm], est[perm])
    results = {}
    for name in ("ordered", "shuffled"):
        js = tmp_path / f"{name}.json"
        args = (tmp_path / "ref.txt", tmp_path / f"{name}.txt", "--strategy", "consecutive")
        code, out, err = _evaluate(capsys, *args, "--json", js)
        assert code == 0, err
        results[name] = (json.loads(js.read_text()), out, err)
    a, b = results["ordered"][0], results["shuffled"][0]
    assert a["translation"] == b["translation"] and a["rotation"] == b["rotation"]
    assert a["estimate_out_of_order"] == {"count": 0, "max_step_back_s": 0.0, "first_line": None}
    # line 1 is the header, data row k is on line k + 2; the first late pose is row 4
    assert b["estimate_out_of_order"] == {"count": 3, "max_step_back_s": 0.5, "first_line": 6}
    out, err = results["shuffled"][1:]
    assert "estimate: 3 pose(s) out of time order (largest step back 0.500000 s" in out
    assert "shuffled.txt: 3 poses out of time order" in err


def test_strict_refuses_an_out_of_order_estimate(tmp_path, capsys):
    _plain(tmp_path / "ref.txt", [0, 1, 2, 3], [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    _plain(tmp_path / "e.txt", [0, 2, 1, 3], [[0, 0, 0], [2, 0, 0], [1, 0, 0], [3, 0, 0]])
    args = (tmp_path / "ref.txt", tmp_path / "e.txt", "--strategy", "consecutive")
    code, _, err = _evaluate(capsys, *args, "--strict")
    assert code == 3
    assert f"{tmp_path / 'e.txt'}:4: 1 pose out of time order" in err
    assert "--strict refuses" in err
    code, out, _ = _evaluate(capsys, *args)
    assert code == 0 and "0 unassociated" in out
    # a reference trajectory follows the same rule
    args = (tmp_path / "e.txt", tmp_path / "ref.txt", "--strategy", "consecutive")
    code, _, err = _evaluate(capsys, *args, "--strict")
    assert code == 3 and f"{tmp_path / 'e.txt'}:4: 1 pose out of time order" in err
    assert "np." not in err


def _swap_flaser_lines(text: str, rng, keep: set[int]) -> tuple[str, list[int]]:
    """Swap disjoint neighbouring lines (1-based pairs (i, i+1)); lines in keep stay put."""
    lines = text.split("\n")
    n = len(lines) - 1 if text.endswith("\n") else len(lines)
    swapped = []
    i = 1
    while i < n - 1:  # never the last line (cut off in run 08)
        if rng.random() < 0.3 and not ({i, i + 1} & keep):
            lines[i - 1], lines[i] = lines[i], lines[i - 1]
            swapped.append(i)
            i += 2
        else:
            i += 1
    return "\n".join(lines), swapped


@pytest.mark.realdata
def test_run_08_with_locally_shuffled_lines_scores_the_same(tmp_path, rng):
    d = require_data("freiburg")
    original = d / "benchmarks/08/test.log"
    text = original.read_text()
    # line 1018 is a NaN pose stamped 2016 (skipped in metricevaluator mode): keep it alone
    shuffled_text, swapped = _swap_flaser_lines(text, rng, keep={1017, 1018, 1019})
    assert len(swapped) > 200 and shuffled_text != text
    shuffled = tmp_path / "test.log"
    shuffled.write_text(shuffled_text)
    results = {}
    for name, log in (("original", original), ("shuffled", shuffled)):
        for part, w in (("trans", "1,1,0,0,0,0"), ("phi", "0,0,0,0,0,1")):
            out = tmp_path / f"{name}-{part}.json"
            argv = ["evaluate", str(d / "mit-csail.relations"), str(log)]
            argv += ["--odometry", str(d / "mit-csail.clf"), "--mode", "metricevaluator"]
            assert main(argv + ["--weights", w, "--json", str(out), "-q"]) == 0
            results[name, part] = json.loads(out.read_text())
    for part in ("trans", "phi"):
        a, b = results["original", part], results["shuffled", part]
        for key in ("translation", "rotation", "combined", "relations", "unassociated"):
            assert a.get(key) == b.get(key), key
        assert a["estimate_out_of_order"]["count"] == 0
        order = b["estimate_out_of_order"]
        assert order["count"] == len(swapped)  # each swap puts one pose behind its neighbour
        assert order["first_line"] == swapped[0] + 1
    assert results["original", "trans"]["translation"]["abs"]["count"] == 1172


# ----------------------------------------------------------- logs that drive a filter


@pytest.fixture(scope="module")
def bundle_source(tmp_path_factory) -> Path:
    b = simulate_bundle(3, steps=80, map_sigma=(0.02, 0.05))
    root = tmp_path_factory.mktemp("src") / "b"
    write_bundle(root, b)
    return root


def _moved_row_copy(src: Path, dst: Path, file: str, back: float, *, swap: bool) -> int:
    """A bundle copy whose ``file`` has one row set ``back`` s before the next row's time;
    ``swap`` puts it after that row (so it goes back ``back`` s). Returns its data index."""
    shutil.copytree(src, dst)
    lines = (dst / file).read_text().splitlines()
    head, rows = lines[0], lines[1:]
    t = np.array([float(r.split(",")[0]) for r in rows])
    k = int(np.flatnonzero((np.diff(t) >= 0.099) & (np.arange(t.size - 1) >= 1))[0])
    fields = rows[k].split(",")
    rows[k] = ",".join([repr(float(t[k + 1]) - back)] + fields[1:])
    if swap:
        rows[k], rows[k + 1] = rows[k + 1], rows[k]
    (dst / file).write_text(head + "\n" + "\n".join(rows) + "\n")
    return k


@pytest.mark.parametrize("file", ["controls.csv", "measurements.csv"])
def test_bundle_step_back_within_tolerance_is_sorted_and_counted(
    tmp_path, capsys, bundle_source, file
):
    _moved_row_copy(bundle_source, tmp_path / "a", file, 0.03, swap=False)
    _moved_row_copy(bundle_source, tmp_path / "b", file, 0.03, swap=True)
    out = {}
    for name in ("a", "b"):
        traj, rep = tmp_path / f"{name}.txt", tmp_path / f"{name}.json"
        code = main(["recover", str(tmp_path / name), "-o", str(traj), "--report", str(rep)])
        assert code == 0
        out[name] = (traj.read_text(), json.loads(rep.read_text()), capsys.readouterr())
    assert out["a"][0] == out["b"][0]  # the same log once in time order
    assert set(out["a"][1]["reordered"].values()) == {0}
    assert out["b"][1]["reordered"][file] == 1
    assert sum(out["b"][1]["reordered"].values()) == 1
    console, err = out["b"][2]
    assert f"put in time order (steps back of at most 0.05 s): 1 row(s) of {file}" in console
    assert file in err and "out of time order" in err


@pytest.mark.parametrize("file", ["controls.csv", "measurements.csv"])
def test_bundle_step_back_beyond_tolerance_is_refused(tmp_path, capsys, bundle_source, file):
    k = _moved_row_copy(bundle_source, tmp_path / "b", file, 0.08, swap=True)
    code = main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "o.txt"), "-q"])
    err = capsys.readouterr().err
    assert code == 3
    # rows k and k + 1 were swapped: the late row is data row k + 1, on line k + 3
    assert f"{tmp_path / 'b' / file}:{k + 3}: time goes backwards by 0.080000 s" in err
    assert f"(line {k + 2})" in err and "np." not in err


def test_bundle_groundtruth_follows_the_filter_rule(tmp_path, capsys, bundle_source):
    shutil.copytree(bundle_source, tmp_path / "b")
    p = tmp_path / "b" / "groundtruth.csv"
    lines = p.read_text().splitlines()
    lines[3], lines[4] = lines[4], lines[3]  # 0.1 s apart: refused
    p.write_text("\n".join(lines) + "\n")
    assert main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "o.txt"), "-q"]) == 3
    assert f"{p}:5: time goes backwards by 0.100000 s" in capsys.readouterr().err


def test_mrclam_step_back_within_tolerance_is_sorted_and_counted(tmp_path):
    rows = ["10.0 0.1 0.0\n", "10.53 0.3 0.2\n", "10.5 0.2 0.1\n", "11.0 0.0 0.0\n"]
    d = make_dataset(tmp_path, odometry_rows=rows)
    with pytest.warns(TimeOrderWarning, match="Robot1_Odometry.dat: 1 odometry row out of"):
        r = read_mrclam_robot(d, 1)
    np.testing.assert_array_equal(
        r.controls, [[10.0, 0.1, 0.0], [10.5, 0.2, 0.1], [10.53, 0.3, 0.2], [11.0, 0.0, 0.0]]
    )
    assert r.reordered == {
        "Robot1_Odometry.dat": 1,
        "Robot1_Measurement.dat": 0,
        "Robot1_Groundtruth.dat": 0,
    }


def test_mrclam_step_back_beyond_tolerance_is_refused(tmp_path):
    rows = ["10.0 0.1 0.0\n", "10.6 0.3 0.2\n", "10.5 0.2 0.1\n", "11.0 0.0 0.0\n"]
    d = make_dataset(tmp_path, odometry_rows=rows)
    with pytest.raises(InputError) as err:
        read_mrclam_robot(d, 1)
    line = HEAD.count("\n") + 3
    msg = str(err.value)
    assert msg.startswith(f"{d / 'Robot1_Odometry.dat'}:{line}: time goes backwards by 0.1")
    assert "t = 10.500000 s after t = 10.600000 s" in msg


# ----------------------------------------------------------- repeated reference times


def test_repeated_reference_times_are_dropped_and_the_mean_is_not_halved(tmp_path, capsys):
    t = np.arange(6.0)
    ref = np.column_stack((t, np.zeros(6), np.zeros(6)))
    # every reference pose written twice (a logger that flushes twice)
    _plain(tmp_path / "ref.txt", np.repeat(t, 2), np.repeat(ref, 2, axis=0))
    _plain(tmp_path / "est.txt", t, ref * [1.1, 0, 0])
    js = tmp_path / "r.json"
    args = (tmp_path / "ref.txt", tmp_path / "est.txt", "--strategy", "consecutive")
    code, out, err = _evaluate(capsys, *args, "--json", js)
    assert code == 0
    res = json.loads(js.read_text())
    # hand oracle: 5 relations of 1 m, each estimated as 1.1 m: error 0.1 m each
    assert res["relations"] == 5
    assert res["translation"]["abs"]["mean"] == pytest.approx(0.1, abs=1e-12)
    assert res["reference_repeated_times_dropped"] == 6
    assert f"{tmp_path / 'ref.txt'}: dropped 6 reference pose(s)" in err
    assert "6 pose(s) repeating an earlier timestamp dropped" in out


def test_zero_length_relations_are_dropped_and_counted(tmp_path, capsys):
    (tmp_path / "r.relations").write_text("0 1 1 0 0 0 0 0\n1 1 0 0 0 0 0 0\n1 2 1 0 0 0 0 0\n")
    _plain(tmp_path / "e.txt", [0, 1, 2], [[0, 0, 0], [1.2, 0, 0], [2.4, 0, 0]])
    js = tmp_path / "r.json"
    code, out, err = _evaluate(capsys, tmp_path / "r.relations", tmp_path / "e.txt", "--json", js)
    assert code == 0
    res = json.loads(js.read_text())
    assert res["relations"] == 2 and res["relations_zero_length_dropped"] == 1
    assert res["translation"]["abs"]["mean"] == pytest.approx(0.2, abs=1e-12)
    assert f"{tmp_path / 'r.relations'}: dropped 1 relation(s) with t1 == t2" in err


def test_reference_file_read_as_a_set_of_timed_poses(tmp_path):
    _plain(tmp_path / "r.txt", [2, 0, 1], [[2, 0, 0], [0, 0, 0], [1, 0, 0]])
    with pytest.warns(TimeOrderWarning):
        got = read_trajectory(tmp_path / "r.txt")
    assert got.trajectory.timestamps.tolist() == [0, 1, 2]
    assert got.trajectory.poses[:, 0].tolist() == [0, 1, 2]
    assert got.out_of_order == 2 and got.time_order.first_line == 3


# ------------------------------------------------------------------ bundle as estimate


def test_bundle_as_estimate_is_refused(tmp_path, capsys, bundle_source):
    b = bundle_source
    code, _, err = _evaluate(capsys, b, b, "--strategy", "global")
    assert code == 3
    assert "no estimated trajectory" in err and "slamrel recover" in err
    assert "online.csv" not in err
    shutil.copytree(b, tmp_path / "b")
    shutil.copy(b / "groundtruth.csv", tmp_path / "b" / "online.csv")
    code, _, err = _evaluate(capsys, tmp_path / "b", tmp_path / "b")
    assert code == 3 and str(tmp_path / "b" / "online.csv") in err


def test_bundle_as_reference_is_its_ground_truth_and_same_file_is_warned(tmp_path, capsys):
    b = simulate_bundle(1, steps=40)
    write_bundle(tmp_path / "b", b)
    gt = tmp_path / "b" / "groundtruth.csv"
    code, out, err = _evaluate(capsys, tmp_path / "b", gt, "--strategy", "consecutive")
    assert code == 0
    assert f"{gt}: given as both REFERENCE and ESTIMATE" in err
    code, out, err = _evaluate(capsys, gt, gt, "--strategy", "consecutive")
    assert code == 0 and f"{gt}: given as both REFERENCE and ESTIMATE" in err
