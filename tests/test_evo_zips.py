"""evo-compatible result zips (``--evo-zip``, ``--evo-ape-zip``) and the ATE on the console.

``evo_res`` refuses (asks on stdin, and crashes when none) results whose titles differ, so a
slamrel zip carries evo's own title for the same computation. The titles below are what
evo v1.38.1 wrote in its zips for ``evo_rpe bag ... --pairs_from_reference`` and
``evo_ape bag ... -r angle_rad`` (read from their ``info.json``). Where evo's side venv
(``benchmarks/.venv-evo``) exists, evo_res runs on slamrel's zips and evo's own, with stdin
closed (non-interactive).
"""

from __future__ import annotations

import io
import json
import math
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, require_data

from slamrel.cli import main
from slamrel.formats.results import EvoDelta, evo_delta, evo_title

EVO_BIN = ROOT / "benchmarks" / ".venv-evo" / "bin"
EVO_SKIP = (
    "evo's side venv benchmarks/.venv-evo is absent: evo is a peer used as a measuring "
    "instrument, not a dependency of slamrel, so this test skips also under CI "
    "(python -m venv benchmarks/.venv-evo && benchmarks/.venv-evo/bin/pip install evo)"
)

# evo v1.38.1's titles, from the info.json of its own result zips
EVO_RPE_TITLE = (
    "RPE w.r.t. translation part (m)\nfor delta = 1 (frames) using consecutive pairs\n(not aligned)"
)
EVO_APE_TITLE = "APE w.r.t. rotation angle in radians (rad)\n(not aligned)"


def test_titles_are_evos():
    d = evo_delta(sync=True, strategy=None, step=1, distance=1.0, chained=False, mode="paper")
    assert d == EvoDelta(1.0, "frames", all_pairs=False)
    assert evo_title("rpe", "trans", delta=d) == EVO_RPE_TITLE
    assert evo_title("ape", "rot", align="none") == EVO_APE_TITLE
    # relations evo has no name for: no evo title (without --sync, another mode, loops)
    assert (
        evo_delta(sync=False, strategy=None, step=1, distance=1, chained=True, mode="paper") is None
    )
    assert (
        evo_delta(sync=True, strategy="loops", step=1, distance=1, chained=True, mode="paper")
        is None
    )
    assert (
        evo_delta(
            sync=True, strategy=None, step=1, distance=1, chained=True, mode="metricevaluator"
        )
        is None
    )
    # step 5 not chained: every pose with the one 5 later, evo's --all_pairs
    d5 = evo_delta(
        sync=True, strategy="consecutive", step=5, distance=1, chained=False, mode="paper"
    )
    assert "for delta = 5 (frames) using all pairs" in evo_title("rpe", "trans", delta=d5)


def _zip(path: Path) -> tuple[dict, dict, np.ndarray, np.ndarray]:
    with zipfile.ZipFile(path) as z:
        info = json.loads(z.read("info.json"))
        stats = json.loads(z.read("stats.json"))
        err = np.load(io.BytesIO(z.read("error_array.npy")))
        t = np.load(io.BytesIO(z.read("timestamps.npy")))
    return info, stats, err, t


def _slamrel_zips(tmp: Path, bag: Path, est: str) -> dict[str, Path]:
    out = {k: tmp / f"slamrel_{est}_{k}.zip" for k in ("rpe", "ape")}
    args = [
        "evaluate", f"{bag}:groundtruth", f"{bag}:{est}", "--sync", "--max-time-diff", "0.01",
        "-q", "--evo-zip", str(out["rpe"]), "--evo-ape-zip", str(out["ape"]),
        "--evo-ape-align", "se3",
    ]  # fmt: skip
    assert main(args) == 0
    return out


