"""Issue 39: batch outputs keyed by everything that changes them; tables quoted; stored
results validated on resume.

The oracles: ``slamrel evaluate --per-relation`` on the same run with the same options (the
per-relation file a batch must hold), Python's :mod:`csv` reader (a quoted name shifts no
column), the cell count of a Markdown row, and the value a first run stored (a result
edited to NaN must be computed again, not trusted).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main


def _runs(root: Path, names: list[str]) -> Path:
    """A folder of run folders ``names`` (planar, seeded, 30 poses each)."""
    rng = np.random.default_rng(7)
    t = np.arange(30) * 0.1
    for k, name in enumerate(names):
        d = root / name
        d.mkdir(parents=True)
        th = np.cumsum(rng.normal(0, 0.05, 30))
        xy = np.cumsum(np.column_stack((np.cos(th), np.sin(th))) * 0.5, axis=0)
        ref = np.column_stack((t, xy, th))
        np.savetxt(d / "reference.txt", ref, fmt="%.9f")
        est = ref + np.column_stack((np.zeros(30), rng.normal(0, 0.02 * (k + 1), (30, 3))))
        np.savetxt(d / "estimate.txt", est, fmt="%.9f")
    return root


def _batch(src: Path, out: Path, *options: str) -> None:
    assert main(["batch", str(src), "-o", str(out), "--workers", "0", "-q", *options]) == 0


def _evaluate_per_relation(run: Path, dest: Path, *options: str) -> bytes:
    argv = ["evaluate", str(run / "reference.txt"), str(run / "estimate.txt")]
    assert main([*argv, "--per-relation", str(dest), "-q", *options]) == 0
    return dest.read_bytes()


def test_per_relation_files_follow_the_options_of_the_run(tmp_path):
    """Options A, then B, then A again (A's results skipped as stored): per_relation/NAME.csv
    used to keep B's relations while table.csv showed A's."""
    src = _runs(tmp_path / "runs", ["r0", "r1"])
    out = tmp_path / "b"
    step2 = _evaluate_per_relation(src / "r1", tmp_path / "a.csv", "--step", "2")
    step3 = _evaluate_per_relation(src / "r1", tmp_path / "b.csv", "--step", "3")
    assert step2 != step3
    target = out / "per_relation" / "r1.csv"
    _batch(src, out, "--step", "2")
    assert target.read_bytes() == step2
    _batch(src, out, "--step", "3")
    assert target.read_bytes() == step3
    _batch(src, out, "--step", "2")  # every result already stored
    assert target.read_bytes() == step2
    # a deleted per-relation file is written again
    target.unlink()
    _batch(src, out, "--step", "2")
    assert target.read_bytes() == step2
    # ... and so is a deleted stored copy (the run is scored again)
    for keyed in (out / "cases").glob("r1-*.csv"):
        keyed.unlink()
    target.unlink()
    assert main(["batch", str(src), "-o", str(out), "--workers", "0", "--step", "2"]) == 0
    assert target.read_bytes() == step2


def test_names_with_separators_shift_no_column(tmp_path):
    names = ["a,b", "c|d", 'e"f']
    src = _runs(tmp_path / "runs", names)
    out = tmp_path / "b"
    _batch(src, out)
    with open(out / "table.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    runs = [r for r in rows if r["kind"] == "run"]
    assert [r["name"] for r in runs] == sorted(names)
    assert all(None not in r and float(r["trans_mean"]) > 0 for r in runs)  # no extra column
    md = (out / "table.md").read_text().splitlines()
    head_cells = md[0].count(" | ") + 1
    for line in md[2:]:
        if line.startswith("|"):
            cells = line.replace("\\|", "").count(" | ") + 1
            assert cells == head_cells, line
    assert "| c\\|d |" in (out / "table.md").read_text()


def test_a_resumed_batch_recomputes_a_result_edited_by_hand(tmp_path, capsys):
    """A stored result edited to hold NaN used to be trusted on resume (the table showed an
    empty cell); its checksum no longer matches, so it is computed again, and said."""
    src = _runs(tmp_path / "runs", ["r0", "r1"])
    out = tmp_path / "b"
    _batch(src, out)
    before = (out / "table.csv").read_text()
    (case,) = (out / "cases").glob("r1-*.json")
    record = json.loads(case.read_text())
    record["result"]["trans_mean"] = float("nan")
    case.write_text(json.dumps(record))
    assert main(["batch", str(src), "-o", str(out), "--workers", "0"]) == 0
    cap = capsys.readouterr()
    assert "(1 run now, 1 already done" in cap.out
    assert f"damaged result {case}: its result does not match the checksum" in cap.err
    assert (out / "table.csv").read_text() == before


@pytest.mark.slow  # 25 s: two pose-only studies
def test_a_resumed_study_recomputes_a_case_edited_to_nan(tmp_path, capsys):
    """The pose-only study resumes through the same sweep: a stored case whose NEES was
    edited to NaN is computed again (it used to be trusted: the table showed nan)."""
    small = ["--worlds", "hu-simple1", "--noise", "a", "--methods", "full,m1"]
    out = tmp_path / "study"
    assert main(["study", "pose-only", "--runs", "1", "-o", str(out), "-q", *small]) == 0
    before = (out / "table.csv").read_bytes()
    case = next(p for p in (out / "cases").glob("*.json") if "_full-" in p.name)
    record = json.loads(case.read_text())
    record["result"]["nees1"] = float("nan")
    case.write_text(json.dumps(record))
    assert main(["study", "pose-only", "--runs", "1", "-o", str(out), *small]) == 0
    cap = capsys.readouterr()
    assert "1 run now, 1 already done" in cap.out, cap.out
    assert "does not match the checksum" in cap.err
    assert (out / "table.csv").read_bytes() == before
