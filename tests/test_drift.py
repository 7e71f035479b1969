"""KITTI drift, RPE by seconds, per-axis errors, affine / 4-DoF / origin / first-N alignment,
time offset and window: each against an independent oracle (a literal port of the KITTI
devkit's loop, trajectopy's stored numbers, TUM's pair loop, brute force, closed forms)."""

from __future__ import annotations

import bisect
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares, minimize_scalar

from relation_metric import se3
from relation_metric.alignment import (
    absolute_trajectory_error,
    affine_fit,
    umeyama,
    umeyama_yaw,
)
from relation_metric.drift import kitti_drift
from relation_metric.relations import generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kitti_sim  # noqa: E402

# trajectopy 5.1.2's RPE over 100..800 m on kitti_sim.drive() (benchmarks/trajectopy_reference.py,
# run in benchmarks/.venv-trajectopy): per length, segments and the mean unnormalised errors
# ‖t(E)‖ [m] and angle(R(E)) [rad].
TRAJECTOPY = [
    (100.0, 1188, 0.46048035093794487, 0.0037948744704953442),
    (200.0, 1077, 0.9416306994718344, 0.005550344309203151),
    (300.0, 966, 1.463416142416852, 0.0066899179069398775),
    (400.0, 855, 2.0611015246617446, 0.007674704625388234),
    (500.0, 744, 2.7839127337524703, 0.009391015674796084),
    (600.0, 633, 3.630373428408992, 0.01119395293699082),
    (700.0, 522, 4.543097440700831, 0.012955700650477955),
    (800.0, 411, 5.332128169931907, 0.013688412342344802),
]


@pytest.fixture(scope="module")
def drive():
    return kitti_sim.drive()


def _devkit(gt: np.ndarray, est: np.ndarray) -> tuple[float, float, dict[float, int]]:
    """A literal port of evaluate_odometry.cpp's calcSequenceErrors on 4x4 matrices."""
    lengths = [100, 200, 300, 400, 500, 600, 700, 800]
    dist = [0.0]
    for i in range(1, len(gt)):
        dist.append(dist[i - 1] + float(np.linalg.norm(gt[i - 1][:3, 3] - gt[i][:3, 3])))
    errs, counts = [], dict.fromkeys(map(float, lengths), 0)
    for first in range(0, len(gt), 10):
        for length in lengths:
            last = next((i for i in range(first, len(dist)) if dist[i] > dist[first] + length), -1)
            if last == -1:
                continue
            d_gt = np.linalg.inv(gt[first]) @ gt[last]
            d_res = np.linalg.inv(est[first]) @ est[last]
            e = np.linalg.inv(d_res) @ d_gt
            r = math.acos(max(min(0.5 * (e[0, 0] + e[1, 1] + e[2, 2] - 1.0), 1.0), -1.0))
            errs.append((r / length, float(np.linalg.norm(e[:3, 3])) / length))
            counts[float(length)] += 1
    r_avg = sum(e[0] for e in errs) / len(errs)
    t_avg = sum(e[1] for e in errs) / len(errs)
    return 100.0 * t_avg, math.degrees(r_avg), counts


def test_kitti_drift_matches_trajectopy_segments(drive):
    gt, est = drive
    d = kitti_drift(se3.from_matrix(gt), se3.from_matrix(est), step=1)
    for (length, count, mean_t, mean_r), row in zip(TRAJECTOPY, d.per_length, strict=True):
        sel = d.segment_length == length
        assert row.length == length and row.count == count
        assert np.mean(d.translation[sel] * length) == pytest.approx(mean_t, rel=1e-9)
        assert np.mean(d.rotation[sel] * length) == pytest.approx(mean_r, rel=1e-8)


