"""NEES over time of an external filter (``slamrel nees``, :func:`nees_over_time`).

Oracles: hand computations on small files (errors written down from the poses, rotations of
known axis and angle, covariances inverted by numpy), and the χ² law for a simulated
consistent filter (errors drawn from the covariances it reports, the estimate built with
scipy's Rotation, independent of slamrel's quaternion algebra).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from relation_metric.consistency import nees_over_time, pose_errors
from slamrel.cli import main
from slamrel.formats.covariances import read_pose_covariances


def _q(rot: Rotation) -> np.ndarray:
    return rot.as_quat()  # [x, y, z, w]


def _rz(a: float) -> Rotation:
    return Rotation.from_rotvec([0.0, 0.0, a])


def _rx(a: float) -> Rotation:
    return Rotation.from_rotvec([a, 0.0, 0.0])


# truth and estimate at t = 0, 1, 2 (positions; rotations)
T = np.array([0.0, 1.0, 2.0])
TRUE_P = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.5]])
TRUE_R = [Rotation.identity(), _rz(0.3), _rz(math.pi / 2)]
EST_P = np.array([[0.1, -0.2, 0.05], [1.0, 0.1, 0.0], [2.0, 1.0, 0.5]])
EST_R = [_rx(0.02), _rz(0.31), _rz(math.pi / 2) * _rx(0.03)]  # last: a body-x perturbation
COV0 = np.diag([0.01, 0.04, 0.09, 1e-4, 4e-4, 9e-4])
A = np.arange(36.0).reshape(6, 6) / 50.0
COV1 = A @ A.T + np.diag([0.02, 0.03, 0.04, 1e-3, 2e-3, 3e-3])
COV2 = np.diag([1.0, 1.0, 1.0, 1e-4, 9e-4, 4e-4])
COVS = np.stack([COV0, COV1, COV2])


def _hand_errors(frame: str) -> np.ndarray:
    """[δp, δθ] written down from the poses (see pose_errors' docstring)."""
    dp = TRUE_P - EST_P
    if frame == "parent":
        # R R̂ᵀ: t0 Rx(-0.02), t1 Rz(-0.01), t2 Rz(π/2) Rx(-0.03) Rz(-π/2) = a turn about y
        dth = np.array([[-0.02, 0, 0], [0, 0, -0.01], [0, -0.03, 0]])
        return np.column_stack((dp, dth))
    # R̂ᵀ R: t0 Rx(-0.02), t1 Rz(-0.01), t2 Rx(-0.03)
    dth = np.array([[-0.02, 0, 0], [0, 0, -0.01], [-0.03, 0, 0]])
    if frame == "openvins":
        return np.column_stack((dp, dth))
    # body: R̂ᵀ (p − p̂) with R̂ᵀ written out with cos/sin
    c, s = math.cos(0.31), math.sin(0.31)
    p1 = np.array([c * dp[1, 0] + s * dp[1, 1], -s * dp[1, 0] + c * dp[1, 1], dp[1, 2]])
    c0, s0 = math.cos(0.02), math.sin(0.02)
    p0 = np.array([dp[0, 0], c0 * dp[0, 1] + s0 * dp[0, 2], -s0 * dp[0, 1] + c0 * dp[0, 2]])
    return np.column_stack((np.stack([p0, p1, dp[2]]), dth))


def _files(tmp_path):
    ref = tmp_path / "truth.tum"
    rows = [" ".join(repr(float(x)) for x in (t, *p, *_q(r))) for t, p, r in zip(T, TRUE_P, TRUE_R)]
    ref.write_text("\n".join(rows) + "\n")
    iu = np.triu_indices(6)
    est = tmp_path / "filter.txt"
    lines = []
    for t, p, r, c in zip(T, EST_P, EST_R, COVS):
        nums = [t, *p, *_q(r), *c[iu]]
        lines.append(" ".join(repr(float(x)) for x in nums))
    est.write_text(
        "# t x y z qx qy qz qw + upper triangle of the 6x6 covariance\n" + "\n".join(lines) + "\n"
    )
    return ref, est


@pytest.mark.parametrize("frame", ["parent", "body", "openvins"])
def test_nees_by_hand(tmp_path, frame):
    ref, est = _files(tmp_path)
    e = _hand_errors(frame)
    expect = np.array([e[k] @ np.linalg.inv(COVS[k]) @ e[k] for k in range(3)])
    if frame == "parent":  # the diagonal first row by hand: 1 + 1 + 0.0025/0.09 + 4
        assert expect[0] == pytest.approx(6 + 0.0025 / 0.09, rel=1e-9)
    csv, j = tmp_path / "nees.csv", tmp_path / "nees.json"
    args = [
        "nees",
        str(ref),
        str(est),
        "--error-frame",
        frame,
        "--csv",
        str(csv),
        "--json",
        str(j),
        "-q",
    ]
    assert main(args) == 0
    got = np.loadtxt(csv, delimiter=",", skiprows=1)
    np.testing.assert_allclose(got[:, 1], expect, rtol=1e-6)
    # the parts: position and orientation NEES from the marginal blocks
    pos = [e[k, :3] @ np.linalg.inv(COVS[k][:3, :3]) @ e[k, :3] for k in range(3)]
    ori = [e[k, 3:] @ np.linalg.inv(COVS[k][3:, 3:]) @ e[k, 3:] for k in range(3)]
    np.testing.assert_allclose(got[:, 2], pos, rtol=1e-6)
    np.testing.assert_allclose(got[:, 3], ori, rtol=1e-6)
    res = json.loads(j.read_text())
    assert res["layout"] == "tum-cov" and res["error_frame"] == frame and res["matched"] == 3
    assert res["nees"]["mean"] == pytest.approx(expect.mean(), rel=1e-6)


def test_openvins_layout_by_hand(tmp_path):
    """ov_eval's 20 columns: orientation triangle first, then position; its error frame."""
    ref, _ = _files(tmp_path)
    est = tmp_path / "ov.txt"
    iu = np.triu_indices(3)
    lines = []
    for t, p, r, c in zip(T, EST_P, EST_R, COVS):
        nums = [t, *p, *_q(r), *c[3:, 3:][iu], *c[:3, :3][iu]]
        lines.append(" ".join(repr(float(x)) for x in nums))
    est.write_text("\n".join(lines) + "\n")
    loaded = read_pose_covariances(est)
    assert loaded.layout == "openvins"
    csv = tmp_path / "ov.csv"
    assert main(["nees", str(ref), str(est), "--csv", str(csv), "-q"]) == 0
    got = np.loadtxt(csv, delimiter=",", skiprows=1)
    e = _hand_errors("openvins")
    pos = [e[k, :3] @ np.linalg.inv(COVS[k][:3, :3]) @ e[k, :3] for k in range(3)]
    ori = [e[k, 3:] @ np.linalg.inv(COVS[k][3:, 3:]) @ e[k, 3:] for k in range(3)]
    np.testing.assert_allclose(got[:, 2], pos, rtol=1e-6)  # ov_eval's position NEES
    np.testing.assert_allclose(got[:, 3], ori, rtol=1e-6)  # ov_eval's orientation NEES
    np.testing.assert_allclose(got[:, 1], np.add(pos, ori), rtol=1e-6)  # no cross terms
    # t = 2: a body-x error of 0.03 rad with σ_rx = 0.01: orientation NEES 9 (parent would say 1)
    assert ori[2] == pytest.approx(9.0, rel=1e-6)


def test_se2_by_hand(tmp_path):
    ref = tmp_path / "truth.txt"
    ref.write_text("0 1 2 0.5\n1 2 2 3.1\n")
    est = tmp_path / "est.txt"  # t x y θ xx xy xθ yy yθ θθ
    est.write_text("0 1.1 1.9 0.45 0.01 0 0 0.04 0 0.0025\n1 2 2 -3.1 1 0 0 1 0 0.01\n")
    csv = tmp_path / "n.csv"
    assert main(["nees", str(ref), str(est), "--csv", str(csv), "-q"]) == 0
    got = np.loadtxt(csv, delimiter=",", skiprows=1)
    # 0.1²/0.01 + 0.1²/0.04 + 0.05²/0.0025 = 1 + 0.25 + 1; then the heading wraps: 2π − 6.2
    wrapped = 3.1 - (-3.1) - 2 * math.pi
    np.testing.assert_allclose(got[:, 1], [2.25, wrapped**2 / 0.01], rtol=1e-9)


def _simulate(rng, n, scale_reported=1.0, frame="parent"):
    """A consistent filter: errors drawn from its covariances; the estimate built from them."""
    t = np.arange(n) * 0.1
    truth_r = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.2, (n, 3)), axis=0))
    truth_p = np.cumsum(rng.normal(0, 0.5, (n, 3)), axis=0)
    a = rng.normal(size=(n, 6, 6)) * np.array([0.2, 0.2, 0.2, 0.02, 0.02, 0.02])[:, None]
    cov = np.einsum("nij,nkj->nik", a, a) + np.diag([1e-3] * 3 + [1e-5] * 3)
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 6)))
    if frame == "parent":  # p = p̂ + δp, R = Exp(δθ) R̂
        est_r = Rotation.from_rotvec(-e[:, 3:]) * truth_r
        est_p = truth_p - e[:, :3]
    else:  # body: p = p̂ + R̂ δp, R = R̂ Exp(δθ)
        est_r = truth_r * Rotation.from_rotvec(-e[:, 3:])
        est_p = truth_p - est_r.apply(e[:, :3])
    est = np.column_stack((est_p, est_r.as_quat()))
    tru = np.column_stack((truth_p, truth_r.as_quat()))
    return t, est, tru, cov * scale_reported, e


