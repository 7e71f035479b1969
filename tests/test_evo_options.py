"""evo's --pairs_from_reference default (pairs on the estimate), --n_to_align, --align_origin,
--t_offset and --t_start/--t_end against slamrel's --pairs-from estimate, --n-to-align, the
origin row of --ate, --t-offset and --t-start/--t-end, on the TUM RGB-D sequences, to 1e-9.

The numbers in :data:`EVO` were computed with evo v1.38.1 (numpy 2.4.6) through its API: for
each case ``sync.associate_trajectories(ref, est, max_diff=0.01, offset_2=t_offset)`` (after
``ref.reduce_to_time_range(t_start, t_end)``, as ``evo_ape`` applies the window), then
``metrics.RPE(rel, delta, Unit.meters, all_pairs=False, pairs_from_reference=False)`` or
``est.align(ref, n=N)`` / ``est.align_origin(ref)`` and ``metrics.APE``, for the translation
part and the rotation angle. When ``benchmarks/.venv-evo`` exists evo is run live as well.
evo's window is on the reference only (its synchronisation then drops the estimate poses
without a partner); slamrel's is on both, which gives the same pairs once synchronised.
"""

from __future__ import annotations

import json
import subprocess
import textwrap

import pytest
from conftest import ROOT, require_data

from slamrel.cli import main

TOL = 1e-9
FR1 = ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt")
FR2 = ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt")
# name -> (files, evo case keywords, slamrel options, slamrel result)
CASES = {
    "fr1_xyz/rpe/0.2m/est": (FR1, {"metric": "rpe", "delta": 0.2},
        ["--strategy", "distance", "--distance", "0.2", "--chained", "--pairs-from", "estimate"],
        "rpe"),
    "fr2_desk/rpe/1m/est": (FR2, {"metric": "rpe", "delta": 1.0},
        ["--strategy", "distance", "--distance", "1", "--chained", "--pairs-from", "estimate"],
        "rpe"),
    "fr1_xyz/ape/se3/n50": (FR1, {"metric": "ape", "align": True, "n": 50},
        ["--ate", "--n-to-align", "50"], "se3"),
    "fr2_desk/ape/origin": (FR2, {"metric": "ape", "origin": True}, ["--ate"], "origin"),
    "fr1_xyz/ape/se3/window": (FR1, {"metric": "ape", "align": True, "t_offset": 0.004,
                                     "t_start": 1305031105.0, "t_end": 1305031120.0},
        ["--ate", "--t-offset", "0.004", "--t-start", "1305031105", "--t-end", "1305031120"],
        "se3"),
}  # fmt: skip
EVO = {
    "fr1_xyz/rpe/0.2m/est": {
        "trans": {
            "rmse": 0.01772389805918355,
            "mean": 0.016164238953614705,
            "max": 0.034528676957711474,
            "min": 0.004179747864432652,
            "count": 41,
        },
        "rot": {
            "rmse": 0.016390764045615472,
            "mean": 0.014257375968362827,
            "max": 0.03475526927949418,
            "min": 0.000803358220255458,
            "count": 41,
        },
    },
    "fr2_desk/rpe/1m/est": {
        "trans": {
            "rmse": 0.011671538090785612,
            "mean": 0.010632208676522929,
            "max": 0.02193402236823489,
            "min": 0.0031070527919776257,
            "count": 19,
        },
        "rot": {
            "rmse": 0.011996366030730591,
            "mean": 0.010509789178481558,
            "max": 0.025672078656947442,
            "min": 0.004238402189735835,
            "count": 19,
        },
    },
    "fr1_xyz/ape/se3/n50": {
        "trans": {
            "rmse": 0.0237089993930142,
            "mean": 0.020997583315485974,
            "max": 0.061811883567353926,
            "min": 0.0019065319529535654,
            "count": 785,
        },
        "rot": {
            "rmse": 0.11418932661112301,
            "mean": 0.11411531569838439,
            "max": 0.12610544209215452,
            "min": 0.09734677531943069,
            "count": 785,
        },
    },
    "fr2_desk/ape/origin": {
        "trans": {
            "rmse": 0.042015511713436704,
            "mean": 0.034069931767972746,
            "max": 0.08431421697474216,
            "min": 0.0,
            "count": 2174,
        },
        "rot": {
            "rmse": 0.022246155842200483,
            "mean": 0.020129756446215355,
            "max": 0.05379110837440534,
            "min": 0.0,
            "count": 2174,
        },
    },
    "fr1_xyz/ape/se3/window": {
        "trans": {
            "rmse": 0.012570761743941993,
            "mean": 0.011066717204793942,
            "max": 0.035695431990568315,
            "min": 7.526258230648793e-05,
            "count": 443,
        },
        "rot": {
            "rmse": 0.040293641307985587,
            "mean": 0.03960215201146898,
            "max": 0.06722085710158002,
            "min": 0.014086914868353291,
            "count": 443,
        },
    },
}
EVO_PYTHON = ROOT / "benchmarks" / ".venv-evo" / "bin" / "python"
EVO_SCRIPT = textwrap.dedent(
    """
    import copy, json, sys
    import evo
    from evo.core import metrics, sync
    from evo.core.metrics import PoseRelation, Unit
    from evo.tools import file_interface
    data, cases = sys.argv[1], json.loads(sys.argv[2])
    out = {}
    for c in cases:
        ref = file_interface.read_tum_trajectory_file(data + "/" + c["gt"])
        e = file_interface.read_tum_trajectory_file(data + "/" + c["est"])
        if c.get("t_start") is not None or c.get("t_end") is not None:
            ref.reduce_to_time_range(c.get("t_start"), c.get("t_end"))
        ref, e = sync.associate_trajectories(ref, e, max_diff=0.01,
                                             offset_2=c.get("t_offset", 0.0))
        res = {}
        for part, rel in (("trans", PoseRelation.translation_part),
                          ("rot", PoseRelation.rotation_angle_rad)):
            if c["metric"] == "rpe":
                m = metrics.RPE(rel, c["delta"], Unit.meters, all_pairs=False,
                                pairs_from_reference=False)
                m.process_data((ref, e))
            else:
                ee = copy.deepcopy(e)
                if c.get("origin"):
                    ee.align_origin(ref)
                elif c.get("align"):
                    ee.align(ref, correct_scale=False, n=c.get("n", -1))
                m = metrics.APE(rel)
                m.process_data((ref, ee))
            st = m.get_all_statistics()
            res[part] = {k: float(st[k]) for k in ("rmse", "mean", "max", "min")}
            res[part]["count"] = int(len(m.error))
        out[c["name"]] = res
    print(json.dumps(out))
    """
)


