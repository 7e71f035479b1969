"""data/: regenerating gives the committed bytes, and the README's "Try it" commands run."""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
from pathlib import Path

import numpy as np

from slamrel.cli import main
from slamrel.formats.bundle import read_bundle
from slamrel.formats.trajectories import read_trajectory

DATA = Path(__file__).resolve().parent.parent / "data"
MADE = ("example", "sim-bundle")  # the folders data/make_data.py writes


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for folder in MADE
        for p in sorted((root / folder).rglob("*"))
        if p.is_file()
    }


_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _same_up_to_last_digits(a: bytes, b: bytes) -> bool:
    """The same text with every number equal within 1e-10 relative (1e-12 absolute): numpy's
    trigonometric functions may differ in the last bit between releases and CPUs (numpy 2.4
    turned 8 of 115 bearings one ulp; integrated over 600 steps of example/estimate.txt, at
    most 4.5e-14 m), so regenerating is byte-exact only on one numpy build."""
    if _NUMBER.sub(b"#", a) != _NUMBER.sub(b"#", b):
        return False
    x = np.array([float(t) for t in _NUMBER.findall(a)])
    y = np.array([float(t) for t in _NUMBER.findall(b)])
    return x.shape == y.shape and bool(np.allclose(x, y, rtol=1e-10, atol=1e-12))


def test_regenerating_the_data_gives_the_same_bytes(tmp_path):
    spec = importlib.util.spec_from_file_location("make_data", DATA / "make_data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.make(tmp_path)
    committed, fresh = _files(DATA), _files(tmp_path)
    assert sorted(committed) == sorted(fresh)
    assert len(committed) >= 9
    changed = [
        name
        for name in committed
        if committed[name] != fresh[name]
        and not _same_up_to_last_digits(committed[name], fresh[name])
    ]
    assert not changed, f"data/ differs from data/make_data.py's output: {changed}"


def test_the_regeneration_check_sees_a_changed_digit():
    assert _same_up_to_last_digits(b"t,x\n1,0.75905421718280253\n", b"t,x\n1,0.75905421718280242\n")
    assert not _same_up_to_last_digits(b"t,x\n1,0.75905421\n", b"t,x\n1,0.75905422\n")
    assert not _same_up_to_last_digits(b"t,x\n1,0.5\n", b"t,y\n1,0.5\n")


def test_the_data_is_what_its_readme_says(tmp_path):
    """Oracle: the README's numbers, recomputed from the files."""
    ref = read_trajectory(DATA / "example" / "reference.txt").trajectory
    est = read_trajectory(DATA / "example" / "estimate.txt").trajectory
    assert len(ref) == len(est) == 600
    np.testing.assert_array_equal(ref.timestamps, 0.5 * np.arange(600))
    np.testing.assert_array_equal(est.poses[0], ref.poses[0])  # dead reckoning from the start
    span = ref.poses[:, :2].max(axis=0) - ref.poses[:, :2].min(axis=0)
    np.testing.assert_allclose(span, [40.0, 20.0], atol=0.01)
    b = read_bundle(DATA / "sim-bundle")
    assert b.controls.shape == (100, 3) and b.map_ids.size == 8
    assert b.measurements.shape == (115, 2) and b.measurement_associated.all()
    assert b.map_covariance.shape == (16, 16) and b.groundtruth is not None
    assert (DATA / "README.md").is_file()


def _readme_try_it() -> list[list[str]]:
    """The ``slamrel`` command lines of the README that use data/, comments dropped."""
    readme = (DATA.parent / "README.md").read_text(encoding="utf-8")
    lines = [ln.split("#")[0].strip() for ln in readme.splitlines()]
    return [shlex.split(ln)[1:] for ln in lines if ln.startswith("slamrel ") and " data/" in ln]


def test_readme_try_it_commands_run(tmp_path, monkeypatch, capsys):
    """Run exactly as written, from a folder where data/ is the project's data/."""
    commands = _readme_try_it()
    assert [c[0] for c in commands] == ["evaluate", "recover", "evaluate"]
    (tmp_path / "data").symlink_to(DATA, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        assert main([*argv, "-q"]) == 0, argv
        assert capsys.readouterr().err == ""
    assert (tmp_path / "recovered.txt").is_file()
    assert main(["slam", "data/sim-bundle", "-o", "slam", "-q"]) == 0  # data/README.md's 4th


def test_recovered_bundle_scores_against_its_ground_truth(tmp_path, capsys):
    """recover, then evaluate against the bundle's groundtruth.csv: a good map and log give
    centimetre-level global relation errors."""
    out = tmp_path / "recovered.txt"
    assert main(["recover", str(DATA / "sim-bundle"), "-o", str(out), "-q"]) == 0
    js = tmp_path / "e.json"
    argv = ["evaluate", str(DATA / "sim-bundle"), str(out), "--strategy", "global"]
    assert main([*argv, "--json", str(js), "-q"]) == 0
    t = json.loads(js.read_text())["translation"]["abs"]
    assert t["count"] > 0 and t["mean"] < 0.1
