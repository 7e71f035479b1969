"""``slamrel ape`` / ``slamrel rpe`` against evo's ``evo_ape`` / ``evo_rpe``, to 1e-9 relative.

The oracle is evo itself: its command-line programs, run live from a side venv
(``benchmarks/.venv-evo``; created by the session fixture with ``python -m venv`` and ``pip
install evo`` when it does not exist, which takes a minute: the tests that need it are
``slow``). Both programs write their result zip (``--save_results``); every statistic of
``stats.json`` and every value of ``error_array.npy`` must agree to 1e-9 relative, with the
same count. The inputs are the TUM RGB-D sequences and the ROS 1 bag of ``../shared/data``
and files this module generates with a seeded generator (KITTI poses written with 17
digits, an EuRoC ground-truth CSV and its TUM estimate).

The fast test checks a few cases against numbers evo 1.38.1 printed (:data:`EVO`), so the
default tier guards the definitions without evo installed.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, require_data

from slamrel.cli import main

TOL = 1e-9
EVO_VENV = ROOT / "benchmarks" / ".venv-evo"

# (name, metric, kind, inputs, options): inputs are keys of the `inputs` fixture
CASES = [
    ("ape/none", "ape", "tum", "fr1", []),
    ("ape/a", "ape", "tum", "fr2", ["-a"]),
    ("ape/as", "ape", "tum", "fr2", ["-as"]),
    ("ape/s", "ape", "tum", "fr1", ["-s"]),
    ("ape/origin", "ape", "tum", "fr1", ["--align_origin"]),
    ("ape/n_to_align", "ape", "tum", "fr1", ["-a", "--n_to_align", "100"]),
    ("ape/angle_deg", "ape", "tum", "fr2", ["-a", "-r", "angle_deg"]),
    ("ape/angle_rad", "ape", "tum", "fr1", ["-r", "angle_rad"]),
    ("ape/full", "ape", "tum", "fr1", ["-a", "-r", "full"]),
    ("ape/rot_part", "ape", "tum", "fr2", ["-r", "rot_part"]),
    ("ape/point_distance", "ape", "tum", "fr1", ["-r", "point_distance"]),
    ("ape/t_offset", "ape", "tum", "fr1", ["--t_offset", "0.004"]),
    ("ape/t_max_diff", "ape", "tum", "fr2", ["--t_max_diff", "0.02"]),
    ("ape/t_start_end", "ape", "tum", "fr1", ["--t_start", "1305031100", "--t_end", "1305031120"]),
    ("ape/project_xy", "ape", "tum", "fr1", ["-a", "--project_to_plane", "xy"]),
    ("rpe/1f", "rpe", "tum", "fr1", []),
    ("rpe/10f", "rpe", "tum", "fr1", ["-d", "10"]),
    ("rpe/10f_all", "rpe", "tum", "fr2", ["-d", "10", "--all_pairs"]),
    ("rpe/0.2m", "rpe", "tum", "fr1", ["-d", "0.2", "-u", "m"]),
    ("rpe/1m_ref", "rpe", "tum", "fr2", ["-d", "1", "-u", "m", "--pairs_from_reference"]),
    ("rpe/0.5m_all", "rpe", "tum", "fr2", ["-d", "0.5", "-u", "m", "--all_pairs"]),
    ("rpe/5d", "rpe", "tum", "fr1", ["-d", "5", "-u", "d"]),
    ("rpe/0.1r", "rpe", "tum", "fr2", ["-d", "0.1", "-u", "r"]),
    ("rpe/10d_all", "rpe", "tum", "fr1", ["-d", "10", "-u", "d", "--all_pairs"]),
    ("rpe/s", "rpe", "tum", "fr2", ["-s", "-d", "10"]),
    ("rpe/as_angle", "rpe", "tum", "fr1", ["-as", "-r", "angle_deg"]),
    ("rpe/full", "rpe", "tum", "fr1", ["-r", "full", "-d", "5"]),
    ("rpe/rot_part", "rpe", "tum", "fr2", ["-r", "rot_part"]),
    ("rpe/point_distance", "rpe", "tum", "fr1", ["-r", "point_distance", "-d", "20"]),
    ("rpe/t_start", "rpe", "tum", "fr1", ["--t_start", "1305031110"]),
    ("bag/ape_a", "ape", "bag", "bag", ["-a"]),
    ("bag/rpe", "rpe", "bag", "bag", ["-d", "1", "-u", "m"]),
    ("kitti/ape_a", "ape", "kitti", "kitti", ["-a"]),
    ("kitti/ape_xz", "ape", "kitti", "kitti", ["-a", "--project_to_plane", "xz"]),
    ("kitti/rpe_100m", "rpe", "kitti", "kitti", ["-d", "100", "-u", "m", "-r", "angle_deg"]),
    ("kitti/rpe_all", "rpe", "kitti", "kitti", ["-d", "50", "-u", "m", "--all_pairs"]),
    ("kitti_e/rpe_100m", "rpe", "kitti", "kitti_e", ["-d", "100", "-u", "m"]),
    ("kitti_e/rpe_origin_full", "rpe", "kitti", "kitti_e", ["--align_origin", "-r", "full"]),
    ("kitti_e/rpe_as_rot", "rpe", "kitti", "kitti_e", ["-as", "-d", "20", "-r", "rot_part"]),
    (
        "kitti_e/rpe_xz",
        "rpe",
        "kitti",
        "kitti_e",
        ["-a", "-d", "50", "-u", "m", "--project_to_plane", "xz"],
    ),
    ("kitti_e/ape_full", "ape", "kitti", "kitti_e", ["-r", "full"]),
    (
        "kitti_e/ape_xz_deg",
        "ape",
        "kitti",
        "kitti_e",
        ["-a", "--project_to_plane", "xz", "-r", "angle_deg"],
    ),
    ("euroc/ape_as", "ape", "euroc", "euroc", ["-as"]),
    ("euroc/rpe", "rpe", "euroc", "euroc", ["-d", "10"]),
    ("repeats/euroc_ape", "ape", "euroc", "euroc_rep", ["-as", "--duplicate_stamps", "keep"]),
    ("repeats/euroc_rpe", "rpe", "euroc", "euroc_rep", ["-d", "5", "--duplicate_stamps", "keep"]),
    ("repeats/tum_ape", "ape", "tum", "tum_rep", ["-a", "--duplicate_stamps", "keep"]),
    ("repeats/tum_rpe", "rpe", "tum", "tum_rep", ["--all_pairs", "--duplicate_stamps", "keep"]),
]


def _evo_bin() -> Path | None:
    """``benchmarks/.venv-evo/bin``, created (``pip install evo``) when it does not exist."""
    bin_dir = EVO_VENV / "bin"
    if not (bin_dir / "evo_ape").exists():
        made = subprocess.run(
            [sys.executable, "-m", "venv", str(EVO_VENV)], capture_output=True, check=False
        )
        if made.returncode == 0:
            subprocess.run(
                [str(bin_dir / "python"), "-m", "pip", "install", "--quiet", "evo"],
                capture_output=True,
                check=False,
            )
    ok = (bin_dir / "evo_ape").exists() and subprocess.run(
        [str(bin_dir / "python"), "-c", "import evo"], capture_output=True, check=False
    ).returncode == 0
    return bin_dir if ok else None


@pytest.fixture(scope="session")
def evo_bin() -> Path:
    """evo's programs; skipped with a message without them, a failure under ``CI=true``."""
    found = _evo_bin()
    if found is None:
        message = f"evo could not be installed into {EVO_VENV} (pip install evo failed)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    return found