@pytest.mark.parametrize("frame", ["parent", "body"])
def test_consistent_filter_lies_in_its_band(rng, frame):
    t, est, tru, cov, e = _simulate(rng, 3000, frame=frame)
    np.testing.assert_allclose(pose_errors(est, tru, frame), e, atol=1e-9)
    r = nees_over_time(t, est, tru, cov, frame=frame)
    assert r.dof == 6 and r.band == pytest.approx((1.2373, 14.4494), abs=1e-3)  # χ²(6) 2.5/97.5%
    assert 0.93 <= r.inside <= 0.97
    assert r.consistent and r.mean_band[0] < 6 < r.mean_band[1]
    # over-confident (reports a quarter of its covariance): NEES ×4, far outside
    bad = nees_over_time(t, est, tru, cov / 4, frame=frame)
    assert not bad.consistent and bad.mean == pytest.approx(4 * r.mean, rel=1e-9)
    assert bad.inside < 0.6


def test_bag_topic_equals_the_text_file(tmp_path, rng):
    """A PoseWithCovarianceStamped topic and the same values as tum-cov give the same NEES."""
    rosbags = pytest.importorskip("rosbags", reason="rosbags not installed")
    del rosbags
    from test_bags import _truth, _write

    truth = _truth(rng)
    bag = _write(tmp_path / "f.bag", "ros1", truth)
    stamps = truth["sec"] + truth["nsec"] * 1e-9
    ref = tmp_path / "ref.tum"
    shift = np.array([0.05, -0.02, 0.01])
    ref.write_text(
        "".join(
            f"{repr(float(t))} {' '.join(repr(float(v)) for v in (*(p + shift), *q))}\n"
            for t, p, q in zip(stamps, truth["xyz"], truth["q"])
        )
    )
    iu = np.triu_indices(6)
    txt = tmp_path / "f.txt"
    txt.write_text(
        "".join(
            " ".join(repr(float(v)) for v in (t, *p, *q, *c[iu])) + "\n"
            for t, p, q, c in zip(stamps, truth["xyz"], truth["q"], truth["cov"])
        )
    )
    out = {}
    for name, src in (("bag", f"{bag}:/posecov"), ("odom", f"{bag}:/odom"), ("txt", str(txt))):
        j = tmp_path / f"{name}.json"
        assert main(["nees", str(ref), src, "--json", str(j), "-q"]) == 0
        out[name] = json.loads(j.read_text())
    # the truth is the estimate shifted: δθ = 0, δp = shift
    expect = [shift @ np.linalg.inv(c[:3, :3]) @ shift for c in truth["cov"]]
    expect_full = [
        np.r_[shift, 0, 0, 0] @ np.linalg.inv(c) @ np.r_[shift, 0, 0, 0] for c in truth["cov"]
    ]
    for name in out:
        assert out[name]["nees"]["mean"] == pytest.approx(np.mean(expect_full), rel=1e-9), name
        assert out[name]["position"]["mean"] == pytest.approx(np.mean(expect), rel=1e-9), name
    assert out["bag"]["layout"] == "bag" and out["txt"]["layout"] == "tum-cov"
    # a PoseStamped topic carries no covariance: refused (exit 3)
    assert main(["nees", str(ref), f"{bag}:/pose", "-q"]) == 3


