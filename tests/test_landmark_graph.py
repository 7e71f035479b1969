"""Landmark graph: mesh relations, degenerate meshes, association, OSPA/GOSPA, CLI."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from conftest import require_data

from landmark_graph.landmark_association import associate_auto
from landmark_graph.map_compare import compare_maps
from landmark_graph.maps import LandmarkMap
from landmark_graph.mesh import delaunay_mesh
from landmark_graph.mesh_relations import mesh_errors
from landmark_graph.set_distances import gospa, ospa
from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.cli import main
from slamrel.formats.landmark_maps import read_map, write_map


def rigid(xy, pose):
    return se2.transform_points(np.asarray(pose, float), xy)


def test_errors_vanish_for_a_rigid_copy(rng):
    ref = rng.uniform(-20, 20, (60, 2))
    mesh = delaunay_mesh(ref)
    e = mesh_errors(rigid(ref, [3.0, -7.0, 2.2]), ref, mesh)
    for arr in (
        e.edge_length,
        e.corner_angle,
        e.edge_displacement_triangle,
        e.edge_displacement_aligned,
    ):
        assert np.nanmax(arr) < 1e-9


def test_one_displaced_landmark_changes_only_what_touches_it(rng):
    ref = rng.uniform(-20, 20, (60, 2))
    mesh = delaunay_mesh(ref)
    est = ref.copy()
    k = 17
    est[k] += [0.4, -0.3]
    e = mesh_errors(est, ref, mesh)
    touches_edge = (mesh.edges == k).any(axis=1)
    assert np.all(e.edge_length[~touches_edge] < 1e-12) and np.all(e.edge_length[touches_edge] > 0)
    touches_tri = (mesh.triangles == k).any(axis=1)
    assert np.all(e.corner_angle[~touches_tri] < 1e-12) and np.all(
        e.corner_angle[touches_tri].max(axis=1) > 0
    )


def test_results_do_not_depend_on_landmark_order(rng):
    ref_xy = rng.uniform(-20, 20, (40, 2))
    ids = np.arange(100, 140)
    est_xy = ref_xy + rng.normal(0, 0.1, ref_xy.shape)
    a = compare_maps(LandmarkMap(ids, est_xy), LandmarkMap(ids, ref_xy)).as_dict()
    p, q = rng.permutation(40), rng.permutation(40)
    b = compare_maps(LandmarkMap(ids[p], est_xy[p]), LandmarkMap(ids[q], ref_xy[q])).as_dict()
    for part in ("translation", "rotation"):
        for stat in ("mean", "std", "max", "rmse", "count"):
            assert a[part]["abs"][stat] == pytest.approx(b[part]["abs"][stat], rel=1e-9)
    assert a["ospa"]["value"] == pytest.approx(b["ospa"]["value"])
    assert a["gospa"]["value"] == pytest.approx(b["gospa"]["value"])


def test_degenerate_meshes():
    assert delaunay_mesh(np.zeros((0, 2))).edges.shape == (0, 2)
    assert delaunay_mesh([[0, 0]]).edges.shape == (0, 2)
    np.testing.assert_array_equal(delaunay_mesh([[0, 0], [1, 1]]).edges, [[0, 1]])
    line = delaunay_mesh([[0, 0], [2, 2], [1, 1], [3, 3]])  # collinear: chain along the line
    assert line.collinear and line.triangles.shape == (0, 3)
    np.testing.assert_array_equal(line.edges, [[0, 2], [1, 2], [1, 3]])
    dup = delaunay_mesh([[0, 0], [1, 0], [0, 1], [1, 0], [1, 1]])  # point 3 duplicates point 1
    np.testing.assert_array_equal(dup.duplicates, [[1, 3]])
    assert not (dup.edges == 3).any()
    thin = delaunay_mesh([[0, 0], [10, 0], [5, 0.05], [5, 8]])
    assert thin.thin.any()


def test_ospa_gospa_equal_brute_force_for_every_p(rng):
    for _ in range(20):
        x = rng.uniform(0, 3, (rng.integers(0, 5), 2))
        y = rng.uniform(0, 3, (rng.integers(1, 6), 2))
        c = 1.0
        for p in (1.0, 2.0, 3.5):
            small, large = (x, y) if len(x) <= len(y) else (y, x)
            m, n = len(small), len(large)
            best = min(
                (
                    sum(min(np.hypot(*(small[i] - large[perm[i]])), c) ** p for i in range(m))
                    for perm in itertools.permutations(range(n), m)
                ),
                default=0.0,
            )
            assert ospa(x, y, c=c, p=p) == pytest.approx(((best + c**p * (n - m)) / n) ** (1 / p))
            assert gospa(x, y, c=c, p=p) == pytest.approx((best + c**p / 2 * (n - m)) ** (1 / p))


@pytest.mark.realdata
def test_mrclam_landmarks_perturbed_and_auto_associated(rng):
    ref = read_map(require_data("mrclam", "MRCLAM_Dataset7", "Landmark_Groundtruth.dat"))
    assert len(ref) == 15
    # a perturbed copy: the per-edge length errors are what the displacement implies
    est_xy = ref.xy.copy()
    est_xy[4] += [0.05, 0.0]
    res = compare_maps(LandmarkMap(ref.ids, est_xy), ref)
    e = res.mesh.edges
    ids = ref.ids[res.association.reference_rows]
    pos = {int(i): k for k, i in enumerate(ref.ids)}
    expected = np.abs(
        np.hypot(
            *(
                est_xy[[pos[int(i)] for i in ids[e[:, 1]]]]
                - est_xy[[pos[int(i)] for i in ids[e[:, 0]]]]
            ).T
        )
        - np.hypot(
            *(
                ref.xy[[pos[int(i)] for i in ids[e[:, 1]]]]
                - ref.xy[[pos[int(i)] for i in ids[e[:, 0]]]]
            ).T
        )
    )
    np.testing.assert_allclose(res.errors.edge_length, expected, atol=1e-12)
    # automatic association after a random rigid transform with 10% (2 of 15) removed, exact
    # and with 1 cm noise (the closest landmarks are 0.19 m apart), at two cut-offs
    for trial in range(30):
        keep = np.sort(rng.permutation(15)[:13])
        g = [*rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
        noise = rng.normal(0, 0.01 * (trial % 2), (13, 2))
        moved = LandmarkMap(ref.ids[keep] + 1000, rigid(ref.xy[keep] + noise, g))
        a = associate_auto(moved, ref, cutoff=(0.3, 1.0)[trial % 3 == 0], seed=trial)
        np.testing.assert_array_equal(moved.ids[a.estimate_rows] - 1000, ref.ids[keep])
        np.testing.assert_array_equal(ref.ids[a.reference_rows], ref.ids[keep])
        np.testing.assert_array_equal(
            np.sort(ref.ids[a.missed]), np.setdiff1d(ref.ids, ref.ids[keep])
        )
        assert a.spurious.size == 0
        # the recovered alignment is the inverse of the transform applied
        assert se2.wrap_angle(a.alignment.angle + g[2]) == pytest.approx(0, abs=0.02)


@pytest.mark.parametrize(
    "est_text,msg",
    [
        ("landmark,x,y\n1,0,0\n2,nan,1\n3,1,1\n", "finite"),
        ("landmark,x,y\n1,0,0\n1,1,1\n3,1,0\n", "duplicate landmark id 1"),
        ("landmark,x,y\n", "empty map"),
    ],
)
def test_bad_maps_exit_3(tmp_path, capsys, est_text, msg):
    est = tmp_path / "est.csv"
    ref = tmp_path / "ref.csv"
    est.write_text(est_text)
    ref.write_text("landmark,x,y\n1,0,0\n2,1,1\n3,1,0\n")
    assert main(["map-compare", str(est), str(ref), "-q"]) == 3
    assert msg in capsys.readouterr().err


def test_association_file_unknown_id_exit_3(tmp_path, capsys):
    m = tmp_path / "m.csv"
    m.write_text("landmark,x,y\n1,0,0\n2,1,1\n3,1,0\n")
    f = tmp_path / "a.csv"
    f.write_text("estimate,reference\n1,1\n9,2\n")
    assert main(["map-compare", str(m), str(m), "--associate", str(f), "-q"]) == 3
    assert "a.csv:3: unknown estimated landmark id 9" in capsys.readouterr().err


def test_cli_outputs(tmp_path):
    m = tmp_path / "m.csv"
    m.write_text(
        "landmark,x,y\n" + "".join(f"{k},{np.cos(k) * k},{np.sin(k) * k}\n" for k in range(1, 12))
    )
    out, per, png = tmp_path / "o.json", tmp_path / "e.csv", tmp_path / "p.png"
    assert (
        main(
            [
                "map-compare",
                str(m),
                str(m),
                "--json",
                str(out),
                "--per-edge",
                str(per),
                "--plot",
                str(png),
                "-q",
            ]
        )
        == 0
    )
    res = json.loads(out.read_text())
    assert res["translation"]["abs"]["max"] < 1e-9 and res["association"]["matched"] == 11
    assert per.read_text().count("\n") == res["relations"] + 1
    assert png.stat().st_size > 5000
    with pytest.raises(InputError):
        LandmarkMap([1, 2], [[0, 0]])


@pytest.mark.parametrize("power", [1.0, 2.0])
def test_sparse_assignment_equals_dense_padded_assignment(rng, power):
    from scipy.optimize import linear_sum_assignment

    from landmark_graph.landmark_association import _sparse_assignment

    c = 0.5
    for _ in range(5):
        x = rng.uniform(0, 10, (40, 2))
        # dense clutter near the matches so that the optimal choice is not the obvious one
        y = np.concatenate((x[:30] + rng.normal(0, 0.25, (30, 2)), rng.uniform(0, 10, (12, 2))))
        er, rr = _sparse_assignment(x, y, c, power=power)
        d = np.hypot(x[:, None, 0] - y[None, :, 0], x[:, None, 1] - y[None, :, 1])
        w = d**power
        cp = c**power
        big = np.full((82, 82), 1e6)
        big[:40, :42] = np.where(d < c, w, 1e6)
        big[:40, 42:] = np.where(np.eye(40) > 0, cp, 1e6)
        big[40:, :42] = np.where(np.eye(42) > 0, cp, 1e6)
        big[40:, 42:] = np.where((d < c).T, 0.0, 1e6)
        a, b = linear_sum_assignment(big)
        assert np.all(d[er, rr] < c) and np.unique(er).size == er.size
        sparse_cost = w[er, rr].sum() + cp * (40 - er.size) + cp * (42 - er.size)
        assert sparse_cost == pytest.approx(big[a, b].sum(), rel=1e-9)


def test_auto_association_large_map(rng):
    n = 3000
    ref = rng.uniform(0, 500, (n, 2))
    keep = np.sort(rng.permutation(n)[: int(0.9 * n)])
    est = rigid(ref[keep] + rng.normal(0, 0.05, (keep.size, 2)), [5.0, 3.0, 0.7])
    a = associate_auto(LandmarkMap(keep, est), LandmarkMap(np.arange(n), ref), cutoff=1.0)
    assert a.estimate_rows.size == keep.size
    np.testing.assert_array_equal(keep[a.estimate_rows], a.reference_rows)


def test_pose_landmark_errors_invariance_and_hand_value(rng):
    from landmark_graph.pose_landmark import pose_landmark_errors

    poses = se2.wrap_last(rng.normal(size=(20, 3)) * [5, 5, 2])
    lms = rng.uniform(-10, 10, (20, 2))
    # a rigid transform of the whole solution (poses and landmarks) changes nothing
    g = np.array([3.0, -1.0, 0.8])
    moved = se2.compose(g, poses)
    np.testing.assert_allclose(pose_landmark_errors(moved, rigid(lms, g), poses, lms), 0, atol=1e-9)
    # hand value: pose at the origin, landmark 0.3 m off along x
    e = pose_landmark_errors([[0, 0, 0]], [[1.3, 2.0]], [[0, 0, 0]], [[1.0, 2.0]])
    assert e[0] == pytest.approx(0.3)


def test_shared_landmark_relations():
    from landmark_graph.pose_landmark import shared_landmark_relations
    from relation_metric.trajectory import Trajectory

    ref = Trajectory.from_poses(np.column_stack((np.arange(5.0), np.zeros(5), np.zeros(5))))
    pose = [0, 0, 0, 1, 1, 2, 2, 2, 4, 4, 4]
    lm = [1, 2, 3, 1, 2, 1, 2, 3, 1, 2, 3]
    rel = shared_landmark_relations(ref, pose, lm, min_common=3)
    assert list(zip(rel.first.astype(int), rel.second.astype(int))) == [(0, 2), (0, 4), (2, 4)]
    np.testing.assert_allclose(rel.delta[0], [2.0, 0.0, 0.0])


def test_cli_console_summary(tmp_path, capsys):
    m = tmp_path / "m.csv"
    m.write_text("landmark,x,y\n1,0,0\n2,1,0\n3,0,1\n4,1,1.2\n")
    assert main(["map-compare", str(m), str(m)]) == 0
    out = capsys.readouterr().out
    assert "matched 4, missed 0, spurious 0" in out
    assert "edge length abs [m]" in out and "OSPA 0.0000" in out


def test_cli_written_association_reads_back_and_overrides(tmp_path, rng):
    ref_xy = rng.uniform(0, 30, (30, 2))
    ref = tmp_path / "ref.csv"
    est = tmp_path / "est.csv"
    write_map(ref, LandmarkMap(np.arange(30), ref_xy))
    moved = rigid(ref_xy[:27], [3.0, 1.0, 2.0])  # the last three are missing in the estimate
    write_map(est, LandmarkMap(np.arange(27) + 500, moved))
    a_csv, j1, j2 = tmp_path / "assoc.csv", tmp_path / "1.json", tmp_path / "2.json"
    args = ["map-compare", str(est), str(ref), "-q"]
    assert (
        main([*args, "--associate", "auto", "--write-association", str(a_csv), "--json", str(j1)])
        == 0
    )
    text = a_csv.read_text()
    assert "# missed reference ids: 27 28 29\n" in text and "500,0\n" in text
    assert main([*args, "--associate", str(a_csv), "--json", str(j2)]) == 0
    r1, r2 = json.loads(j1.read_text()), json.loads(j2.read_text())
    a1, a2 = r1.pop("association"), r2.pop("association")
    assert (a1.pop("source"), a1.pop("requested")) == ("auto", "auto")
    assert (a2.pop("source"), a2.pop("requested")) == ("file", "file")
    # the same pairs, the same numbers: the file's comparison is aligned as the automatic one
    assert a1 == a2 and r1 == r2
    assert a1["missed_ids"] == [27, 28, 29]
    assert r1["ospa"]["frame"] == r2["ospa"]["frame"]
    assert r1["ospa"]["frame"].startswith("estimate moved onto the reference by the SE(2)")
    # the user edits one pair: the file overrides the automatic result
    a_csv.write_text(text.replace("500,0\n", "500,28\n"))
    assert main([*args, "--associate", str(a_csv), "--json", str(j2)]) == 0
    r3 = json.loads(j2.read_text())
    assert r3["association"]["missed_ids"] == [0, 27, 29]
    assert r3["translation"]["abs"]["max"] > 1.0  # the wrong pair shows in the edge errors
    # the association file is an input: not to be overwritten
    assert main([*args, "--associate", str(a_csv), "--json", str(a_csv)]) == 3


@pytest.mark.parametrize(
    "assoc_text,extra,msg",
    [
        ("estimate,reference\n1,1\n1,2\n", [], "a.csv:3: estimated landmark 1 is associated twice"),
        ("estimate,reference\n1,1\n2,1\n", [], "a.csv:3: reference landmark 1 is associated twice"),
        ("est,ref\n1,1\n", [], "a.csv:1: missing column(s) estimate, reference"),
        ("estimate,reference\n1,x\n", [], "a.csv:2: column 'reference': expected a number"),
        ("estimate,reference\n1,1.5\n", [], "a.csv:2: column 'reference': expected an integer"),
    ],
)
def test_cli_bad_association_file_exit_3(tmp_path, capsys, assoc_text, extra, msg):
    m = tmp_path / "m.csv"
    m.write_text("landmark,x,y\n1,0,0\n2,1,1\n3,1,0\n")
    args = ["map-compare", str(m), str(m), "-q", *extra]
    if assoc_text is not None:
        (tmp_path / "a.csv").write_text(assoc_text)
        args += ["--associate", str(tmp_path / "a.csv")]
    assert main(args) == 3
    assert msg in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra,msg",
    [
        (["--cutoff", "-1"], "argument --cutoff: expected a finite positive number"),
        (["--order", "0.5"], "argument --order: expected a finite number >= 1"),
        (["--associate", "auto", "--cutoff", "nan"], "argument --cutoff"),
        (["--thin-angle", "200"], "argument --thin-angle: expected an angle in degrees in (0, 60]"),
    ],
)
def test_cli_bad_options_exit_2(tmp_path, capsys, extra, msg):
    m = tmp_path / "m.csv"
    m.write_text("landmark,x,y\n1,0,0\n2,1,1\n3,1,0\n")
    with pytest.raises(SystemExit) as e:
        main(["map-compare", str(m), str(m), "-q", *extra])
    assert e.value.code == 2
    assert msg in capsys.readouterr().err


def test_cli_reports_duplicate_reference_positions(tmp_path, capsys):
    ref = tmp_path / "ref.csv"
    ref.write_text("landmark,x,y\n1,0,0\n2,4,0\n3,0,4\n4,4,0\n5,4,4\n")
    out = tmp_path / "o.json"
    assert main(["map-compare", str(ref), str(ref), "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["mesh"]["duplicates"] == 1 and sorted(res["mesh"]["duplicate_ids"][0]) == [2, 4]
    assert "1 duplicate reference positions" in capsys.readouterr().out


def test_auto_association_of_clustered_maps_equals_the_least_squares_oracle(rng):
    """Clusters of 3 landmarks within 0.3 m (as MRCLAM) above the exhaustive-search size:
    the result must equal the optimal assignment after the least-squares alignment on the
    true correspondences (which itself may swap landmarks a few mm apart)."""
    from landmark_graph.landmark_association import _apply, _sparse_assignment
    from relation_metric.alignment import umeyama

    for trial in range(10):
        centres = rng.uniform(0, 20, (30, 2))
        ref = (centres[:, None, :] + rng.uniform(-0.15, 0.15, (30, 3, 2))).reshape(-1, 2)
        keep = np.sort(rng.permutation(90)[:81])
        g = [*rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
        est = rigid(ref[keep] + rng.normal(0, 0.01, (81, 2)), g)
        a = associate_auto(
            LandmarkMap(keep, est), LandmarkMap(np.arange(90), ref), cutoff=0.1, seed=trial
        )
        er, rr = _sparse_assignment(_apply(umeyama(est, ref[keep]), est), ref, 0.1)
        np.testing.assert_array_equal(a.reference_rows, np.sort(rr))
        np.testing.assert_array_equal(a.estimate_rows, er[np.argsort(rr)])
