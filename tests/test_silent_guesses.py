"""Issue 25: no silent wrong number.

Each test feeds the CLI an input whose number used to be wrong without a word (a row ignored,
a default guessed, a value rounded through float64, ...) and checks the fix at its root:
either one clear refusal (exit 3, the file, the line and what was expected) or a counted
warning with the count in the JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main
from tests.test_readers_fuzz import BUNDLE


def _write(root: Path, files: dict[str, str]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (root / name).write_text(text)
    return root


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err
    return err


# ---------------------------------------------------------------- 4. misspelt manifest keys


def test_misspelt_manifest_key_is_refused_with_a_suggestion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meta = json.loads(BUNDLE["bundle.json"])
    meta["initial_pos"] = meta.pop("initial_pose")
    files = dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)})
    b = _write(tmp_path / "b", files)
    err = _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        "bundle.json:",
        "'initial_pos'",
        "did you mean 'initial_pose'",
    )
    assert not (tmp_path / "o.tum").exists(), err


def test_misspelt_model_key_is_refused_and_writer_keys_are_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meta = json.loads(BUNDLE["bundle.json"])
    meta["sensor_model"]["max_rnage"] = 5.0
    b = _write(tmp_path / "b", dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)}))
    _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        "in sensor_model",
        "did you mean 'max_range'",
    )
    meta["sensor_model"].pop("max_rnage")
    meta["x_writer"] = {"version": 3}
    b = _write(tmp_path / "c", dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)}))
    assert main(["recover", str(b), "-o", str(tmp_path / "o.tum"), "-q"]) == 0


# ------------------------------------------------------------------ shared trajectory files


def _plain(path: Path, t: np.ndarray, poses: np.ndarray) -> Path:
    rows = "".join(f"{a:.17g} {b[0]:.17g} {b[1]:.17g} {b[2]:.17g}\n" for a, b in zip(t, poses))
    path.write_text("# t x y theta\n" + rows)
    return path


def _track(n: int = 40, dt: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * dt
    yaw = 0.3 * t + 0.2 * np.sin(t)
    poses = np.column_stack((np.cos(t) * t, np.sin(t), np.angle(np.exp(1j * yaw))))
    return t, poses


def _evaluate_json(argv: list[str], out: Path) -> dict:
    assert main(["evaluate", *argv, "--json", str(out), "-q"]) == 0
    return json.loads(out.read_text())


# ------------------------------------------------- 5. quaternions normalised on every path


def test_planar_tum_quaternions_are_normalised(tmp_path: Path) -> None:
    t, poses = _track()
    ref = _plain(tmp_path / "ref.txt", t, poses)
    scale = 1.0 + 9e-4  # inside the 1e-3 norm tolerance
    q = scale * np.column_stack(
        (np.zeros_like(t), np.zeros_like(t), np.sin(poses[:, 2] / 2), np.cos(poses[:, 2] / 2))
    )
    rows = np.column_stack((t, poses[:, :2], np.zeros_like(t), q))
    est = tmp_path / "est.tum"
    est.write_text("".join(" ".join(f"{v:.17g}" for v in r) + "\n" for r in rows))
    result = _evaluate_json([str(ref), str(est)], tmp_path / "r.json")
    assert result["group"] == "SE2"
    assert result["rotation"]["abs"]["max"] < 1e-9


# ------------------------------------------------------- 6. OSPA/GOSPA for a large order p


def test_ospa_does_not_underflow_for_a_large_order(tmp_path: Path) -> None:
    (tmp_path / "ref.csv").write_text("landmark,x,y\n1,0,0\n2,5,0\n3,0,5\n4,5,5\n")
    (tmp_path / "est.csv").write_text("landmark,x,y\n1,0.5,0\n2,5,0.5\n3,0,5.5\n4,5.5,5\n")
    argv = ["map-compare", str(tmp_path / "est.csv"), str(tmp_path / "ref.csv")]
    argv += ["--associate", "id", "--cutoff", "1", "--order", "2000", "-q"]
    assert main([*argv, "--json", str(tmp_path / "r.json")]) == 0
    result = json.loads((tmp_path / "r.json").read_text())
    # every aligned residual is sqrt(2)/4 m: both distances are that for any order
    assert result["ospa"]["value"] == pytest.approx(np.sqrt(2) / 4, rel=1e-12)
    assert result["gospa"]["value"] == pytest.approx(np.sqrt(2) / 4 * 4 ** (1 / 2000), rel=1e-12)


# ------------------------------------------------------------ 8. duplicated relation lines


def _relations_file(path: Path, t: np.ndarray, poses: np.ndarray, repeat: int = 0) -> Path:
    from relation_metric.relations import RelationSet
    from relation_metric.se2 import between
    from slamrel.formats.relations import write_relations

    delta = between(poses[:-1], poses[1:])
    write_relations(path, RelationSet(t[:-1], t[1:], delta, key="time"))
    if repeat:
        lines = path.read_text().splitlines(keepends=True)
        path.write_text("".join(lines + lines[repeat : repeat + 1]))
    return path


def test_duplicate_relation_lines_are_dropped_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t, poses = _track()
    rel = _relations_file(tmp_path / "r.relations", t, poses, repeat=3)
    bent = poses.copy()
    bent[3:, 2] += 0.01  # the repeated relation carries the whole error
    est = _plain(tmp_path / "est.txt", t, bent)
    result = _evaluate_json([str(rel), str(est)], tmp_path / "a.json")
    assert result["relations"] == len(t) - 1
    assert result["relations_duplicates"] == {"count": 1, "dropped": True, "first_line": 41}
    assert "repeat an earlier line exactly" in capsys.readouterr().err
    kept = _evaluate_json([str(rel), str(est), "--mode", "metricevaluator"], tmp_path / "b.json")
    assert kept["relations"] == len(t)
    assert kept["relations_duplicates"]["dropped"] is False


# -------------------------------------------------- 1. two estimate poses at one timestamp


def test_two_estimate_poses_at_one_time_are_refused_in_either_order(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t, poses = _track()
    ref = _plain(tmp_path / "ref.txt", t, poses)
    other = poses[10] + np.array([0.2, -0.1, 0.05])
    for name, rows in (("a", (poses[10], other)), ("b", (other, poses[10]))):
        tt = np.insert(t, 11, t[10])
        pp = np.insert(poses, 10, rows[0], axis=0)
        pp[11] = rows[1]
        est = _plain(tmp_path / f"{name}.txt", tt, pp)
        _refused(
            ["evaluate", str(ref), str(est)], capsys, f"{est}:13:", "two different estimate poses"
        )


def test_exact_estimate_repeats_are_dropped_counted_and_refused_by_strict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t, poses = _track()
    ref = _plain(tmp_path / "ref.txt", t, poses)
    est = _plain(tmp_path / "est.txt", np.insert(t, 5, t[5]), np.insert(poses, 5, poses[5], axis=0))
    result = _evaluate_json([str(ref), str(est)], tmp_path / "r.json")
    assert result["estimate_repeated_times"] == {"count": 1, "differing": 0, "first_line": 8}
    assert result["unassociated"] == 0
    assert "repeat the previous pose exactly" in capsys.readouterr().err
    _refused(["evaluate", str(ref), str(est), "--strict"], capsys, f"{est}:8:", "--strict")
    # the reference side: repeats are dropped (the first kept), and --strict refuses them
    ref2 = _plain(
        tmp_path / "ref2.txt", np.insert(t, 5, t[5]), np.insert(poses, 5, poses[6], axis=0)
    )
    _refused(["evaluate", str(ref2), str(est), "--strict"], capsys, f"{ref2}:8:")


# ---------------------------------------- 2. both ends of a relation at one estimate pose


def test_relations_collapsing_on_one_estimate_pose_are_not_scored_as_zero_motion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t, poses = _track(n=41, dt=0.25)
    ref = _plain(tmp_path / "ref.txt", t, poses)
    est = _plain(tmp_path / "est.txt", t[::2], poses[::2])  # half the reference rate
    tol = ["--max-time-diff", "0.3"]
    result = _evaluate_json([str(ref), str(est), *tol], tmp_path / "a.json")
    same = result["same_estimate_pose"]
    # 0.25 s relations, poses 0.5 s apart: the end at an odd time ties between two poses
    # and takes the earlier; every relation starting at an even time collapses
    assert same["count"] == 20 and same["unassociated"] == 20 and same["interpolated"] == 0
    assert result["unassociated"] == 20
    assert "both ends at one estimate pose" in capsys.readouterr().err
    assert result["translation"]["abs"]["count"] == 20
    inter = _evaluate_json([str(ref), str(est), *tol, "--interpolate"], tmp_path / "b.json")
    assert inter["same_estimate_pose"]["interpolated"] == 20
    assert inter["unassociated"] == 0 and inter["interpolated"] == 20


# ------------------------------------------------------------- 7. zero selected relations


def test_no_selected_relation_is_refused_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t, poses = _track()
    ref = _plain(tmp_path / "ref.txt", t, poses)
    est = _plain(tmp_path / "est.txt", t, poses)
    outs = ["--json", str(tmp_path / "r.json"), "--evo-zip", str(tmp_path / "r.zip")]
    _refused(
        ["evaluate", str(ref), str(est), "--strategy", "loops", "--radius", "1e-9", *outs],
        capsys,
        "no relation was selected",
        "--strategy loops",
    )
    zero = tmp_path / "zero.relations"
    zero.write_text("0.5 0.5 0 0 0 0 0 0\n")
    _refused(["evaluate", str(zero), str(est), *outs], capsys, "no relation left to score")
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.zip").exists()


def test_evaluate_api_refuses_no_relations_unless_asked() -> None:
    """The Python API as the command: no relation is an error, not a NaN table; a caller
    that reports empty sets itself (allow_empty=True) gets count 0."""
    import slamrel
    from relation_metric.errors import InputError

    t, poses = _track()
    traj = slamrel.Trajectory(t, poses)
    rel = slamrel.generate_relations(traj, "consecutive")
    empty = rel.subset(np.zeros(len(rel), dtype=bool))
    with pytest.raises(InputError, match="no relations to score of ref.relations"):
        slamrel.evaluate(empty, traj, relations_name="ref.relations")
    ev = slamrel.evaluate(empty, traj, allow_empty=True)
    assert ev.translation.abs.count == 0
    assert slamrel.evaluate(rel, traj).translation.abs.count == len(rel)


def test_evo_zip_of_no_scored_relation_is_refused(tmp_path: Path) -> None:
    from relation_metric.errors import InputError
    from relation_metric.evaluate import evaluate
    from relation_metric.relations import RelationSet
    from relation_metric.trajectory import Trajectory
    from slamrel.formats.results import write_evo_zip

    ev = evaluate(
        RelationSet(np.empty(0), np.empty(0), np.empty((0, 3))),
        Trajectory([0.0], [[0, 0, 0]]),
        allow_empty=True,
    )
    with pytest.raises(InputError, match="no zip written"):
        write_evo_zip(tmp_path / "e.zip", ev)
    assert not (tmp_path / "e.zip").exists()


# ------------------------------------------------------------- 3. a disconnected pose graph


def test_disconnected_pose_graph_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    info = "100 0 0 100 0 100"
    lines = [f"VERTEX_SE2 {k} {k} 0 0" for k in range(6)]
    lines += [f"EDGE_SE2 {k} {k + 1} 1 0 0 {info}" for k in (0, 1, 3, 4)]  # 0-1-2 | 3-4-5
    g = tmp_path / "g.g2o"
    g.write_text("\n".join(lines) + "\n")
    for batch in ("0", "2"):
        _refused(
            ["solve", str(g), "-o", str(tmp_path / "out"), "--batch", batch],
            capsys,
            f"{g}",
            "2 disconnected parts",
            "e.g. pose 3, share no factor with pose 0",  # the file's ids
        )
    assert not (tmp_path / "out").exists()


# ------------------------------------------- 10. self-loop edges and bearings out of range


@pytest.mark.parametrize(
    "name,text",
    [
        ("g.g2o", "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"),
        ("t.graph", "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\n"),
    ],
)
def test_self_loop_edges_are_refused_with_their_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, text: str
) -> None:
    from slamrel.formats.g2o import read_g2o_graph
    from slamrel.formats.toro import read_toro_graph

    path = tmp_path / name
    loop = text.splitlines()[-1].replace(" 0 1 ", " 1 1 ", 1)
    path.write_text(text + loop + "\n")
    reader = read_g2o_graph if name.endswith(".g2o") else read_toro_graph
    from relation_metric.errors import InputError

    with pytest.raises(InputError, match="to itself") as err:
        reader(path)
    assert f"{path}:4:" in str(err.value)
    if name.endswith(".g2o"):
        _refused(["solve", str(path), "-o", str(tmp_path / "o")], capsys, f"{path}:4:")


def test_bearings_outside_pi_are_wrapped_and_counted_or_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import math

    meas = "t,range,bearing,landmark\n0.5,1.5,0.1,1\n1.5,2.0,{b},\n2.5,3.0,0.5,2\n"
    wrapped = 2 * math.pi - 0.3
    b = _write(tmp_path / "b", dict(BUNDLE, **{"measurements.csv": meas.format(b=wrapped)}))
    report = tmp_path / "rep.json"
    argv = ["recover", str(b), "-o", str(tmp_path / "o.tum"), "--report", str(report), "-q"]
    assert main(argv) == 0
    assert json.loads(report.read_text())["wrapped_bearings"] == 1
    assert "measurements.csv:3: 1 bearing(s) outside [-pi, pi) wrapped" in capsys.readouterr().err
    from slamrel.formats.bundle import read_bundle

    with pytest.warns(UserWarning):
        bundle = read_bundle(b)
    assert bundle.measurements[1, 1] == pytest.approx(-0.3, abs=1e-12)
    c = _write(tmp_path / "c", dict(BUNDLE, **{"measurements.csv": meas.format(b=45.0)}))
    _refused(
        ["recover", str(c), "-o", str(tmp_path / "p.tum")], capsys, "measurements.csv:3:", "degrees"
    )


# --------------------------------------------------- 9. landmark ids read exactly as int64


GTSAM_L = ord("l") << 56  # gtsam.symbol('l', 0): far beyond 2**53


def test_landmark_ids_beyond_2_53_are_read_exactly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ids = [2**53, 2**53 + 1, GTSAM_L + 1, GTSAM_L + 2]
    xy = [(0, 0), (5, 0), (0, 5), (5, 5)]
    ref = tmp_path / "ref.csv"
    est = tmp_path / "est.csv"
    ref.write_text("landmark,x,y\n" + "".join(f"{i},{x},{y}\n" for i, (x, y) in zip(ids, xy)))
    est.write_text("landmark,x,y\n" + "".join(f"{i},{x + 0.1},{y}\n" for i, (x, y) in zip(ids, xy)))
    out = tmp_path / "a.csv"
    argv = ["map-compare", str(est), str(ref), "--associate", "id", "-q"]
    assert main([*argv, "--write-association", str(out)]) == 0
    pairs = [tuple(map(int, ln.split(","))) for ln in out.read_text().splitlines()[3:]]
    assert sorted(pairs) == sorted((i, i) for i in ids)
    # the association CSV reads the ids exactly too
    assert main(["map-compare", str(est), str(ref), "--associate", str(out), "-q"]) == 0
    bad = tmp_path / "bad.csv"
    bad.write_text("landmark,x,y\n1,0,0\n2.5,1,1\n")
    _refused(["map-compare", str(bad), str(ref), "-q"], capsys, f"{bad}:3:", "integer id")


def test_bundle_measurement_ids_are_read_exactly(tmp_path: Path) -> None:
    from slamrel.formats.bundle import read_bundle

    big = 2**53
    files = dict(BUNDLE)
    files["map.csv"] = (
        f"landmark,x,y,cxx,cxy,cyy\n{big},1.5,0.2,0.01,0,0.01\n{big + 1},3,1,0.02,0.001,0.02\n"
    )
    files["measurements.csv"] = (
        f"t,range,bearing,landmark\n0.5,1.5,0.1,{big + 1}\n1.5,2.0,-0.3,\n2.5,3.0,0.5,{big}\n"
    )
    files.pop("landmarks_groundtruth.csv")
    b = read_bundle(_write(tmp_path / "b", files))
    assert b.measurement_landmarks.tolist() == [big + 1, 0, big]
    assert b.measurement_associated.tolist() == [True, False, True]
    assert b.map_ids.tolist() == [big, big + 1]


GTSAM_X = ord("x") << 56  # gtsam.symbol('x', 0)


def test_g2o_ids_beyond_2_53_are_read_exactly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """g2o ids through float64 would turn 2**53 + 1 into 2**53 and GTSAM's symbol keys into
    their neighbours: maps and graphs read them exactly; a trajectory, whose ids are its
    timestamps, refuses them at their line."""
    from slamrel.formats.g2o import read_g2o_graph
    from slamrel.formats.landmark_maps import read_map

    g = tmp_path / "m.g2o"
    g.write_text(f"VERTEX_XY 1 0 0\nVERTEX_XY {2**53 + 1} 1 1\nVERTEX_XY {GTSAM_L + 3} 2 2\n")
    assert read_map(str(g)).ids.tolist() == [1, 2**53 + 1, GTSAM_L + 3]
    ref = tmp_path / "ref.csv"
    ref.write_text(f"landmark,x,y\n1,0,0\n{2**53 + 1},1,1\n{GTSAM_L + 3},2,2\n")
    out = tmp_path / "a.csv"
    argv = ["map-compare", str(g), str(ref), "--associate", "id", "--write-association", str(out)]
    assert main([*argv, "-q"]) == 0
    pairs = [tuple(map(int, ln.split(","))) for ln in out.read_text().splitlines()[3:]]
    assert sorted(pairs) == [(1, 1), (2**53 + 1, 2**53 + 1), (GTSAM_L + 3, GTSAM_L + 3)]
    # a pose graph keyed by GTSAM symbols: x0 x1 x2 and l0, neighbours 1 apart
    x0, l0 = GTSAM_X, GTSAM_L
    info3, info2 = "100 0 0 100 0 100", "100 0 100"
    graph = tmp_path / "g.g2o"
    graph.write_text(
        f"VERTEX_SE2 {x0} 0 0 0\nVERTEX_SE2 {x0 + 1} 1 0 0\nVERTEX_SE2 {x0 + 2} 2 0 0\n"
        f"VERTEX_XY {l0} 1 1\n"
        f"EDGE_SE2 {x0} {x0 + 1} 1 0 0 {info3}\nEDGE_SE2 {x0 + 1} {x0 + 2} 1 0 0 {info3}\n"
        f"EDGE_SE2_XY {x0 + 2} {l0} -1 1 {info2}\n"
    )
    pg, pose_ids, lm_ids = read_g2o_graph(str(graph))
    assert pose_ids.tolist() == [x0, x0 + 1, x0 + 2] and lm_ids.tolist() == [l0]
    assert pg.pp_i.tolist() == [0, 1] and pg.pp_j.tolist() == [1, 2]
    assert pg.pl_k.tolist() == [2] and pg.pl_l.tolist() == [0]
    assert main(["solve", str(graph), "-o", str(tmp_path / "solved"), "-q"]) == 0
    _, back_poses, back_lms = read_g2o_graph(str(tmp_path / "solved" / "solved.g2o"))
    assert back_poses.tolist() == pose_ids.tolist() and back_lms.tolist() == [l0]
    # an edge to x0 + 3 (which a double would round onto x0 + 4 or x0) is unknown, named exactly
    bad = tmp_path / "bad.g2o"
    bad.write_text(graph.read_text() + f"EDGE_SE2 {x0} {x0 + 3} 1 0 0 {info3}\n")
    _refused(["solve", str(bad), "-o", str(tmp_path / "o")], capsys, f"{bad}:8:", str(x0 + 3))
    # as a trajectory the ids are timestamps: refused, not rounded
    _refused(
        ["evaluate", str(graph), str(graph), "--strategy", "consecutive"],
        capsys,
        f"{graph}:1:",
        "below 2**53",
    )


def test_isam_self_loop_is_refused_by_import_and_solve(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same self-loop check as g2o and TORO (relation_metric.ids.refuse_self_loops)."""
    path = tmp_path / "loop.txt"
    path.write_text("ODOMETRY 0 1 1.0 0 0 10 0 0 10 0 100\nODOMETRY 1 1 0.0 0 0 10 0 0 10 0 100\n")
    _refused(["import", "isam", str(path), "-o", str(tmp_path / "g.g2o")], capsys, f"{path}:2:")
    _refused(["solve", str(path), "-o", str(tmp_path / "o")], capsys, f"{path}:2:")