def test_bad_covariance_files(tmp_path, capsys):
    ref, est = _files(tmp_path)
    lines = est.read_text().splitlines()
    nums = lines[2].split()
    nums[8] = "-1"  # c11 < 0: not positive definite
    bad = tmp_path / "bad.txt"
    bad.write_text("\n".join([*lines[:2], " ".join(nums), *lines[3:]]) + "\n")
    assert main(["nees", str(ref), str(bad), "-q"]) == 3
    assert f"{bad}:3: covariance: expected a positive definite" in capsys.readouterr().err
    short = tmp_path / "short.txt"
    short.write_text("0 1 2 3 4 5\n")
    assert main(["nees", str(ref), str(short), "-q"]) == 3
    assert "cannot tell the layout from 6 columns" in capsys.readouterr().err
    far = tmp_path / "far.tum"
    far.write_text("100 0 0 0 0 0 0 1\n101 0 0 0 0 0 0 1\n")
    assert main(["nees", str(far), str(est), "-q"]) == 3
    assert "no estimate time lies within 0.01 s of a reference pose" in capsys.readouterr().err


def test_figure_is_written(tmp_path, rng):
    pytest.importorskip("matplotlib")
    t, est, tru, cov, _ = _simulate(rng, 50)
    ref, f = tmp_path / "ref.tum", tmp_path / "f.txt"
    iu = np.triu_indices(6)
    ref.write_text(
        "".join(" ".join(map(repr, (tk, *row))) + "\n" for tk, row in zip(t.tolist(), tru.tolist()))
    )
    f.write_text(
        "".join(
            " ".join(map(repr, (tk, *row, *c[iu].tolist()))) + "\n"
            for tk, row, c in zip(t.tolist(), est.tolist(), cov)
        )
    )
    png = tmp_path / "nees.png"
    assert main(["nees", str(ref), str(f), "--plot", str(png), "-q"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _write_run(path, t, est, cov, skip=()):
    iu = np.triu_indices(6)
    path.write_text(
        "".join(
            " ".join(map(repr, (tk, *row, *c[iu].tolist()))) + "\n"
            for k, (tk, row, c) in enumerate(zip(t.tolist(), est.tolist(), cov))
            if k not in skip
        )
    )


def test_monte_carlo_runs_average_in_their_band(tmp_path, rng):
    from scipy.stats import chi2

    runs, n = 20, 300
    t, _, tru, _, _ = _simulate(rng, n)
    ests, covs = [], []
    for _ in range(runs):  # the same truth, a fresh consistent filter each run
        _, est, tru_r, cov, e = _simulate(rng, n)
        # move this run's errors onto the common truth: same error, same covariance
        r_true = Rotation.from_quat(tru[:, 3:])
        est_r = Rotation.from_rotvec(-e[:, 3:]) * r_true
        ests.append(np.column_stack((tru[:, :3] - e[:, :3], est_r.as_quat())))
        covs.append(cov)
    r = nees_over_time(t, np.stack(ests), tru, np.stack(covs))
    lo, hi = chi2.ppf([0.025, 0.975], runs * 6) / runs
    assert r.runs == runs and r.band == pytest.approx((lo, hi), rel=1e-9)
    singles = [nees_over_time(t, ests[k], tru, covs[k]).nees for k in range(runs)]
    np.testing.assert_allclose(r.nees, np.mean(singles, axis=0), rtol=1e-12)
    assert 0.9 <= r.inside <= 0.99 and r.consistent
    # through the command: three runs in files, one missing a pose
    ref = tmp_path / "ref.tum"
    ref.write_text(
        "".join(" ".join(map(repr, (tk, *row))) + "\n" for tk, row in zip(t.tolist(), tru.tolist()))
    )
    paths = []
    for k in range(3):
        f = tmp_path / f"run{k}.txt"
        _write_run(f, t, ests[k], covs[k], skip=(7,) if k == 1 else ())
        paths.append(str(f))
    j = tmp_path / "mc.json"
    assert main(["nees", str(ref), *paths, "--json", str(j), "-q"]) == 0
    res = json.loads(j.read_text())
    assert res["runs"] == 3 and res["matched"] == n - 1 and res["left_out"] == [1, 0, 1]
    keep = np.delete(np.arange(n), 7)
    expect = np.mean([singles[k][keep] for k in range(3)])
    assert res["nees"]["mean"] == pytest.approx(expect, rel=1e-9)
    assert res["nees"]["band"] == pytest.approx(list(chi2.ppf([0.025, 0.975], 18) / 3), rel=1e-9)