def test_kitti_drift_cli_equals_devkit_port(drive, tmp_path):
    gt, est = drive
    kitti_sim.write_kitti(tmp_path / "gt.txt", gt)
    kitti_sim.write_kitti(tmp_path / "est.txt", est)
    out = tmp_path / "m.json"
    args = ["evaluate", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt"), "--kitti-drift"]
    assert main([*args, "--json", str(out), "-q"]) == 0
    got = json.loads(out.read_text())["kitti_drift"]
    t_pct, r_deg, counts = _devkit(gt, est)
    assert got["translation_percent"] == pytest.approx(t_pct, rel=1e-9)
    assert got["rotation_deg_per_m"] == pytest.approx(r_deg, rel=1e-7)
    assert {r["length_m"]: r["count"] for r in got["per_length"]} == counts
    assert got["segments"] == sum(counts.values()) and got["pairs"] == len(gt)


def test_kitti_drift_of_a_scaled_straight_line_is_its_scale_error():
    # 1 m a frame along z; the estimate 1 % longer: every segment is 1 % off, no rotation
    n = 1000
    gt = np.zeros((n, 7))
    gt[:, 2], gt[:, 6] = np.arange(n), 1.0
    est = gt.copy()
    est[:, 2] *= 1.01
    d = kitti_drift(gt, est)
    # the segment of L ends at the first frame strictly beyond L: L + 1 frames of 1 m
    assert d.translation_percent == pytest.approx(
        100 * 0.01 * np.mean((d.segment_length + 1) / d.segment_length), rel=1e-12
    )
    assert d.rotation_deg_per_m == 0.0
    assert d.per_length[-1].count == len(range(0, n - 801, 10))


def test_kitti_drift_refuses_a_short_path(tmp_path, capsys):
    gt = np.tile(np.eye(4), (50, 1, 1))
    gt[:, 2, 3] = np.arange(50)
    kitti_sim.write_kitti(tmp_path / "gt.txt", gt)
    code = main(["evaluate", str(tmp_path / "gt.txt"), str(tmp_path / "gt.txt"), "--kitti-drift"])
    assert code == 3
    assert "shorter than the shortest segment" in capsys.readouterr().err


def _tum_closest(stamps: list[float], t: float) -> int:
    i = bisect.bisect_left(stamps, t)
    if i == 0:
        return 0
    if i == len(stamps):
        return len(stamps) - 1
    return i - 1 if abs(stamps[i - 1] - t) <= abs(stamps[i] - t) else i


def test_rpe_by_seconds_is_tums_pair_rule():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.02, 0.08, 400))
    poses = np.column_stack((np.cos(t), np.sin(t), t))
    rel = generate_relations(Trajectory(t, poses), "time", seconds=1.5, key="index")
    stamps = list(t)
    expect = []
    for i in range(len(stamps)):  # evaluate_rpe.py, fixed delta in seconds
        j = _tum_closest(stamps, stamps[i] + 1.5)
        if j != len(stamps) - 1 and j != i:
            expect.append((i, j))
    assert list(zip(rel.first.astype(int), rel.second.astype(int), strict=True)) == expect


def _brute_affine(x: np.ndarray, y: np.ndarray) -> float:
    d = x.shape[1]

    def resid(p):
        return (y - (x @ p[: d * d].reshape(d, d).T + p[d * d :])).ravel()

    return float(np.sum(least_squares(resid, np.r_[np.eye(d).ravel(), np.zeros(d)]).fun ** 2))


def test_affine_fit_is_the_least_squares_minimum():
    rng = np.random.default_rng(11)
    x = rng.normal(size=(60, 3))
    a_true = np.array([[1.2, 0.3, 0.0], [-0.1, 0.8, 0.2], [0.05, 0.0, 1.5]])
    y = x @ a_true.T + [1.0, -2.0, 0.5] + rng.normal(0, 0.05, (60, 3))
    af = affine_fit(x, y)
    ours = float(np.sum((y - af.apply_points(x)) ** 2))
    assert ours == pytest.approx(_brute_affine(x, y), rel=1e-9)
    # nested families: affine ≤ similarity ≤ rigid
    sim = umeyama(x, y, with_scale=True)
    rig = umeyama(x, y)

    def cost(al):
        return float(np.sum((y - (al.scale * x @ al.rotation.T + al.translation)) ** 2))

    assert ours <= cost(sim) + 1e-12 <= cost(rig) + 2e-12
    # an exact affine image is rescued to zero
    assert np.allclose(affine_fit(x, x @ a_true.T + 3.0).apply_points(x), x @ a_true.T + 3.0)


def test_affine_of_a_planar_path_is_rank_deficient_but_minimal():
    rng = np.random.default_rng(5)
    x = np.column_stack((rng.normal(size=(40, 2)), np.zeros(40)))
    y = x + rng.normal(0, 0.1, (40, 3))
    af = affine_fit(x, y)
    assert af.rank == 2
    assert float(np.sum((y - af.apply_points(x)) ** 2)) == pytest.approx(
        _brute_affine(x, y), rel=1e-7
    )


