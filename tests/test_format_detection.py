"""Format from the extension first; content sniffing only where the extension says nothing;
an evaluate REFERENCE that reads two ways is an error naming both readings."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from relation_metric.errors import InputError
from slamrel.cli import main
from slamrel.formats.trajectories import detect_trajectory_format, read_trajectory

PLAIN = "0 0 0 0\n1 1 0 0\n2 2 0 0\n"
EIGHT = "0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n"


@pytest.mark.parametrize(
    "name,text,fmt",
    [
        ("a.tum", PLAIN, "tum"),  # the extension decides, even against the content
        ("a.TUM", EIGHT, "tum"),
        ("a.log", EIGHT, "carmen"),
        ("a.clf", "", "carmen"),
        ("a.csv", PLAIN, "csv"),
        ("a.g2o", PLAIN, "g2o"),
        ("a.txt", EIGHT, "tum"),  # sniffed
        ("a.dat", PLAIN, "plain"),
        ("noext", "VERTEX_SE2 0 1 2 3\n", "g2o"),
        ("a.txt", "t,x,y,theta\n0,1,2,3\n", "csv"),
        ("a.other", "ODOM 1 2 3 0 0 0 1 h 0\n", "carmen"),
    ],
)
def test_extension_first_then_content(tmp_path, name, text, fmt):
    p = tmp_path / name
    p.write_text(text)
    assert detect_trajectory_format(p) == fmt


def test_extension_decides_the_reader(tmp_path):
    p = tmp_path / "a.tum"
    p.write_text(PLAIN)
    with pytest.raises(InputError, match="a.tum:1: .*8"):
        read_trajectory(p)
    assert len(read_trajectory(p, format="plain").trajectory) == 3  # --format overrides


@pytest.mark.parametrize("name", ["r.relations", "r.rel"])
def test_relations_file_is_no_trajectory(tmp_path, name):
    p = tmp_path / name
    p.write_text(EIGHT)
    with pytest.raises(InputError, match="holds relations between poses, not a trajectory"):
        read_trajectory(p)


def _walk(rng, n):
    t = 1.0e9 + np.arange(n) * 0.5
    th = np.cumsum(rng.normal(0, 0.3, n))
    xy = np.cumsum(np.column_stack((np.cos(th), np.sin(th))) * 0.5, axis=0)
    return t, np.column_stack((xy, th))


def _tum(path, t, poses):
    rows = [
        f"{a!r} {x!r} {y!r} 0 0 0 {float(np.sin(th / 2))!r} {float(np.cos(th / 2))!r}\n"
        for a, (x, y, th) in zip(t.tolist(), poses.tolist())
    ]
    path.write_text("# t x y z qx qy qz qw\n" + "".join(rows))
    return path


def _consecutive_errors(ref, est):
    """Hand oracle: ‖δ − δ*‖ of pose k → k+1 relations, δ = R(θ_k)ᵀ (p_k+1 − p_k)."""

    def rel(p):
        d = p[1:, :2] - p[:-1, :2]
        c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
        return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))

    return np.hypot(*(rel(est) - rel(ref)).T)


@pytest.fixture
def tum_pair(tmp_path, rng):
    t, ref = _walk(rng, 60)
    est = ref + np.column_stack((rng.normal(0, 0.02, (60, 2)), np.zeros(60)))
    oracle = float(_consecutive_errors(ref, est).mean())
    return _tum(tmp_path / "ref.tum", t, ref), _tum(tmp_path / "est.tum", t, est), oracle


def _mean(capsys, tmp_path, *argv):
    js = tmp_path / "out.json"
    code = main(["evaluate", *map(str, argv), "--json", str(js), "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    res = json.loads(js.read_text())
    return res["translation"]["abs"]["mean"], res


@pytest.mark.parametrize("mode", ["metricevaluator", "paper"])
def test_tum_reference_is_a_trajectory_without_strategy(tmp_path, capsys, tum_pair, mode):
    # used to be read as a .relations file: 14.6 m in metricevaluator mode instead of ~0.025
    ref, est, oracle = tum_pair
    assert 0.015 < oracle < 0.04
    mean, res = _mean(capsys, tmp_path, ref, est, "--mode", mode)
    assert mean == pytest.approx(oracle, rel=1e-9)
    assert res["relations"] == 59 and res["reference_repeated_times_dropped"] == 0


def test_eight_column_txt_reference_is_told_apart_by_its_quaternions(tmp_path, capsys, tum_pair):
    """A .txt says nothing: unit quaternions in every row → TUM; evo's own files are .txt, so
    60 rows are read without a warning; 5 rows (unit norms by accident are thinkable) warn."""
    ref, est, oracle = tum_pair
    txt = tmp_path / "ref.txt"
    shutil.copy(ref, txt)
    js = tmp_path / "out.json"
    assert main(["evaluate", str(txt), str(est), "--json", str(js), "-q"]) == 0
    assert capsys.readouterr().err == ""
    short = tmp_path / "short.txt"
    short.write_text("".join(ref.read_text().splitlines(keepends=True)[:5]))
    assert main(["evaluate", str(short), str(est), "-q"]) == 0
    err = capsys.readouterr().err
    assert f"{short}: read as a TUM trajectory (every row ends in a unit quaternion)" in err
    assert "--reference-format tum" in err
    assert json.loads(js.read_text())["translation"]["abs"]["mean"] == pytest.approx(
        oracle, rel=1e-9
    )
    for option in (["--reference-format", "tum"], ["--strategy", "consecutive"]):
        assert _mean(capsys, tmp_path, txt, est, *option)[0] == pytest.approx(oracle, rel=1e-9)


def test_relations_in_a_txt_file_are_read_as_relations_with_a_warning(tmp_path, capsys):
    rel = "0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0\n"
    (tmp_path / "rel.txt").write_text(rel)
    (tmp_path / "est.txt").write_text("0 0 0 0\n1 1.5 0 0\n2 3 0 0\n")
    mean, res = _mean(capsys, tmp_path, tmp_path / "rel.txt", tmp_path / "est.txt")
    assert res["relations"] == 2 and mean == pytest.approx(0.5)  # hand: 1.5 m against 1 m
    js = tmp_path / "o.json"
    assert main(["evaluate", str(tmp_path / "rel.txt"), str(tmp_path / "est.txt"), "-q"]) == 0
    assert "read as Freiburg relations" in capsys.readouterr().err
    shutil.copy(tmp_path / "rel.txt", tmp_path / "rel.relations")
    assert _mean(capsys, tmp_path, tmp_path / "rel.relations", tmp_path / "est.txt")[0] == mean
    assert not js.exists()


def test_one_row_of_eight_that_fits_both_readings_is_refused(tmp_path, capsys):
    (tmp_path / "r.txt").write_text("0 1 0 0 0 0 0 1\n")
    (tmp_path / "e.txt").write_text(PLAIN)
    assert main(["evaluate", str(tmp_path / "r.txt"), str(tmp_path / "e.txt")]) == 3
    err = capsys.readouterr().err
    assert f"{tmp_path / 'r.txt'}: ambiguous reference" in err
    for words in (".relations", "TUM trajectory", "--reference-format tum", "--strategy"):
        assert words in err


def test_relations_file_with_strategy_is_refused(tmp_path, capsys):
    (tmp_path / "r.relations").write_text("0 1 1 0 0 0 0 0\n")
    (tmp_path / "e.txt").write_text(PLAIN)
    argv = ["evaluate", str(tmp_path / "r.relations"), str(tmp_path / "e.txt")]
    assert main(argv + ["--strategy", "consecutive"]) == 2  # a usage error
    assert "drop --strategy" in capsys.readouterr().err


def test_unrecognised_reference_mentions_both_kinds(tmp_path, capsys):
    (tmp_path / "r.txt").write_text("0 1 2\n")
    (tmp_path / "e.txt").write_text(PLAIN)
    assert main(["evaluate", str(tmp_path / "r.txt"), str(tmp_path / "e.txt")]) == 3
    err = capsys.readouterr().err
    assert f"{tmp_path / 'r.txt'}: cannot recognise the reference" in err
    assert ".relations" in err and "--reference-format" in err


def test_estimate_format_option_overrides_the_extension(tmp_path, capsys):
    (tmp_path / "r.relations").write_text("0 1 1 0 0 0 0 0\n1 2 1 0 0 0 0 0\n")
    (tmp_path / "e.log").write_text("0 0 0 0\n1 1.5 0 0\n2 3 0 0\n")
    argv = ["evaluate", str(tmp_path / "r.relations"), str(tmp_path / "e.log")]
    assert main(argv + ["-q"]) == 3  # read as CARMEN, as its extension says
    err = capsys.readouterr().err
    assert "e.log: no poses found (read as carmen)" in err and "--format" in err
    assert _mean(capsys, tmp_path, *argv[1:], "--format", "plain")[0] == pytest.approx(0.5)