def _kitti_pair(folder: Path, fmt: str = "%.17g") -> tuple[Path, Path]:
    """A seeded KITTI-like drive (camera frame: y down, z forward) and a noisy estimate,
    written with ``fmt`` (KITTI's own files: ``%e``, 7 digits, rotations orthonormal to
    ~1e-7 only)."""
    rng = np.random.default_rng(40)
    n = 600
    yaw = np.cumsum(rng.normal(0.0, 0.01, n))
    step = np.stack([np.sin(yaw), 0.01 * rng.normal(size=n), np.cos(yaw)], axis=1)
    pos = np.cumsum(step, axis=0)
    files = []
    for name, noise in (("gt.kitti", 0.0), ("est.kitti", 1.0)):
        y = yaw + noise * np.cumsum(rng.normal(0.0, 0.002, n))
        c, s = np.cos(y), np.sin(y)
        r = np.zeros((n, 3, 3))
        r[:, 0, 0], r[:, 0, 2], r[:, 1, 1], r[:, 2, 0], r[:, 2, 2] = c, s, 1.0, -s, c
        p = pos + noise * np.cumsum(rng.normal(0.0, 0.02, (n, 3)), axis=0)
        rows = np.concatenate((r, p[:, :, None]), axis=2).reshape(n, 12)
        path = folder / (name if fmt == "%.17g" else f"short_{name}")
        np.savetxt(path, rows, fmt=fmt)
        files.append(path)
    return files[0], files[1]