def test_four_dof_alignment_against_brute_force():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(80, 3)) * [5, 5, 1]
    psi = 0.9
    c, s = math.cos(psi), math.sin(psi)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    # a tilt that no yaw can undo: left over in the residual
    tilt = se3.to_matrix(np.r_[0, 0, 0, se3.from_euler_zyx([0.05, -0.03, 0.0])])[:3, :3]
    y = x @ (tilt @ rz).T + [3, -1, 2] + rng.normal(0, 0.02, x.shape)

    def cost_at(angle):  # the best translation for a yaw is the centroid difference
        cc, ss = math.cos(angle), math.sin(angle)
        r = np.array([[cc, -ss, 0], [ss, cc, 0], [0, 0, 1]])
        moved = x @ r.T
        return float(np.sum((y - moved - (y.mean(0) - moved.mean(0))) ** 2))

    best = minimize_scalar(
        cost_at, bounds=(psi - 0.5, psi + 0.5), method="bounded", options={"xatol": 1e-12}
    )
    al = umeyama_yaw(x, y)
    got = float(np.sum((y - (x @ al.rotation.T + al.translation)) ** 2))
    assert got == pytest.approx(best.fun, rel=1e-9)
    assert math.atan2(al.rotation[1, 0], al.rotation[0, 0]) == pytest.approx(best.x, abs=1e-6)
    assert np.allclose(al.rotation[2], [0, 0, 1]) and al.scale == 1.0


def _traj3(rng, n=100):
    t = np.arange(n) * 0.1
    rpy = np.column_stack((0.1 * np.sin(t), 0.05 * np.cos(t), t * 0.3))
    p = np.column_stack((np.cos(t) * 10, np.sin(t) * 10, 0.2 * t, se3.from_euler_zyx(rpy)))
    return Trajectory(t, p)


def test_origin_first_n_and_axes():
    rng = np.random.default_rng(4)
    ref = _traj3(rng)
    offset = np.r_[1.0, 2.0, -0.5, se3.from_euler_zyx([0.02, 0.01, 0.7])]
    noisy = ref.poses.copy()
    noisy[:, :3] += rng.normal(0, 0.05, (len(ref), 3))
    est = Trajectory(ref.timestamps, se3.compose(se3.inverse(offset), noisy))
    r = absolute_trajectory_error(est, ref, align="origin")
    # origin: X_ref,0 ∘ X_est,0⁻¹ moves the first pose onto the first pose exactly
    assert r.translation[0] < 1e-9 and r.rotation[0] < 1e-7
    # first N: the Umeyama fit of the first 10 matched positions, applied to all
    r10 = absolute_trajectory_error(est, ref, align="se3", n_to_align=10)
    al = umeyama(est.poses[:10, :3], ref.poses[:10, :3])
    moved = est.poses[:, :3] @ al.rotation.T + al.translation
    np.testing.assert_allclose(
        r10.translation, np.linalg.norm(ref.poses[:, :3] - moved, axis=1), atol=1e-9
    )
    assert r10.aligned_on == 10
    # per axis: the components of p_ref − A(p_est), in-plane and height
    res = ref.poses[:, :3] - moved
    s = r10.axes.summaries()
    assert s["x"].rmse == pytest.approx(np.sqrt(np.mean(res[:, 0] ** 2)), rel=1e-9)
    assert s["in_plane"].mean == pytest.approx(np.mean(np.hypot(res[:, 0], res[:, 1])), rel=1e-9)
    assert s["height"].max == pytest.approx(np.abs(res[:, 2]).max(), rel=1e-9)


def _write_tum(path, traj):
    np.savetxt(path, np.column_stack((traj.timestamps, traj.poses)), fmt="%.9f")


def test_time_offset_and_window_equal_cutting_the_files(tmp_path):
    rng = np.random.default_rng(9)
    ref = _traj3(rng, 200)
    est_p = ref.poses.copy()
    est_p[:, :3] += rng.normal(0, 0.03, (200, 3))
    _write_tum(tmp_path / "ref.tum", ref)
    _write_tum(tmp_path / "shifted.tum", Trajectory(ref.timestamps + 0.25, est_p))
    _write_tum(tmp_path / "est.tum", Trajectory(ref.timestamps, est_p))
    keep = (ref.timestamps >= 3.0) & (ref.timestamps <= 15.0)
    _write_tum(tmp_path / "ref_cut.tum", Trajectory(ref.timestamps[keep], ref.poses[keep]))
    _write_tum(tmp_path / "est_cut.tum", Trajectory(ref.timestamps[keep], est_p[keep]))

    def score(r, e, *extra):
        out = tmp_path / "o.json"
        assert (
            main(
                [
                    "evaluate",
                    str(tmp_path / r),
                    str(tmp_path / e),
                    "--ate",
                    "--json",
                    str(out),
                    "-q",
                    "--max-time-diff",
                    "0.01",
                    *extra,
                ]
            )
            == 0
        )
        res = json.loads(out.read_text())
        return res["translation"]["abs"], res["ate"]["se3"]["translation"], res

    plain = score("ref.tum", "est.tum")
    shifted = score("ref.tum", "shifted.tum", "--t-offset", "-0.25")
    for a, b in zip(shifted[:2], plain[:2], strict=True):
        assert a == pytest.approx(b, rel=1e-9)
    cut = score("ref_cut.tum", "est_cut.tum")
    windowed = score("ref.tum", "est.tum", "--t-start", "3", "--t-end", "15")
    assert windowed[:2] == cut[:2]
    assert windowed[2]["time_window_dropped"] == {
        "reference": int((~keep).sum()),
        "estimate": int((~keep).sum()),
    }


