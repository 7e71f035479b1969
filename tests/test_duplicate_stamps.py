"""``--duplicate-stamps`` of ``slamrel evaluate`` and ``slamrel traj convert``: files with
repeated timestamps read as evo reads them, on request, counted and said.

The input is the estimate of ``tests/test_evo_cli.py`` with 4 rows written twice at one time
(evo's EuRoC ``V102.txt`` case, :func:`test_evo_cli._repeated_pair`). Oracles:

- evo 1.38.1's own numbers for these files (:data:`EVO`, its ``stats.json``):
  ``evo_ape euroc data.csv est_rep.tum -as`` and ``evo_rpe euroc data.csv est_rep.tum -d 5``;
  ``evaluate --sync --max-time-diff 0.01`` with ``--duplicate-stamps keep`` gives them in its
  sim3 ATE row and its chained relations of step 5 (docs/evo.md's equivalences);
- the input file's own rows for ``traj convert``: ``keep`` writes every row in file order (as
  ``evo_traj --save_as_tum`` does, checked live in ``test_evo_cli.py``), ``first`` the first
  row of each timestamp.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evo_cli import _repeated_pair

from slamrel.cli import main

TOL = 1e-9
#: evo 1.38.1 on the files of :func:`_repeated_pair` (statistics of its result zips; ``std``
#: left out: evo's is the population std, the JSON's the sample std).
EVO = {
    "ape_as": {
        "rmse": 0.02113800993518426,
        "mean": 0.01771452759319638,
        "median": 0.01668784722395268,
        "min": 0.0014496188656617265,
        "max": 0.08891660802898424,
        "count": 204,
    },
    "rpe_5f": {
        "rmse": 0.027083346367485137,
        "mean": 0.02539699183611057,
        "median": 0.025339493980656304,
        "min": 0.007284138590444881,
        "max": 0.04607047308006109,
        "count": 40,
    },
}


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    gt, est, _, _ = _repeated_pair(tmp_path)
    return gt, est


def _evaluate(gt: Path, est: Path, out: Path, *options: str) -> dict:
    args = ["evaluate", str(gt), str(est), "--sync", "--max-time-diff", "0.01", *options]
    assert main([*args, "--json", str(out), "-q"]) == 0
    return json.loads(out.read_text())


def _close(ours: dict, evo: dict) -> None:
    for key, value in evo.items():
        assert ours[key] == pytest.approx(value, rel=TOL), key


def test_evaluate_refuses_by_default_naming_the_option(
    files: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    gt, est = files
    assert main(["evaluate", str(gt), str(est), "--sync", "--ate", "-q"]) == 3
    err = capsys.readouterr().err
    assert f"{est}:52:" in err and "--duplicate-stamps keep reads it as evo does" in err
    assert "Traceback" not in err


def test_evaluate_keep_gives_evos_numbers(
    files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gt, est = files
    ate = _evaluate(gt, est, tmp_path / "a.json", "--ate", "--duplicate-stamps", "keep")
    assert "kept all 4 estimate pose(s)" in capsys.readouterr().err
    assert ate["estimate_repeated_times"] == {"count": 4, "differing": 4, "first_line": 52}
    _close(ate["ate"]["sim3"]["translation"], EVO["ape_as"])
    rpe = _evaluate(
        gt, est, tmp_path / "r.json", "--step", "5", "--chained", "--duplicate-stamps", "keep"
    )
    _close(rpe["translation"]["abs"], EVO["rpe_5f"])


def test_evaluate_first_drops_the_later_poses(files: tuple[Path, Path], tmp_path: Path) -> None:
    """``first``: the numbers of the file with the 4 later rows deleted by hand."""
    gt, est = files
    rows = np.loadtxt(est)
    _, first = np.unique(rows[:, 0], return_index=True)
    clean = tmp_path / "clean.tum"
    np.savetxt(clean, rows[np.sort(first)], fmt="%.17g")
    assert np.sort(first).size == rows.shape[0] - 4
    got = _evaluate(gt, est, tmp_path / "f.json", "--ate", "--duplicate-stamps", "first")
    want = _evaluate(gt, clean, tmp_path / "c.json", "--ate")
    assert got["ate"] == want["ate"]
    assert got["estimate_repeated_times"]["count"] == 4


def test_convert_refuses_keeps_or_takes_the_first(
    files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, est = files
    rows = np.loadtxt(est)
    out = tmp_path / "out.tum"
    assert main(["traj", "convert", str(est), "-o", str(out)]) == 3
    assert "--duplicate-stamps keep" in capsys.readouterr().err and not out.exists()
    assert main(["traj", "convert", str(est), "-o", str(out), "--duplicate-stamps", "keep"]) == 0
    said = capsys.readouterr()
    assert "204 3-D poses" in said.out and "4 repeated timestamp(s) written" in said.out
    assert "kept all 4 estimate pose(s)" in said.err
    written = np.loadtxt(out)
    np.testing.assert_allclose(written[:, :4], rows[:, :4], rtol=1e-15, atol=0)
    dots = np.abs(np.einsum("ni,ni->n", written[:, 4:], rows[:, 4:]))
    np.testing.assert_allclose(dots, 1.0, atol=1e-12)  # the same rotations (sign free)
    first = tmp_path / "first.tum"
    argv = ["traj", "convert", str(est), "-o", str(first), "--duplicate-stamps", "first"]
    assert main(argv) == 0
    assert "200 3-D poses" in capsys.readouterr().out
    _, keep = np.unique(rows[:, 0], return_index=True)
    np.testing.assert_allclose(np.loadtxt(first)[:, :4], rows[np.sort(keep), :4], rtol=1e-15)