def _slamrel(tmp_path, files, options, kind):
    gt, est = (require_data("tum_rgbd", f) for f in files)
    j = tmp_path / "r.json"
    args = ["evaluate", str(gt), str(est), "--reference-format", "tum", "--sync",
            "--max-time-diff", "0.01", *options, "--json", str(j), "-q"]  # fmt: skip
    assert main(args) == 0
    res = json.loads(j.read_text())
    if kind == "rpe":
        return {"trans": res["translation"]["abs"], "rot": res["rotation"]["abs"]}
    row = res["ate"][kind]
    return {"trans": row["translation"], "rot": row["rotation"]}


def _check(ours, theirs):
    for part in ("trans", "rot"):
        assert ours[part]["count"] == theirs[part]["count"], part
        for key in ("rmse", "mean", "max", "min"):
            assert ours[part][key] == pytest.approx(theirs[part][key], abs=TOL), (part, key)


@pytest.mark.parametrize("name", list(CASES))
def test_evo_options_to_1e9(tmp_path, name):
    files, _, options, kind = CASES[name]
    _check(_slamrel(tmp_path, files, options, kind), EVO[name])


def test_stored_numbers_are_evos_live():
    if not EVO_PYTHON.exists():
        pytest.skip("benchmarks/.venv-evo absent: the stored numbers are checked above")
    data = require_data("tum_rgbd")
    cases = [{"name": n, "gt": f[0], "est": f[1], **kw} for n, (f, kw, _, _) in CASES.items()]
    out = subprocess.run([str(EVO_PYTHON), "-c", EVO_SCRIPT, str(data), json.dumps(cases)],
                         capture_output=True, text=True, timeout=300, check=True)  # fmt: skip
    live = json.loads(out.stdout)
    for name in CASES:
        _check(live[name], EVO[name])
