"""``slamrel evaluate`` / ``relations generate`` / ``example``: outputs, exit codes, messages."""

from __future__ import annotations

import json
import re
import zipfile
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def example(tmp_path):
    assert main(["example", "-o", str(tmp_path / "ex"), "-q"]) == 0
    return tmp_path / "ex"


def test_json_structure_and_consistency(example, tmp_path):
    out = tmp_path / "m.json"
    per = tmp_path / "per.csv"
    code = main(
        [
            "evaluate",
            str(example / "reference.relations"),
            str(example / "estimate.txt"),
            "--json",
            str(out),
            "--per-relation",
            str(per),
            "-q",
        ]
    )
    assert code == 0
    res = json.loads(out.read_text())
    for key in (
        "relations",
        "associated_by_odometry",
        "unassociated",
        "rotation_unit",
        "translation",
        "rotation",
    ):
        assert key in res
    for part in ("translation", "rotation"):
        for kind in ("abs", "sqr"):
            assert set(res[part][kind]) == {"mean", "std", "min", "max", "median", "rmse", "count"}
    assert res["rotation_unit"] == "rad"
    rows = np.genfromtxt(per, delimiter=",", names=True)
    assert rows.shape[0] == res["relations"]
    # the per-relation CSV and the JSON agree: an independent recomputation of the statistics
    assert rows["trans_error"].mean() == pytest.approx(res["translation"]["abs"]["mean"], rel=1e-6)
    assert (rows["trans_error"] ** 2).mean() == pytest.approx(
        res["translation"]["sqr"]["mean"], rel=1e-6
    )
    assert rows["rot_error_rad"].std(ddof=1) == pytest.approx(
        res["rotation"]["abs"]["std"], rel=1e-6
    )


