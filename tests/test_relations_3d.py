"""The relation metric on SE(3): readers, relations, errors, the CLI."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relation_metric import se2, se3
from relation_metric.errors import InputError
from relation_metric.evaluate import evaluate
from relation_metric.groups import SE2, SE3
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.cli import main
from slamrel.formats.relations import read_relations, write_relations
from slamrel.formats.trajectories import PlanarProjectionWarning, read_trajectory


def helix(n=200, seed=0):
    """A 3-D trajectory: a rising, rolling helix, 10 Hz."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 4 * np.pi, n)
    xyz = np.column_stack((np.cos(s), np.sin(s), 0.1 * s))
    rpy = np.column_stack((0.2 * np.sin(s), 0.1 * np.cos(s), s + rng.normal(0, 0.01, n)))
    return Trajectory(np.arange(n) * 0.1, np.column_stack((xyz, se3.from_euler_zyx(rpy))))


def write_tum(path, traj):
    rows = np.column_stack((traj.timestamps, traj.poses))
    np.savetxt(path, rows, fmt="%.12f", header="t x y z qx qy qz qw")


def perturbed(traj, rng, sigma=0.01):
    noise = np.column_stack(
        (
            rng.normal(0, sigma, (len(traj), 3)),
            se3.from_euler_zyx(rng.normal(0, sigma, (len(traj), 3))),
        )
    )
    return Trajectory(traj.timestamps, se3.compose(traj.poses, noise))


# --- readers ---------------------------------------------------------------------------


def test_tum_with_out_of_plane_motion_is_3d_and_planar_tum_stays_2d(tmp_path):
    ref = helix()
    write_tum(tmp_path / "a.tum", ref)
    loaded = read_trajectory(tmp_path / "a.tum").trajectory
    assert loaded.group is SE3
    np.testing.assert_allclose(se3.to_matrix(loaded.poses), se3.to_matrix(ref.poses), atol=1e-11)
    flat = Trajectory(ref.timestamps, se2.wrap_last(np.column_stack((ref.xy, np.arange(200.0)))))
    write_tum(tmp_path / "b.tum", flat.lifted())
    back = read_trajectory(tmp_path / "b.tum").trajectory
    assert back.group is SE2
    np.testing.assert_allclose(back.poses, flat.poses, atol=1e-11)


def test_planar_projection_warns_with_the_discarded_motion(tmp_path):
    n = 50
    rpy = np.column_stack((np.linspace(0, math.radians(10), n), np.zeros(n), np.zeros(n)))
    xyz = np.column_stack((np.arange(n), np.zeros(n), np.linspace(0, 0.5, n)))
    write_tum(
        tmp_path / "a.tum",
        Trajectory(np.arange(n), np.column_stack((xyz, se3.from_euler_zyx(rpy)))),
    )
    with pytest.warns(PlanarProjectionWarning, match=r"z range 0\.5 m, \|roll\| up to 10 deg"):
        t = read_trajectory(tmp_path / "a.tum", dimension="2d").trajectory
    assert t.group is SE2 and t.poses.shape == (n, 3)


def test_kitti_reader_with_and_without_times(tmp_path):
    ref = helix(30)
    m = se3.to_matrix(ref.poses)[:, :3, :].reshape(30, 12)
    np.savetxt(tmp_path / "poses.txt", m, fmt="%.12e")
    np.savetxt(tmp_path / "times.txt", ref.timestamps + 5.0, fmt="%.6f")
    loaded = read_trajectory(tmp_path / "poses.txt", times=tmp_path / "times.txt")
    assert loaded.format == "kitti"
    np.testing.assert_allclose(loaded.trajectory.timestamps, ref.timestamps + 5.0)
    np.testing.assert_allclose(
        se3.to_matrix(loaded.trajectory.poses), se3.to_matrix(ref.poses), atol=1e-11
    )
    no_times = read_trajectory(tmp_path / "poses.txt", format="kitti").trajectory
    np.testing.assert_array_equal(no_times.timestamps, np.arange(30.0))
    np.savetxt(tmp_path / "short.txt", ref.timestamps[:5])
    with pytest.raises(InputError, match="5 timestamps for the 30 poses"):
        read_trajectory(tmp_path / "poses.txt", times=tmp_path / "short.txt")
    m[3, 0] = 2.0  # not a rotation
    np.savetxt(tmp_path / "bad.txt", m)
    with pytest.raises(InputError, match="not orthonormal") as exc:
        read_trajectory(tmp_path / "bad.txt", format="kitti")
    assert exc.value.line == 4