def _euroc_pair(folder: Path) -> tuple[Path, Path]:
    """A seeded 200 Hz EuRoC ground-truth CSV and a 20 Hz TUM estimate with time jitter."""
    rng = np.random.default_rng(41)
    n = 2000
    t_ns = 1403636580838555648 + np.arange(n, dtype=np.int64) * 5_000_000
    pos = np.cumsum(rng.normal(0.0, 0.005, (n, 3)), axis=0)
    q = rng.normal(0.0, 0.02, (n, 4)) + np.array([0.0, 0.0, 0.0, 1.0])
    q /= np.linalg.norm(q, axis=1)[:, None]  # x y z w
    gt = folder / "data.csv"
    with open(gt, "w") as f:
        f.write("#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],")
        f.write("q_RS_y [],q_RS_z []\n")
        for k in range(n):
            x, y, z = pos[k]
            f.write(f"{t_ns[k]},{x:.17g},{y:.17g},{z:.17g},{q[k, 3]:.17g},{q[k, 0]:.17g},")
            f.write(f"{q[k, 1]:.17g},{q[k, 2]:.17g}\n")
    sel = np.arange(0, n, 10)
    t = t_ns[sel] * 1e-9 + rng.uniform(-0.002, 0.002, sel.size)
    p = pos[sel] + rng.normal(0.0, 0.01, (sel.size, 3))
    est = folder / "est.tum"
    rows = np.column_stack((t, p, q[sel]))
    np.savetxt(est, rows, fmt="%.17g")
    return gt, est


def _repeated_pair(folder: Path) -> tuple[Path, Path, Path, Path]:
    """Files with repeated timestamps carrying different poses, as evo's EuRoC ``V102.txt``.

    ``est_rep.tum``: the EuRoC estimate with 4 rows written twice at one time, the second
    pose moved by 5 cm (the shorter trajectory of the association: evo pairs both).
    ``gt_rep.tum`` / ``est_exact.tum``: a 200 Hz TUM reference whose rows at 3 of the
    estimate's exact times are written twice with different poses (the longer trajectory:
    evo's exact match takes the last of them).
    """
    gt_csv, est = _euroc_pair(folder)
    rows = np.loadtxt(est)
    dup = rows[[50, 100, 101, 150]].copy()
    dup[:, 1:4] += 0.05
    rep = np.insert(rows, [51, 101, 102, 151], dup, axis=0)
    est_rep = folder / "est_rep.tum"
    np.savetxt(est_rep, rep, fmt="%.17g")
    g = np.loadtxt(gt_csv, delimiter=",")
    t = g[:, 0] * 1e-9
    gt = np.column_stack((t, g[:, 1:4], g[:, 5:8], g[:, 4]))
    twice = gt[[300, 600, 900]].copy()
    twice[:, 1:4] -= 0.04
    gt_rows = np.insert(gt, [301, 601, 901], twice, axis=0)
    gt_rep = folder / "gt_rep.tum"
    np.savetxt(gt_rep, gt_rows, fmt="%.17g")
    exact = folder / "est_exact.tum"
    sel = gt[::10].copy()
    sel[:, 1:4] += np.random.default_rng(42).normal(0.0, 0.01, (sel.shape[0], 3))
    np.savetxt(exact, sel, fmt="%.17g")
    return gt_csv, est_rep, gt_rep, exact


@pytest.fixture(scope="session")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """The positional arguments of each input (after the kind), real and generated."""
    folder = tmp_path_factory.mktemp("evo_cli")
    tum = require_data("tum_rgbd")
    kitti = _kitti_pair(folder)
    kitti_e = _kitti_pair(folder, "%e")
    euroc = _euroc_pair(folder)
    rep = _repeated_pair(folder)
    return {
        "fr1": [
            str(tum / "freiburg1_xyz-groundtruth.txt"),
            str(tum / "freiburg1_xyz-rgbdslam.txt"),
        ],
        "fr2": [str(tum / "fr2_desk_groundtruth.txt"), str(tum / "fr2_desk_ORB.txt")],
        "bag": [str(require_data("rosbag", "ROS_example.bag")), "groundtruth", "ORB-SLAM"],
        "kitti": [str(p) for p in kitti],
        "kitti_e": [str(p) for p in kitti_e],
        "euroc": [str(p) for p in euroc],
        "euroc_rep": [str(rep[0]), str(rep[1])],
        "tum_rep": [str(rep[2]), str(rep[3])],
    }