def test_degrees(example, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    main(
        [
            "evaluate",
            str(example / "reference.relations"),
            str(example / "estimate.txt"),
            "--json",
            str(a),
            "-q",
        ]
    )
    main(
        [
            "evaluate",
            str(example / "reference.relations"),
            str(example / "estimate.txt"),
            "--json",
            str(b),
            "--degrees",
            "-q",
        ]
    )
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    assert rb["rotation_unit"] == "deg"
    assert rb["rotation"]["abs"]["mean"] == pytest.approx(np.degrees(ra["rotation"]["abs"]["mean"]))
    assert rb["translation"] == ra["translation"]


def test_evo_zip_layout(example, tmp_path):
    z = tmp_path / "res.zip"
    assert (
        main(
            [
                "evaluate",
                str(example / "reference.relations"),
                str(example / "estimate.txt"),
                "--evo-zip",
                str(z),
                "-q",
            ]
        )
        == 0
    )
    with zipfile.ZipFile(z) as archive:
        names = set(archive.namelist())
        assert {"info.json", "stats.json", "error_array.npy"} <= names
        info = json.loads(archive.read("info.json"))
        stats = json.loads(archive.read("stats.json"))
        err = np.load(BytesIO(archive.read("error_array.npy")))
    assert {"title", "ref_name", "est_name", "label"} <= set(info)
    assert stats["rmse"] == pytest.approx(np.sqrt(np.mean(err**2)))
    assert stats["std"] == pytest.approx(np.std(err))  # evo's population std
    assert stats["sse"] == pytest.approx(np.sum(err**2))


def test_plot_is_written(example, tmp_path):
    png = tmp_path / "p.png"
    assert (
        main(
            [
                "evaluate",
                str(example / "reference.relations"),
                str(example / "estimate.txt"),
                "--plot",
                str(png),
                "-q",
            ]
        )
        == 0
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_reference_trajectory_with_strategy_and_ate(example, tmp_path):
    out = tmp_path / "g.json"
    code = main(
        [
            "evaluate",
            str(example / "reference.txt"),
            str(example / "estimate.txt"),
            "--strategy",
            "global",
            "--count",
            "300",
            "--ate",
            "--json",
            str(out),
            "-q",
        ]
    )
    assert code == 0
    res = json.loads(out.read_text())
    assert res["relations"] == 300
    assert (
        res["ate"]["se2"]["translation"]["rmse"]
        <= res["ate"]["none"]["translation"]["rmse"] + 1e-12
    )
    assert (
        res["ate"]["sim2"]["translation"]["rmse"]
        <= res["ate"]["se2"]["translation"]["rmse"] + 1e-12
    )


def test_relations_generate_round_trip(example, tmp_path):
    out = tmp_path / "gen.relations"
    assert (
        main(
            [
                "relations",
                "generate",
                str(example / "reference.txt"),
                "--strategy",
                "distance",
                "--distance",
                "5",
                "-o",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    res = tmp_path / "r.json"
    # scoring the reference against its own relations gives zero error
    assert (
        main(["evaluate", str(out), str(example / "reference.txt"), "--json", str(res), "-q"]) == 0
    )
    assert json.loads(res.read_text())["translation"]["abs"]["max"] < 1e-6


def _bad(tmp_path, capsys, rel_text, est_text, *extra):
    rel = tmp_path / "r.relations"
    est = tmp_path / "e.txt"
    rel.write_text(rel_text)
    est.write_text(est_text)
    code = main(["evaluate", str(rel), str(est), "-q", *extra])
    return code, capsys.readouterr().err


GOOD_REL = "0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0\n"
GOOD_EST = "0 0 0 0\n1 1 0 0\n2 2 0 0\n"


@pytest.mark.parametrize(
    "case,rel,est,where,what",
    [
        (
            "truncated line before the last",
            GOOD_REL,
            "0 0 0 0\n1 1 0\n2 2 0 0\n",
            "e.txt:2",
            "expected 4 fields",
        ),
        ("letters in a number", GOOD_REL, "0 0 0 0\n1 1 0 0\n2 2o 0 0\n", "e.txt:3", "got '2o'"),
        ("NaN", "0 1 nan 0 0 0 0 0\n", GOOD_EST, "r.relations:1", "finite"),
        ("empty file", "", GOOD_EST, "r.relations", "no data"),
        (
            "relations line with wrong field count",
            "0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0 9\n",
            GOOD_EST,
            "r.relations:2",
            "expected 8 fields",
        ),
        (
            "another time base",
            "1e9 1000000001 1 0 0 0 0 0\n",
            GOOD_EST,
            "",
            "relations span 1000000000.000000 .. 1000000001.000000 s, "
            "the estimate 0.000000 .. 2.000000 s",
        ),
    ],
)
def test_bad_input_exit_code_3(tmp_path, capsys, case, rel, est, where, what):
    code, err = _bad(tmp_path, capsys, rel, est)
    assert code == 3, case
    assert where in err and what in err, err


def test_some_unassociated_warn_and_strict(tmp_path, capsys):
    rel = GOOD_REL + "5 6 1 0 0 0 0 0\n"
    code, err = _bad(tmp_path, capsys, rel, GOOD_EST)
    assert code == 0
    # the warning names the estimate and the relations file
    assert re.search(
        r"warning: \S*e\.txt: 1 of 3 relations of \S*r\.relations could not be associated"
        r".*#2 \(5\.000000 -> 6\.000000",
        err,
    ), err
    code, err = _bad(tmp_path, capsys, rel, GOOD_EST, "--strict")
    assert code == 3 and "--strict" in err and "e.txt: " in err


def test_usage_error_exit_2(tmp_path):
    with pytest.raises(SystemExit) as e:
        main(["evaluate", "--mode", "nonsense", "a", "b"])
    assert e.value.code == 2


def test_refuses_to_overwrite_an_input(example, capsys):
    est = example / "estimate.txt"
    before = est.read_bytes()
    code = main(["evaluate", str(example / "reference.relations"), str(est), "--json", str(est)])
    assert code == 3 and "refusing to overwrite an input" in capsys.readouterr().err
    assert est.read_bytes() == before


def test_readme_commands_are_what_ci_runs():
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", readme, flags=re.S)
    ci = (ROOT / ".ci" / "run").read_text()
    setup, tests = blocks[0].strip(), blocks[1].strip()
    assert setup in ci.splitlines()
    assert tests in ci.splitlines()