def test_ape_zip_matches_the_printed_ate(tmp_path, capsys):
    bag = require_data("rosbag", "ROS_example.bag")
    zips = _slamrel_zips(tmp_path, bag, "ORB-SLAM")
    info, stats, err, t = _zip(zips["ape"])
    assert info["title"] == "APE w.r.t. translation part (m)\n(with SE(3) Umeyama alignment)"
    assert info["est_name"] == "ORB-SLAM" and info["ref_name"] == "groundtruth"
    # the same numbers as the console's ATE table (an independent path: --ate's JSON)
    j = tmp_path / "ate.json"
    args = [
        "evaluate", f"{bag}:groundtruth", f"{bag}:ORB-SLAM", "--sync", "--max-time-diff",
        "0.01", "--ate", "--json", str(j),
    ]  # fmt: skip
    assert main(args) == 0
    ate = json.loads(j.read_text())["ate"]["se3"]
    n = ate["matched"]
    assert err.size == t.size == n
    assert stats["rmse"] == pytest.approx(ate["translation"]["rmse"], abs=1e-12)
    assert stats["std"] == pytest.approx(ate["translation"]["std"] * math.sqrt((n - 1) / n))
    assert stats["sse"] == pytest.approx(float(np.sum(err**2)), rel=1e-12)
    assert np.all(np.diff(t) > 0)
    printed = capsys.readouterr().out
    row = next(line for line in printed.splitlines() if line.startswith("ATE translation [m] se3"))
    cells = [float(x) for x in row.split()[4:]]
    expect = [stats[k] for k in ("rmse", "mean", "median", "std", "min", "max", "sse")]
    assert cells[:7] == pytest.approx(expect, abs=1e-6) and int(cells[7]) == n


def test_ape_zip_needs_a_reference_trajectory(tmp_path):
    ref = tmp_path / "r.relations"
    ref.write_text("0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0\n")
    est = tmp_path / "e.txt"
    est.write_text("0 0 0 0\n1 1 0 0\n2 2 0 0\n")
    z = tmp_path / "ape.zip"
    assert main(["evaluate", str(ref), str(est), "--evo-ape-zip", str(z), "-q"]) == 2
    assert not z.exists()


def _evo_ok() -> bool:
    if not (EVO_BIN / "evo_res").exists():
        return False
    return (
        subprocess.run([str(EVO_BIN / "python"), "-c", "import evo"], check=False).returncode == 0
    )


def _evo_res(*zips: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(EVO_BIN / "evo_res"), *map(str, zips)],
        stdin=subprocess.DEVNULL,  # non-interactive: a confirmation prompt would crash evo_res
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_evo_res_reads_slamrel_zips_beside_evos(tmp_path):
    if not _evo_ok():
        pytest.skip(EVO_SKIP)
    bag = require_data("rosbag", "ROS_example.bag")
    orb = _slamrel_zips(tmp_path, bag, "ORB-SLAM")
    sptam = _slamrel_zips(tmp_path, bag, "S-PTAM")
    theirs = {"rpe": tmp_path / "evo_rpe.zip", "ape": tmp_path / "evo_ape.zip"}
    for tool, extra in (("rpe", ["--pairs_from_reference"]), ("ape", ["-a"])):
        r = subprocess.run(
            [str(EVO_BIN / f"evo_{tool}"), "bag", str(bag), "groundtruth", "S-PTAM", *extra,
             "--save_results", str(theirs[tool]), "--no_warnings"],
            stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300, check=False,
        )  # fmt: skip
        assert r.returncode == 0, r.stderr[-2000:]
    for tool in ("rpe", "ape"):
        info_ours, stats_ours, err_ours, _ = _zip(sptam[tool])
        info_evo, stats_evo, err_evo, _ = _zip(theirs[tool])
        assert info_ours["title"] == info_evo["title"]
        assert info_ours["label"] == info_evo["label"]
        np.testing.assert_allclose(err_ours, err_evo, rtol=0, atol=1e-9)
        # two slamrel zips, and a slamrel zip beside evo's (renamed: est_name must differ)
        for pair in ((orb[tool], sptam[tool]), (orb[tool], theirs[tool])):
            r = _evo_res(*pair)
            assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-2000:]
            assert "Mismatching titles" not in r.stdout + r.stderr
            assert info_evo["title"].splitlines()[0] in r.stdout
            for z in pair:
                rmse = _zip(z)[1]["rmse"]
                assert f"{rmse:.6f}"[:-1] in r.stdout  # pandas prints 6 significant digits
