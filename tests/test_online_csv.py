"""``online.csv`` with its covariance columns: one reader, one writer, and the online NEES of
``slamrel run BUNDLE`` (in the same anchored frame as the recovered one)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relation_metric.errors import InputError
from relation_metric.timeorder import TimeOrderWarning
from relation_metric.trajectory import Trajectory
from slamrel.cli import main
from slamrel.formats.bundle import read_online, write_online


def _online(n: int = 6, seed: int = 0) -> tuple[Trajectory, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, 3, 3))
    return Trajectory(np.arange(n) * 0.1, rng.normal(size=(n, 3))), a @ a.transpose(0, 2, 1)


def test_online_csv_round_trips_with_and_without_covariances(tmp_path: Path) -> None:
    traj, cov = _online()
    p = tmp_path / "online.csv"
    write_online(p, traj, cov)
    assert p.read_text().splitlines()[0] == "t,x,y,theta,cxx,cxy,cxt,cyy,cyt,ctt"
    back = read_online(p)
    assert np.array_equal(back.trajectory.timestamps, traj.timestamps)
    assert np.array_equal(back.trajectory.poses, traj.poses)
    assert back.covariances is not None and np.array_equal(back.covariances, cov)
    write_online(p, traj)
    back = read_online(p)
    assert back.covariances is None and np.array_equal(back.trajectory.poses, traj.poses)


def test_online_csv_rows_out_of_order_keep_their_covariances(tmp_path: Path) -> None:
    traj, cov = _online()
    p = tmp_path / "online.csv"
    write_online(p, traj, cov)
    head, *rows = p.read_text().splitlines()
    p.write_text("\n".join([head, *rows[::-1]]) + "\n")
    with pytest.warns(TimeOrderWarning):
        back = read_online(p)
    assert np.array_equal(back.trajectory.poses, traj.poses)
    assert back.covariances is not None and np.array_equal(back.covariances, cov)


HEAD = "t,x,y,theta,cxx,cxy,cxt,cyy,cyt,ctt\n"
GOOD = "0,0,0,0,1,0,0,1,0,1\n"


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        (HEAD + GOOD + "0.1,0,0,0,1,0,0,1,,1\n", 3, "expected all six numbers"),
        (HEAD + GOOD + "# comment\n0.1,0,0,0,1,2,0,1,0,1\n", 4, "positive semi-definite"),
        (HEAD + GOOD + "0.1,0,0,0,1,0.5,0,1,0,x\n", 3, "column 'ctt'"),
        ("t,x,y,theta,cxx,cxy,cyy\n0,0,0,0,1,0,1\n", 1, "expected all of cxx,cxy,cxt"),
    ],
)
def test_a_malformed_covariance_row_is_refused_with_file_and_line(
    tmp_path: Path, text: str, line: int, message: str
) -> None:
    p = tmp_path / "online.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_online(p)
    assert f"online.csv:{line}" in str(err.value)


def _csv(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def _nees_by_hand(bundle: Path) -> float:
    """The online NEES of ``slamrel run`` from the files: the run starts at the true pose, so
    the map frame is the truth frame (docs/bundle.md, "The frame of the NEES"); compared at
    the ground-truth times (the first, the prior, left out)."""
    r, d = np.eye(2), np.zeros(2)
    on, gt = _csv(bundle / "online.csv"), _csv(bundle / "groundtruth.csv")
    k = np.searchsorted(on[:, 0], gt[:, 0])
    assert np.array_equal(on[k, 0], gt[:, 0])
    on, gt = on[k][1:], gt[1:]
    xy = on[:, 1:3] @ r.T + d
    th = on[:, 3] + np.arctan2(r[1, 0], r[0, 0])
    e = np.column_stack((gt[:, 1:3] - xy, np.angle(np.exp(1j * (gt[:, 3] - th)))))
    cxx, cxy, cxt, cyy, cyt, ctt = on[:, 4:10].T
    p = np.stack([[cxx, cxy, cxt], [cxy, cyy, cyt], [cxt, cyt, ctt]]).transpose(2, 0, 1)
    jac = np.eye(3)
    jac[:2, :2] = r
    p = jac @ p @ jac.T
    return float(np.mean(np.einsum("ka,kab,kb->k", e, np.linalg.inv(p), e)))


@pytest.mark.slow
def test_run_on_a_bundle_with_online_covariances_reports_the_online_nees(tmp_path: Path) -> None:
    sim, slam, rep = tmp_path / "sim", tmp_path / "slam", tmp_path / "rep"
    assert main(["simulate", "simple1", "--seed", "2", "-o", str(sim), "-q"]) == 0
    assert main(["slam", str(sim), "-o", str(slam), "--store-online", "-q"]) == 0
    assert read_online(slam / "online.csv").covariances is not None
    assert main(["run", str(slam), "-o", str(rep), "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    assert set(m["nees"]) == {"recovered", "online"}
    assert not m["nees_frame"]["aligned"]
    assert m["nees_frame"]["map_anchoring"]["association"] == "id"
    assert m["nees"]["online"]["mean"] == pytest.approx(_nees_by_hand(slam), rel=1e-9)
    assert set(m["nees_truth_frame"]) == {"recovered", "online"}
    assert "online" in (rep / "report.html").read_text().split("NEES (3 dof)")[1]

    # without the covariance columns: scored, but no online NEES, and the report says so
    on = read_online(slam / "online.csv")
    write_online(slam / "online.csv", on.trajectory)
    assert main(["run", str(slam), "-o", str(rep), "--force", "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    assert "online" in m and set(m["nees"]) == {"recovered"}
    assert any("there is no online NEES" in n for n in m["notes"])