def test_window_refusals(tmp_path, capsys):
    ref = _traj3(np.random.default_rng(1), 50)
    _write_tum(tmp_path / "ref.tum", ref)
    args = ["evaluate", str(tmp_path / "ref.tum"), str(tmp_path / "ref.tum")]
    assert main([*args, "--t-start", "5", "--t-end", "1"]) == 2
    assert main([*args, "--t-start", "100"]) == 3
    assert "time window" in capsys.readouterr().err


def _planar_tum(path, t, xy):
    """A 3-D TUM file of a planar path (heading along the path)."""
    th = np.unwrap(np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0])))
    q = np.column_stack((np.zeros((len(t), 2)), np.sin(th / 2), np.cos(th / 2)))
    z = 0.01 * np.sin(t)  # off the plane: read as SE(3)
    np.savetxt(path, np.column_stack((t, xy, z, q)), fmt="%.9f")


def test_pairs_from_estimate_are_chosen_on_the_estimates_path(tmp_path):
    t = np.arange(300) * 0.1
    xy = np.column_stack((5 * np.cos(t / 5), 5 * np.sin(t / 5)))
    est_xy = 1.3 * xy + np.random.default_rng(0).normal(0, 0.01, xy.shape)  # longer path
    _planar_tum(tmp_path / "ref.tum", t, xy)
    _planar_tum(tmp_path / "est.tum", t, est_xy)
    per = tmp_path / "per.csv"
    base = [
        "evaluate",
        str(tmp_path / "ref.tum"),
        str(tmp_path / "est.tum"),
        "--sync",
        "--max-time-diff",
        "0.01",
        "--strategy",
        "distance",
        "--distance",
        "2",
        "-q",
    ]
    assert main([*base, "--pairs-from", "estimate", "--per-relation", str(per)]) == 0
    rows = np.genfromtxt(per, delimiter=",", names=True)
    est = np.loadtxt(tmp_path / "est.tum")[:, 1:4]
    s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(est, axis=0), axis=1))))
    expect = []
    for i in range(len(s)):  # evo's rule: the first pose at least 2 m further on the estimate
        j = next((k for k in range(i, len(s)) if s[k] >= s[i] + 2.0), None)
        if j is not None:
            expect.append((t[i], t[j]))
    np.testing.assert_allclose(np.column_stack((rows["t1"], rows["t2"])), expect, atol=1e-9)
    # on the reference (the default), whose path is shorter, 2 m takes more poses: fewer pairs
    assert main([*base, "--per-relation", str(per)]) == 0
    assert len(np.genfromtxt(per, delimiter=",", names=True)) < len(expect)


def test_pairs_from_estimate_needs_sync(tmp_path, capsys):
    t = np.arange(50) * 0.1
    _planar_tum(tmp_path / "ref.tum", t, np.column_stack((t, t**2 / 10)))
    args = ["evaluate", str(tmp_path / "ref.tum"), str(tmp_path / "ref.tum")]
    assert main([*args, "--pairs-from", "estimate"]) == 2
    assert "--sync" in capsys.readouterr().err


def test_denser_reference_and_tolerance_are_warned_about(tmp_path, capsys):
    t_ref = np.arange(2000) * 0.005  # 200 Hz, as EuRoC's ground truth
    t_est = np.arange(100) * 0.1  # 10 Hz
    path = lambda t: np.column_stack((np.cos(t), np.sin(t)))  # noqa: E731
    _planar_tum(tmp_path / "ref.tum", t_ref, path(t_ref))
    _planar_tum(tmp_path / "est.tum", t_est, path(t_est))
    args = ["evaluate", str(tmp_path / "ref.tum"), str(tmp_path / "est.tum"), "-q"]
    assert main(args) == 0
    assert "200 poses/s, the estimate 10 (20x denser)" in capsys.readouterr().err
    assert main([*args, "--sync"]) == 0
    err = capsys.readouterr().err
    assert "evo's default t_max_diff is 0.01 s" in err and "denser" not in err
    assert main([*args, "--sync", "--max-time-diff", "0.01"]) == 0  # evo's settings: silent
    assert "warning" not in capsys.readouterr().err