def _read_zip(path: Path) -> tuple[dict, np.ndarray, dict]:
    with zipfile.ZipFile(path) as z:
        stats = json.loads(z.read("stats.json"))
        info = json.loads(z.read("info.json"))
        errors = np.load(io.BytesIO(z.read("error_array.npy")))
    return stats, errors, info


def _slamrel(metric: str, kind: str, args: list[str], out: Path) -> None:
    assert main([metric, kind, *args, "--save_results", str(out), "--silent"]) == 0


def _assert_close(ours: dict, theirs: dict, where: str) -> None:
    for key, value in theirs.items():
        assert ours[key] == pytest.approx(value, rel=TOL, abs=1e-15), f"{where}: {key}"


def _evo_words(args: list[str]) -> list[str]:
    """The command line without slamrel's own options (``--duplicate_stamps X``): evo's."""
    out: list[str] = []
    skip = False
    for a in args:
        if skip or a == "--duplicate_stamps":
            skip = not skip
            continue
        out.append(a)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_same_numbers_as_evo(case, evo_bin: Path, inputs: dict, tmp_path: Path) -> None:
    name, metric, kind, key, options = case
    args = [*inputs[key], *options]
    ours, theirs = tmp_path / "slamrel.zip", tmp_path / "evo.zip"
    _slamrel(metric, kind, args, ours)
    run = subprocess.run(
        [str(evo_bin / f"evo_{metric}"), kind, *_evo_words(args), "--save_results", str(theirs)]
        + ["--no_warnings", "--silent"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    s_ours, e_ours, i_ours = _read_zip(ours)
    s_evo, e_evo, i_evo = _read_zip(theirs)
    assert e_ours.size == e_evo.size, name
    _assert_close(s_ours, s_evo, name)
    np.testing.assert_allclose(e_ours, e_evo, rtol=TOL, atol=1e-15, err_msg=name)
    assert i_ours["title"] == i_evo["title"]
    assert i_ours["label"] == i_evo["label"]


# What evo 1.38.1 wrote (`--save_results`, stats.json and the error count) for three command
# lines, on the TUM sequences: evo_ape tum fr2_desk_groundtruth.txt fr2_desk_ORB.txt -as;
# evo_rpe tum (fr2) -d 0.5 -u m --all_pairs; evo_rpe tum freiburg1_xyz-groundtruth.txt
# freiburg1_xyz-rgbdslam.txt -d 5 -u d -r angle_deg.
EVO = {
    ("ape", "fr2", ("-as",)): (
        {
            "rmse": 0.006123163030157291,
            "mean": 0.005586197318706158,
            "median": 0.005305225075852879,
            "std": 0.0025074937707530087,
            "min": 0.0001897958096084112,
            "max": 0.021476785562787627,
            "sse": 0.08151005482370602,
        },
        2174,
    ),
    ("rpe", "fr2", ("-d", "0.5", "-u", "m", "--all_pairs")): (
        {
            "rmse": 0.008989520953905159,
            "mean": 0.008302033623749436,
            "median": 0.007998807730659705,
            "std": 0.003447857985885397,
            "min": 0.0005867444322175406,
            "max": 0.02265137274312376,
            "sse": 0.1615421624744191,
        },
        1999,
    ),
    ("rpe", "fr1", ("-d", "5", "-u", "d", "-r", "angle_deg")): (
        {
            "rmse": 0.7147370717532202,
            "mean": 0.61680501800854,
            "median": 0.5485987623152174,
            "std": 0.3611103037824489,
            "min": 0.07960641186954612,
            "max": 1.412087018943947,
            "sse": 43.422171947761264,
        },
        85,
    ),
}


@pytest.mark.parametrize("case", list(EVO), ids=["ape_as", "rpe_0.5m_all", "rpe_5d"])
def test_numbers_evo_printed(case, tmp_path: Path) -> None:
    metric, key, options = case
    tum = require_data("tum_rgbd")
    files = {
        "fr1": ["freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"],
        "fr2": ["fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"],
    }[key]
    out = tmp_path / "r.zip"
    _slamrel(metric, "tum", [*(str(tum / f) for f in files), *options], out)
    stats, errors, _ = _read_zip(out)
    expected, count = EVO[case]
    assert errors.size == count
    _assert_close(stats, expected, str(case))


def test_printed_like_evo(capsys: pytest.CaptureFixture[str]) -> None:
    """evo's layout: the title, a blank line, the statistics by name, %.6f after a tab."""
    tum = require_data("tum_rgbd")
    args = [str(tum / "fr2_desk_groundtruth.txt"), str(tum / "fr2_desk_ORB.txt"), "-as"]
    assert main(["ape", "tum", *args]) == 0
    expected = (
        "APE w.r.t. translation part (m)\n(with Sim(3) Umeyama alignment)\n\n"
        "       max\t0.021477\n      mean\t0.005586\n    median\t0.005305\n"
        "       min\t0.000190\n      rmse\t0.006123\n       sse\t0.081510\n"
        "       std\t0.002507\n\n"
    )
    assert capsys.readouterr().out == expected


@pytest.mark.parametrize("metric", ["ape", "rpe"])
def test_help_lists_every_option_with_its_default(
    metric: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        main([metric, "tum", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the lines
    words = ["--pose_relation", "--align", "--correct_scale", "--align_origin", "--n_to_align"]
    words += ["--project_to_plane", "--t_max_diff", "--t_offset", "--t_start", "--t_end"]
    words += ["--save_results", "(default: -1", "(default: 0.01)", "(default: trans_part)"]
    if metric == "rpe":
        words += ["--delta ", "--delta_unit", "--all_pairs", "--pairs_from_reference"]
        words += ["(default: f)", "(default: 1.0)", "(default: 0.1)"]
    for word in words:
        assert word in text, word


def test_kitti_needs_as_many_poses(tmp_path: Path) -> None:
    gt, est = _kitti_pair(tmp_path)
    short = tmp_path / "short.kitti"
    short.write_text("".join(est.read_text().splitlines(keepends=True)[:-3]))
    assert main(["ape", "kitti", str(gt), str(short)]) == 3


def test_align_and_align_origin_exclude_each_other(tmp_path: Path) -> None:
    gt, est = _kitti_pair(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(["ape", "kitti", str(gt), str(est), "-a", "--align_origin"])
    assert stop.value.code == 2


def test_repeated_stamps_refused_by_default_and_kept_on_request(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """evo's V102.txt case: two poses at one time are refused, naming the option that keeps
    them; with it every estimate pose is associated (the estimate is the shorter: evo pairs
    each of its poses, repeats included), and the repeats are counted in a warning."""
    gt, est, _, _ = _repeated_pair(tmp_path)
    assert main(["ape", "euroc", str(gt), str(est)]) == 3
    err = capsys.readouterr().err
    assert f"{est}:52:" in err and "--duplicate_stamps keep" in err
    out = tmp_path / "keep.zip"
    _slamrel("ape", "euroc", [str(gt), str(est), "--duplicate_stamps", "keep"], out)
    assert "kept all 4 estimate pose(s)" in capsys.readouterr().err
    _, errors, _ = _read_zip(out)
    assert errors.size == len(np.loadtxt(est))  # 204 rows, all within 2 ms of a 200 Hz pose
    first = tmp_path / "first.zip"
    _slamrel("ape", "euroc", [str(gt), str(est), "--duplicate_stamps", "first"], first)
    assert _read_zip(first)[1].size == errors.size - 4


def test_exact_match_on_a_repeated_time_takes_the_last_as_evo() -> None:
    """Hand oracle of evo's ``searchsorted(side="right")``: a query equal to a repeated time
    gets the last of the repeats; queries between times are unchanged."""
    from relation_metric.time_association import match_nearest_times

    times = np.array([0.0, 1.0, 1.0, 1.0, 2.0, 3.0, 3.0])
    i, k = match_nearest_times(np.array([1.0, 0.9, 1.2, 2.9, 3.0, 1.7]), times, 0.5)
    assert i.tolist() == [0, 1, 2, 3, 4, 5]
    assert k.tolist() == [3, 1, 3, 5, 6, 4]


def test_kitti_rotations_used_as_written(tmp_path: Path) -> None:
    """KITTI's rotation blocks written with 7 digits are orthonormal to ~1e-7 only; the RPE
    uses them as written, as evo does. Oracle: evo's arithmetic written out pair by pair on
    4x4 matrices (inverse by transposition), independent of slamrel's vectorised path."""
    gt, est = _kitti_pair(tmp_path, "%e")
    out = tmp_path / "r.zip"
    _slamrel("rpe", "kitti", [str(gt), str(est), "-d", "10", "-r", "full"], out)
    ours = _read_zip(out)[1]

    def inv(m: np.ndarray) -> np.ndarray:
        r = np.eye(4)
        r[:3, :3] = m[:3, :3].T
        r[:3, 3] = -m[:3, :3].T @ m[:3, 3]
        return r

    q, p = (np.loadtxt(f).reshape(-1, 3, 4) for f in (gt, est))
    h = np.tile(np.eye(4), (q.shape[0], 1, 1))
    qq, pp = h.copy(), h.copy()
    qq[:, :3], pp[:, :3] = q, p
    oracle = [
        np.linalg.norm(inv(inv(qq[i]) @ qq[i + 10]) @ (inv(pp[i]) @ pp[i + 10]) - np.eye(4))
        for i in range(0, q.shape[0] - 10, 10)
    ]
    np.testing.assert_allclose(ours, oracle, rtol=1e-12)
    # the quaternion reading (re-orthonormalised) differs at this precision: the test can fail
    from slamrel.evo_metrics import EvoOptions, evo_files

    o = EvoOptions("rpe", "kitti", str(gt), str(est), delta=10, pose_relation="full")
    r = evo_files(o)
    from relation_metric.pose_error import relative_pose_errors

    quat = relative_pose_errors(r.reference, r.estimate, "full", delta=10)
    assert np.abs(quat.errors - ours).max() > 1e-9 * np.abs(ours).max()


def _kind_parsers(metric: str) -> dict:
    import argparse

    from slamrel.cli import build_parser

    def subparsers(p: argparse.ArgumentParser) -> dict:
        (act,) = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        return act.choices

    return subparsers(subparsers(build_parser(metric))[metric])


@pytest.mark.parametrize("metric", ["ape", "rpe"])
def test_help_states_every_default(metric: str, capsys: pytest.CaptureFixture[str]) -> None:
    """As evo's --help: every option of every input kind says its default, and the rendered
    text shows the parser's actual default value (a flag: off; no value: none)."""
    for kind, parser in _kind_parsers(metric).items():
        with pytest.raises(SystemExit):
            main([metric, kind, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        for action in parser._actions:
            if not action.option_strings or action.dest == "help":
                continue
            if action.default is None:
                shown = "none"
            elif action.default is False:
                shown = "off"
            else:
                shown = str(action.default)
            assert f"(default: {shown}" in " ".join((action.help or "").split()).replace(
                "%(default)s", shown
            ), (kind, action.dest)
            assert action.option_strings[-1] in text, (kind, action.dest)


def test_save_plot_writes_the_errors_it_scored(tmp_path: Path) -> None:
    """--save_plot: a valid PNG and PDF (signature, PNG size in its header); the figure's
    error line is the error array of the result zip (the oracle: the same run's numbers)."""
    import matplotlib

    matplotlib.use("Agg")
    gt, est = _euroc_pair(tmp_path)
    png, pdf, out = tmp_path / "e.png", tmp_path / "e.pdf", tmp_path / "r.zip"
    args = [str(gt), str(est), "-d", "5", "--save_plot", str(png), "--save_results", str(out)]
    assert main(["rpe", "euroc", *args, "--silent"]) == 0
    head = png.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR"
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    assert width > 500 and height > 500
    assert main(["ape", "euroc", str(gt), str(est), "-a", "--save_plot", str(pdf)]) == 0
    data = pdf.read_bytes()
    assert data[:5] == b"%PDF-" and data.rstrip().endswith(b"%%EOF")
    from slamrel.evo_metrics import EvoOptions, evo_files
    from slamrel.plots.pose_errors import pose_error_figure

    result = evo_files(EvoOptions("rpe", "euroc", str(gt), str(est), delta=5))
    fig = pose_error_figure(result)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_ydata(), _read_zip(out)[1])
    before = gt.read_bytes()
    assert main(["ape", "euroc", str(gt), str(est), "--save_plot", str(gt)]) == 3  # an input
    assert gt.read_bytes() == before