def test_euroc_groundtruth_csv(tmp_path):
    ref = helix(20)
    q = ref.poses[:, 3:]
    header = (
        "#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],"
        "q_RS_z [],v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1]"
    )
    ns = (1403636579758555392 + np.arange(20) * 5_000_000).astype(np.int64)
    rows = [
        ",".join([str(t)] + [f"{v:.12f}" for v in (*p[:3], qq[3], *qq[:3], 0, 0, 0)])
        for t, p, qq in zip(ns, ref.poses, q)
    ]
    (tmp_path / "data.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    loaded = read_trajectory(tmp_path / "data.csv")
    assert loaded.format == "euroc" and loaded.trajectory.group is SE3
    np.testing.assert_allclose(loaded.trajectory.timestamps, ns * 1e-9)
    np.testing.assert_allclose(
        se3.to_matrix(loaded.trajectory.poses), se3.to_matrix(ref.poses), atol=1e-11
    )


# --- relations and errors ----------------------------------------------------------------


def test_freiburg_6dof_lines_are_scored_on_se3_by_hand(tmp_path):
    # reference: 1 m forward, 0.3 m up and rolled 0.1 rad; the planar estimate only moves forward
    (tmp_path / "r.relations").write_text("0 1 1 0 0.3 0.1 0 0\n")
    rel = read_relations(tmp_path / "r.relations")
    assert rel.group is SE2 and rel.has_out_of_plane
    est = Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]])
    ev = evaluate(rel, est)
    assert ev.relations.group is SE3
    # e = δ*⁻¹ δ: translation R_x(0.1)ᵀ (0, 0, −0.3) has norm 0.3; rotation angle 0.1
    assert ev.errors.translation[0] == pytest.approx(0.3, abs=1e-12)
    assert ev.errors.rotation[0] == pytest.approx(0.1, abs=1e-12)
    me = evaluate(rel, est, mode="metricevaluator", weights="1,1,1,1,1,1")
    assert me.relations.group is SE2  # parameter difference, as the C++ tool
    assert me.errors.combined[0] == pytest.approx(math.hypot(0.3, 0.1), abs=1e-12)