def test_evaluate_help_has_evo_equivalents_and_the_real_strategy_default(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = capsys.readouterr().out
    assert "evo equivalents" in text and "--pairs-from estimate" in text
    assert "default: None" not in text and "(default: consecutive)" in text


def test_plot_plane_auto_and_named():
    from slamrel.plots.relation_errors import plot_plane

    gt, _ = kitti_sim.drive()
    kitti = gt[:, :3, 3]  # camera frame: x right, y down, z forward; the drive lies in x-z
    assert plot_plane("auto", kitti) == (0, 2, 1)
    z_up = kitti[:, [0, 2, 1]]
    assert plot_plane("auto", z_up) == (0, 1, 2)
    assert plot_plane("zy", kitti) == (2, 1, 0)
    assert plot_plane("auto", kitti[:, :2]) == (0, 1, None)
    with pytest.raises(ValueError, match="needs 3-D"):
        plot_plane("xz", kitti[:, :2])


def test_plot_mode_draws_the_chosen_plane_and_the_reference(tmp_path):
    from slamrel.evaluation import score_files
    from slamrel.evaluation_options import EvaluateOptions
    from slamrel.plots.relation_errors import evaluation_figure, plot_plane, pyplot

    gt, est = kitti_sim.drive(frames=300)
    kitti_sim.write_kitti(tmp_path / "gt.txt", gt)
    kitti_sim.write_kitti(tmp_path / "est.txt", est)
    scored = score_files(tmp_path / "gt.txt", tmp_path / "est.txt", EvaluateOptions())
    fig = evaluation_figure(
        scored.evaluation, scored.estimate, plot_mode="auto", reference=scored.reference
    )
    ax = fig.axes[1]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    np.testing.assert_allclose(lines["reference (as given)"].get_xydata(), gt[:, :3, 3][:, [0, 2]])
    np.testing.assert_allclose(lines["estimate"].get_xydata(), est[:, :3, 3][:, [0, 2]], atol=1e-9)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [m]", "z [m]")
    assert any(a.get_ylabel() == "y [m]" for a in fig.axes)  # the remaining axis over time
    pyplot().close(fig)
    out = tmp_path / "f.png"
    assert (
        main(
            [
                "evaluate",
                str(tmp_path / "gt.txt"),
                str(tmp_path / "est.txt"),
                "--plot",
                str(out),
                "--plot-mode",
                "xy",
                "-q",
            ]
        )
        == 0
    )
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fig = evaluation_figure(
        scored.evaluation, scored.estimate, plot_mode="xyz", reference=scored.reference
    )
    ax3 = next(a for a in fig.axes if a.name == "3d")
    ref_line = next(ln for ln in ax3.get_lines() if ln.get_label() == "reference (as given)")
    np.testing.assert_allclose(np.column_stack(ref_line.get_data_3d()), gt[:, :3, 3])
    pyplot().close(fig)
    planar = ["evaluate", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt"), "--planar"]
    assert main([*planar, "--plot", str(tmp_path / "g.png"), "--plot-mode", "xz", "-q"]) == 2
    assert not (tmp_path / "g.png").exists()
    with pytest.raises(ValueError, match="3-D view"):
        plot_plane("xyz", gt[:, :3, 3])


def test_relation_axes_by_hand(tmp_path, capsys):
    # straight along x, heading 0; the estimate drifts 0.1 m sideways a step: every
    # consecutive relation is off by e = (0, 0.1) in its own frame
    t = np.arange(30.0)
    ref = np.column_stack((t, t, np.zeros(30), np.zeros(30)))
    est = ref.copy()
    est[:, 2] = 0.1 * t
    est[:, 3] = 0.0
    np.savetxt(tmp_path / "ref.txt", ref, fmt="%.9f")
    np.savetxt(tmp_path / "est.txt", est, fmt="%.9f")
    out = tmp_path / "a.json"
    args = ["evaluate", str(tmp_path / "ref.txt"), str(tmp_path / "est.txt"), "--axes"]
    assert main([*args, "--json", str(out)]) == 0
    axes = json.loads(out.read_text())["relation_axes"]
    assert set(axes) == {"x", "y", "in_plane"}
    assert axes["x"]["max"] == pytest.approx(0.0, abs=1e-12)
    assert axes["y"]["mean"] == pytest.approx(0.1, abs=1e-12) and axes["y"]["count"] == 29
    assert axes["in_plane"]["rmse"] == pytest.approx(0.1, abs=1e-12)
    assert "|e_y| [m]" in capsys.readouterr().out
