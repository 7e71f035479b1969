"""Parity with evo's RPE and APE on the TUM RGB-D sequences to 1e-9.

slamrel is driven through its CLI (``evaluate --sync --max-time-diff 0.01``: evo's
nearest-time association with ``t_max_diff = 0.01``; ``--strategy consecutive --step D
--chained`` is evo's delta in frames, ``--strategy distance --distance D --chained`` its
delta in metres with ``--pairs_from_reference``; ``--ate`` its APE after no, SE(3) and Sim(3)
Umeyama alignment). Errors are the translation part and the rotation angle.

The numbers in :data:`EVO` were computed once with evo v1.38.1 (numpy 2.4.6, scipy 1.17.1)
by ``python benchmarks/evo_reference.py`` (its API equivalent of
``evo_rpe tum GT EST --t_max_diff 0.01 --delta D --delta_unit {f,m} --pairs_from_reference
--pose_relation {trans_part,angle_rad}`` and ``evo_ape tum GT EST --t_max_diff 0.01 [-a|-as]
--pose_relation {trans_part,angle_rad}``). When the evo venv of the benchmarks
(``benchmarks/.venv-evo``) exists, evo is also run live and every error is compared.

The cases and the live evo run are this file's own copy of ``benchmarks/evo_reference.py``,
on purpose: the stored numbers were made by that script, and the test keeps the definition
of its oracle beside them, so that editing or removing a benchmark cannot change what is
checked here (tests import nothing from ``benchmarks/``).
"""

from __future__ import annotations

import io
import json
import math
import subprocess
import tempfile
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, require_data

from slamrel.cli import main

TOL = 1e-9

SEQUENCES = {
    "fr1_xyz": ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    "fr2_desk": ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"),
}
# (name, sequence, metric, delta, unit, align) — align: "" | "se3" | "sim3" (APE only)
CASES = [
    ("fr1_xyz/rpe/1f", "fr1_xyz", "rpe", 1, "frames", ""),
    ("fr1_xyz/rpe/10f", "fr1_xyz", "rpe", 10, "frames", ""),
    ("fr1_xyz/rpe/0.2m", "fr1_xyz", "rpe", 0.2, "meters", ""),
    ("fr1_xyz/ape", "fr1_xyz", "ape", 0, "", ""),
    ("fr1_xyz/ape/se3", "fr1_xyz", "ape", 0, "", "se3"),
    ("fr2_desk/rpe/1f", "fr2_desk", "rpe", 1, "frames", ""),
    ("fr2_desk/rpe/1m", "fr2_desk", "rpe", 1.0, "meters", ""),
    ("fr2_desk/ape/se3", "fr2_desk", "ape", 0, "", "se3"),
    ("fr2_desk/ape/sim3", "fr2_desk", "ape", 0, "", "sim3"),
]
EVO_PYTHON = ROOT / "benchmarks" / ".venv-evo" / "bin" / "python"
# evo's API run of every case (evo_rpe/evo_ape with --t_max_diff 0.01, see the module doc):
# statistics and count by case, and each error array saved as <arrays>/<case>_<part>.npy.
EVO_SCRIPT = textwrap.dedent(
    """
    import copy, json, sys
    import numpy as np
    import evo
    from evo.core import metrics, sync
    from evo.core.metrics import PoseRelation, Unit
    from evo.tools import file_interface
    data, cases, arrays = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
    out = {"evo_version": evo.__version__}
    for name, (gt, est), metric, delta, unit, align in cases:
        ref = file_interface.read_tum_trajectory_file(data + "/" + gt)
        e = file_interface.read_tum_trajectory_file(data + "/" + est)
        ref, e = sync.associate_trajectories(ref, e, max_diff=0.01)
        if align:
            e = copy.deepcopy(e)
            e.align(ref, correct_scale=(align == "sim3"))
        res = {}
        for part, rel in (("trans", PoseRelation.translation_part),
                          ("rot", PoseRelation.rotation_angle_rad)):
            if metric == "rpe":
                m = metrics.RPE(rel, delta=delta, delta_unit=Unit[unit], all_pairs=False,
                                pairs_from_reference=True)
            else:
                m = metrics.APE(rel)
            m.process_data((ref, e))
            res[part] = {k: float(v) for k, v in m.get_all_statistics().items()}
            res[part]["count"] = int(m.error.size)
            np.save(arrays + "/" + name.replace("/", "_") + "_" + part + ".npy", m.error)
        out[name] = res
    print(json.dumps(out))
    """
)