def test_metricevaluator_mode_on_se3_is_the_parameter_difference(rng):
    d = np.column_stack((rng.normal(size=(10, 3)), se3.from_euler_zyx(rng.normal(0, 0.3, (10, 3)))))
    r = np.column_stack((rng.normal(size=(10, 3)), se3.from_euler_zyx(rng.normal(0, 0.3, (10, 3)))))
    from relation_metric.metric import relation_errors

    e = relation_errors(d, r, mode="metricevaluator", weights="0,0,0,1,0,0")
    roll = se3.euler_zyx(d[:, 3:])[:, 0] - se3.euler_zyx(r[:, 3:])[:, 0]
    np.testing.assert_allclose(e.combined, np.abs(se2.wrap_angle(roll)), atol=1e-12)
    p = relation_errors(d, r, mode="paper")
    err = np.linalg.inv(se3.to_matrix(r)) @ se3.to_matrix(d)
    np.testing.assert_allclose(p.translation, np.linalg.norm(err[:, :3, 3], axis=1), atol=1e-12)
    cos = np.clip((np.trace(err[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
    np.testing.assert_allclose(p.rotation, np.arccos(cos), atol=1e-7)


def test_generation_on_3d_reference_reproduces_it(tmp_path):
    ref = helix()
    for strategy in ("consecutive", "distance", "loops", "global", "random"):
        rel = generate_relations(
            ref, strategy, distance=0.5, radius=0.8, min_separation_time=5.0, count=300
        )
        assert rel.group is SE3 and len(rel) > 0, strategy
        ev = evaluate(rel, ref)
        assert ev.translation.abs.max < 1e-12 and ev.rotation.abs.max < 1e-7, strategy
    rel = generate_relations(ref, "random", count=50)
    write_relations(tmp_path / "r.relations", rel)
    back = read_relations(tmp_path / "r.relations").lifted()
    np.testing.assert_allclose(se3.to_matrix(back.delta), se3.to_matrix(rel.delta), atol=1e-8)


def test_loops_use_3d_distances():
    # the same x, y twice, 5 m apart in height: no loop in 3-D
    n = 100
    xyz = np.column_stack((np.zeros(n), np.zeros(n), np.linspace(0, 5, n)))
    xyz[: n // 2, 2] = 0.0
    xyz[n // 2 :, 2] = 5.0
    xyz[:, 0] = np.concatenate((np.linspace(0, 1, n // 2), np.linspace(0, 1, n // 2)))
    traj = Trajectory(np.arange(n) * 1.0, np.column_stack((xyz, np.tile([0, 0, 0, 1.0], (n, 1)))))
    assert len(generate_relations(traj, "loops", radius=0.5, min_separation_time=30)) == 0
    assert len(generate_relations(traj.planar(), "loops", radius=0.5, min_separation_time=30)) > 0


def test_chained_pairs_are_evos():
    ref = helix(20)
    rel = generate_relations(ref, "consecutive", step=3, chained=True, key="index")
    np.testing.assert_array_equal(rel.first, [0, 3, 6, 9, 12, 15])
    np.testing.assert_array_equal(rel.second, [3, 6, 9, 12, 15, 18])
    s = ref.path_length()
    rel = generate_relations(ref, "distance", distance=1.0, chained=True, key="index")
    i, j = rel.first.astype(int), rel.second.astype(int)
    assert i[0] == 0 and np.array_equal(i[1:], j[:-1])
    assert np.all(s[j] - s[i] >= 1.0 - 1e-12) and np.all(s[j - 1] - s[i] < 1.0)


def test_interpolation_and_odometry_on_se3():
    ref = helix(101)
    est = Trajectory(ref.timestamps[::2], ref.poses[::2])  # every other pose
    rel = RelationSet.from_trajectory_pairs(ref, np.arange(1, 99, 2), np.arange(3, 101, 2))
    ev = evaluate(rel, est, max_time_diff=0.01, interpolate=True, max_interpolation_gap=0.5)
    assert ev.association.interpolated.all()
    assert ev.translation.abs.max < 0.01  # constant-twist interpolation on a smooth helix
    ev = evaluate(rel, est, max_time_diff=0.01, odometry=ref)  # odometry = ground truth
    assert ev.association.via_odometry.all()
    assert ev.translation.abs.max < 1e-12 and ev.rotation.abs.max < 1e-7


# --- property: the SE(3) path on planar data is the SE(2) path -----------------------------


@pytest.mark.filterwarnings("ignore::relation_metric.evaluate.UnassociatedRelationsWarning")
@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**31 - 1),
    st.sampled_from(["consecutive", "random", "distance"]),
    st.sampled_from(["paper", "metricevaluator"]),
    st.booleans(),
    st.sampled_from(["nearest", "interpolate", "odometry"]),
)
def test_se3_path_on_planar_data_equals_se2_path(seed, strategy, mode, by_time, assoc):
    rng = np.random.default_rng(seed)
    n = 60
    steps = np.column_stack(
        (rng.uniform(0.1, 0.5, n - 1), rng.normal(0, 0.05, n - 1), rng.normal(0, 0.5, n - 1))
    )
    ref = Trajectory.from_poses(se2.cumulative_compose(steps), dt=0.1)
    noisy = ref.poses + rng.normal(0, [0.05, 0.05, 0.05], (n, 3))
    key = "time" if by_time or assoc != "nearest" else "index"
    # off the relation times: the ends are interpolated or corrected with odometry
    shift = 0.0 if assoc == "nearest" else 0.04
    est = Trajectory(ref.timestamps + shift, noisy)
    odo = Trajectory(ref.timestamps, ref.poses + rng.normal(0, 0.01, (n, 3)))
    rel = generate_relations(ref, strategy, count=100, distance=0.7, key=key, seed=seed)
    w = rng.uniform(0, 1, 6).round(3)
    kw = {"mode": mode, "weights": w, "max_time_diff": 0.01}
    kw |= {"interpolate": assoc == "interpolate", "max_interpolation_gap": 0.5}
    planar = evaluate(rel, est, odometry=odo if assoc == "odometry" else None, **kw)
    lifted = evaluate(
        rel.lifted(), est.lifted(), odometry=odo if assoc == "odometry" else None, **kw
    )
    if assoc == "interpolate":
        assert planar.association.interpolated.any()
    if assoc == "odometry":
        assert planar.association.via_odometry.any()
    assert planar.relations.group is SE2 and lifted.relations.group is SE3
    for part in ("translation", "rotation", "combined"):
        a, b = getattr(planar.errors, part), getattr(lifted.errors, part)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
        for k in ("abs", "sqr"):
            sa, sb = getattr(getattr(planar, part), k), getattr(getattr(lifted, part), k)
            assert sb.count == sa.count
            np.testing.assert_allclose(
                [sb.mean, sb.max, sb.rmse], [sa.mean, sa.max, sa.rmse], rtol=0, atol=1e-9
            )


# --- CLI -----------------------------------------------------------------------------------


def test_cli_scores_3d_and_planar_only_on_request(tmp_path, capsys):
    rng = np.random.default_rng(5)
    ref = helix()
    est = perturbed(ref, rng)
    write_tum(tmp_path / "gt.tum", ref)
    write_tum(tmp_path / "est.tum", est)
    out = tmp_path / "r.json"
    assert (
        main(
            [
                "evaluate",
                str(tmp_path / "gt.tum"),
                str(tmp_path / "est.tum"),
                "--json",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    res = json.loads(out.read_text())
    assert res["group"] == "SE3"
    # oracle: the SE(3) errors of consecutive relations, straight from the matrices
    m_ref, m_est = se3.to_matrix(ref.poses), se3.to_matrix(est.poses)
    d_ref = np.linalg.inv(m_ref[:-1]) @ m_ref[1:]
    d_est = np.linalg.inv(m_est[:-1]) @ m_est[1:]
    e = np.linalg.inv(d_ref) @ d_est
    trans = np.linalg.norm(e[:, :3, 3], axis=1)
    assert res["translation"]["abs"]["mean"] == pytest.approx(trans.mean(), abs=1e-12)
    capsys.readouterr()
    args = [
        "evaluate",
        str(tmp_path / "gt.tum"),
        str(tmp_path / "est.tum"),
        "--planar",
        "--json",
        str(out),
        "-q",
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(args) == 0
    err = capsys.readouterr().err
    assert "discarding its out-of-plane motion (z range 1.26 m" in err
    res = json.loads(out.read_text())
    assert res["group"] == "SE2"
    z_est = est.poses[:, 2].max() - est.poses[:, 2].min()
    assert res["planar_projection"]["estimate"]["z_range"] == pytest.approx(z_est, abs=1e-9)
    assert res["planar_projection"]["reference"]["max_abs_roll"] == pytest.approx(0.2, abs=1e-3)


def test_cli_3d_ate_evo_zip_plot_and_relations_generate(tmp_path):
    rng = np.random.default_rng(6)
    ref = helix()
    est = perturbed(ref, rng, 0.002)
    # the estimate in another frame: SE(3) alignment removes it
    offset = np.concatenate(([1.0, -2.0, 0.5], se3.from_euler_zyx([0.3, -0.2, 1.0])))
    est = Trajectory(est.timestamps, se3.compose(offset, est.poses))
    write_tum(tmp_path / "gt.tum", ref)
    write_tum(tmp_path / "est.tum", est)
    out = tmp_path / "r.json"
    args = [
        "evaluate", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"), "--ate", "-q",
        "--json", str(out), "--evo-zip", str(tmp_path / "e.zip"), "--plot", str(tmp_path / "p.png"),
    ]  # fmt: skip
    assert main(args) == 0
    ate = json.loads(out.read_text())["ate"]
    assert set(ate) == {"none", "se3", "sim3", "4dof", "origin", "affine"}
    assert ate["none"]["translation"]["rmse"] > 1.0
    assert ate["se3"]["translation"]["rmse"] < 0.01
    # nested families: the affine minimum is below the rigid one; a tilted offset is no yaw
    assert ate["affine"]["translation"]["rmse"] <= ate["se3"]["translation"]["rmse"] + 1e-12
    assert ate["4dof"]["translation"]["rmse"] > ate["se3"]["translation"]["rmse"]
    assert (tmp_path / "e.zip").stat().st_size > 0 and (tmp_path / "p.png").stat().st_size > 0
    rel_path = tmp_path / "g.relations"
    assert main(["relations", "generate", str(tmp_path / "gt.tum"), "-o", str(rel_path), "-q"]) == 0
    rel = read_relations(rel_path)
    assert rel.has_out_of_plane and len(rel) == len(ref) - 1


def test_cli_sync_needs_a_reference_trajectory_and_kitti_is_recognised(tmp_path, capsys):
    (tmp_path / "r.relations").write_text("0 1 1 0 0 0 0 0\n")
    ref = helix(30)
    write_tum(tmp_path / "est.tum", ref)
    assert (
        main(["evaluate", str(tmp_path / "r.relations"), str(tmp_path / "est.tum"), "--sync"]) == 2
    )  # an option that does not go with this input: a usage error (exit 2)
    assert "argument --sync: needs a reference trajectory" in capsys.readouterr().err
    # a KITTI pose file (12 columns, .txt) with its times file is recognised and scored in 3-D
    m = se3.to_matrix(ref.poses)[:, :3, :].reshape(30, 12)
    np.savetxt(tmp_path / "poses.txt", m, fmt="%.12e")
    np.savetxt(tmp_path / "times.txt", ref.timestamps, fmt="%.6f")
    out = tmp_path / "r.json"
    args = [
        "evaluate", str(tmp_path / "est.tum"), str(tmp_path / "poses.txt"),
        "--times", str(tmp_path / "times.txt"), "--reference-format", "tum",
        "--json", str(out), "-q",
    ]  # fmt: skip
    assert main(args) == 0
    res = json.loads(out.read_text())
    assert res["group"] == "SE3" and res["unassociated"] == 0
    assert res["translation"]["abs"]["max"] < 1e-9