def _evo_python() -> Path | None:
    """The benchmarks' evo venv python when it exists and imports evo (never creates it)."""
    if not EVO_PYTHON.exists():
        return None
    ok = subprocess.run([str(EVO_PYTHON), "-c", "import evo"], capture_output=True, check=False)
    return EVO_PYTHON if ok.returncode == 0 else None


def _run_evo(python: Path, data: Path, arrays: Path) -> dict:
    """evo's results by case (:data:`EVO_SCRIPT` run with the evo venv's ``python``)."""
    cases = [(n, SEQUENCES[s], m, d, u, a) for n, s, m, d, u, a in CASES]
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "evo_run.py"
        script.write_text(EVO_SCRIPT)
        r = subprocess.run(
            [str(python), str(script), str(data), json.dumps(cases), str(arrays)],
            capture_output=True,
            text=True,
            check=False,
        )
    if r.returncode:
        raise RuntimeError("evo failed: " + r.stderr.strip()[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


EVO = {
    "fr1_xyz/rpe/1f": {
        "trans": {
            "rmse": 0.005764370848928318,
            "mean": 0.00481560947020396,
            "median": 0.004138857799364448,
            "std": 0.003168260834346898,
            "min": 0.00017106115346223795,
            "max": 0.020865814532329843,
            "sse": 0.026050729486636066,
            "count": 784,
        },
        "rot": {
            "rmse": 0.006171713938616683,
            "mean": 0.005241338606301213,
            "median": 0.004575188642116212,
            "std": 0.0032585921122797678,
            "min": 0.00029560892037159756,
            "max": 0.028506393947577036,
            "sse": 0.029862601505050518,
            "count": 784,
        },
    },
    "fr1_xyz/rpe/10f": {
        "trans": {
            "rmse": 0.01461013202388883,
            "mean": 0.012477076968475899,
            "median": 0.011981234060699633,
            "std": 0.007601217539196613,
            "min": 0.0010349715017425696,
            "max": 0.043153861730255504,
            "sse": 0.01664956470492603,
            "count": 78,
        },
        "rot": {
            "rmse": 0.012244730138468822,
            "mean": 0.010974490801853328,
            "median": 0.010414732364757397,
            "std": 0.005430834908553507,
            "min": 0.001049567778784557,
            "max": 0.027817981189301216,
            "sse": 0.011694806460786281,
            "count": 78,
        },
    },
    "fr1_xyz/rpe/0.2m": {
        "trans": {
            "rmse": 0.01914487280297293,
            "mean": 0.01728477648004973,
            "median": 0.01590513981497103,
            "std": 0.008231807619030728,
            "min": 0.0032246899593419806,
            "max": 0.04713975006964585,
            "sse": 0.01392799387639648,
            "count": 38,
        },
        "rot": {
            "rmse": 0.012540132789272107,
            "mean": 0.011754364167162657,
            "median": 0.011891781428067169,
            "std": 0.00436919367827749,
            "min": 0.002191910283745949,
            "max": 0.021260275986670792,
            "sse": 0.005975687354157941,
            "count": 38,
        },
    },
    "fr1_xyz/ape": {
        "trans": {
            "rmse": 0.020079418378506592,
            "mean": 0.01806251843069654,
            "median": 0.016517756173282164,
            "std": 0.008770887660884508,
            "min": 0.0012561023047507462,
            "max": 0.04328943388403233,
            "sse": 0.31649868829899996,
            "count": 785,
        },
        "rot": {
            "rmse": 0.012246855842450137,
            "mean": 0.011013500687530932,
            "median": 0.010222802513952526,
            "std": 0.0053561441944285524,
            "min": 0.00047903755028827255,
            "max": 0.03174709264398175,
            "sse": 0.1177386002502177,
            "count": 785,
        },
    },
    "fr1_xyz/ape/se3": {
        "trans": {
            "rmse": 0.013470088849733684,
            "mean": 0.012024498709110237,
            "median": 0.011183186775061079,
            "std": 0.0060708092058905936,
            "min": 0.0009550461813175756,
            "max": 0.03475954589500906,
            "sse": 0.14243298549147998,
            "count": 785,
        },
        "rot": {
            "rmse": 0.03591363307214646,
            "mean": 0.03533760250975893,
            "median": 0.03492126477198447,
            "std": 0.006406472453936795,
            "min": 0.012949616960985712,
            "max": 0.06352284343172908,
            "sse": 1.012484396746006,
            "count": 785,
        },
    },
    "fr2_desk/rpe/1f": {
        "trans": {
            "rmse": 0.003490321374787292,
            "mean": 0.0030380874175009644,
            "median": 0.002750288386204023,
            "std": 0.0017182456584898963,
            "min": 0.0001319690055884261,
            "max": 0.01948467892016712,
            "sse": 0.026472231989372496,
            "count": 2173,
        },
        "rot": {
            "rmse": 0.004895984113511812,
            "mean": 0.004006510104788864,
            "median": 0.0032780504727434093,
            "std": 0.002813989555770379,
            "min": 0.000105399489647916,
            "max": 0.021980737733404095,
            "sse": 0.05208824513559857,
            "count": 2173,
        },
    },
    "fr2_desk/rpe/1m": {
        "trans": {
            "rmse": 0.015808009564688773,
            "mean": 0.014108778854026158,
            "median": 0.01170575295056064,
            "std": 0.007129903621050994,
            "min": 0.005655268581708497,
            "max": 0.037425194921939554,
            "sse": 0.004248183828753959,
            "count": 17,
        },
        "rot": {
            "rmse": 0.014976536248024518,
            "mean": 0.01236694284887011,
            "median": 0.009240363451353721,
            "std": 0.008447210341951521,
            "min": 0.0018937944965995305,
            "max": 0.030047052418660816,
            "sse": 0.0038130428458026688,
            "count": 17,
        },
    },
    "fr2_desk/ape/se3": {
        "trans": {
            "rmse": 0.008118977562044926,
            "mean": 0.0074917768702161495,
            "median": 0.007414629829316952,
            "std": 0.00312906950703932,
            "min": 0.0003496361984068482,
            "max": 0.024299593694385276,
            "sse": 0.14330528992359803,
            "count": 2174,
        },
        "rot": {
            "rmse": 0.01726192865814985,
            "mean": 0.01674596435994816,
            "median": 0.016577158843191372,
            "std": 0.00418889706896709,
            "min": 0.002320424264499307,
            "max": 0.03534066965609874,
            "sse": 0.6477958694919457,
            "count": 2174,
        },
    },
    "fr2_desk/ape/sim3": {
        "trans": {
            "rmse": 0.006123163030157264,
            "mean": 0.00558619731870614,
            "median": 0.005305225075852613,
            "std": 0.002507493770752984,
            "min": 0.0001897958096088303,
            "max": 0.021476785562788304,
            "sse": 0.08151005482370531,
            "count": 2174,
        },
        "rot": {
            "rmse": 0.01726192865814985,
            "mean": 0.01674596435994816,
            "median": 0.016577158843191372,
            "std": 0.00418889706896709,
            "min": 0.002320424264499307,
            "max": 0.03534066965609874,
            "sse": 0.6477958694919457,
            "count": 2174,
        },
    },
}


def _strategy(delta: float, unit: str) -> list[str]:
    if unit == "frames":
        return ["--strategy", "consecutive", "--step", str(int(delta)), "--chained"]
    return ["--strategy", "distance", "--distance", repr(float(delta)), "--chained"]


def _zip(path: Path) -> tuple[np.ndarray, dict]:
    with zipfile.ZipFile(path) as z:
        errors = np.load(io.BytesIO(z.read("error_array.npy")))
        stats = json.loads(z.read("stats.json"))
    return errors, stats


def _slamrel_rpe(tmp_path: Path, gt: Path, est: Path, delta: float, unit: str) -> dict:
    out = {}
    for part in ("trans", "rot"):
        z = tmp_path / f"{part}.zip"
        args = [
            "evaluate", str(gt), str(est), "--reference-format", "tum", "--sync",
            "--max-time-diff", "0.01", *_strategy(delta, unit), "-q",
            "--evo-zip", str(z), "--evo-part", part,
        ]  # fmt: skip
        assert main(args) == 0
        out[part] = _zip(z)
    return out


def _slamrel_ape(tmp_path: Path, gt: Path, est: Path) -> dict:
    j = tmp_path / "ape.json"
    args = [
        "evaluate", str(gt), str(est), "--reference-format", "tum", "--sync",
        "--max-time-diff", "0.01", "--ate", "-q", "--json", str(j),
    ]  # fmt: skip
    assert main(args) == 0
    return json.loads(j.read_text())


def _check_stats(ours: dict, theirs: dict, *, population_std: bool) -> None:
    assert ours["count"] == theirs["count"]
    for key in ("rmse", "mean", "median", "min", "max"):
        assert ours[key] == pytest.approx(theirs[key], abs=TOL), key
    n = theirs["count"]
    std = ours["std"] if population_std else ours["std"] * math.sqrt((n - 1) / n)
    assert std == pytest.approx(theirs["std"], abs=TOL)


@pytest.mark.parametrize("case", CASES)
def test_matches_stored_evo_numbers(tmp_path, case):
    name, seq, metric, delta, unit, align = case
    gt_name, est_name = SEQUENCES[seq]
    gt = require_data("tum_rgbd", gt_name)
    est = require_data("tum_rgbd", est_name)
    stored = EVO[name]
    if metric == "rpe":
        ours = _slamrel_rpe(tmp_path, gt, est, delta, unit)
        for part in ("trans", "rot"):
            errors, stats = ours[part]
            assert errors.size == stored[part]["count"]
            _check_stats({**stats, "count": errors.size}, stored[part], population_std=True)
            assert stats["sse"] == pytest.approx(stored[part]["sse"], abs=TOL)
    else:
        ate = _slamrel_ape(tmp_path, gt, est)["ate"][align or "none"]
        for part, key in (("trans", "translation"), ("rot", "rotation")):
            ours = {**ate[key], "count": ate["matched"]}
            _check_stats(ours, stored[part], population_std=False)


@pytest.fixture(scope="module")
def live_evo(tmp_path_factory):
    python = _evo_python()
    if python is None:
        pytest.skip("evo venv not installed (run python benchmarks/evo_reference.py once)")
    data = require_data("tum_rgbd")
    arrays = tmp_path_factory.mktemp("evo_arrays")
    return _run_evo(python, data, arrays), arrays


def test_live_evo_agrees_error_by_error(tmp_path, live_evo):
    results, arrays = live_evo
    for name, seq, metric, delta, unit, _align in CASES:
        if metric != "rpe":
            continue
        gt_name, est_name = SEQUENCES[seq]
        gt = require_data("tum_rgbd", gt_name)
        est = require_data("tum_rgbd", est_name)
        ours = _slamrel_rpe(tmp_path, gt, est, delta, unit)
        for part in ("trans", "rot"):
            theirs = np.load(arrays / (name.replace("/", "_") + f"_{part}.npy"))
            assert ours[part][0].shape == theirs.shape, name
            np.testing.assert_allclose(ours[part][0], theirs, rtol=0, atol=TOL, err_msg=name)
    for name in EVO:  # the stored numbers are what this evo computes
        for part in ("trans", "rot"):
            for key, value in EVO[name][part].items():
                assert results[name][part][key] == pytest.approx(value, abs=TOL), (name, key)
