"""``slamrel run``: the report folder, its numbers, and interrupted runs."""

from __future__ import annotations

import json
import re

import pytest

import slamrel.pipeline as pipeline
from slamrel.cli import main


def test_run_writes_a_consistent_report(tmp_path):
    out = tmp_path / "rep"
    assert main(["run", "simple2", "--noise", "b", "--seed", "1", "-o", str(out), "-q"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"report.html", "metrics.json", "figure_1.png", "bundle"} <= names
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["trajectory"]["translation"]["abs"]["count"] > 0
    assert set(metrics["trajectory"]["by_relation_set"]) == {"consecutive", "loops", "global"}
    assert "dead_reckoning" in metrics
    html = (out / "report.html").read_text()
    # every mean in the report's translation table equals metrics.json (3 significant digits)
    trans_table = html.split("translation relation error")[1].split("</table>")[0]
    cells = re.findall(r"<tr><td>(\w+)</td><td>(\w+)</td><td>([^<]+)</td>", trans_table)
    shown = {(a, b): float(c) for a, b, c in cells}
    source = metrics["trajectory_source"]
    for name, key in ((source, "trajectory"), ("dead_reckoning", "dead_reckoning")):
        assert shown[(name, "all")] == pytest.approx(
            metrics[key]["translation"]["abs"]["mean"], rel=5e-3
        )
        for rs, ev in metrics[key]["by_relation_set"].items():
            assert shown[(name, rs)] == pytest.approx(ev["translation"]["abs"]["mean"], rel=5e-3)
    # SLAM beats dead reckoning on global relations
    g = metrics["trajectory"]["by_relation_set"]["global"]["translation"]["abs"]["mean"]
    assert g < metrics["dead_reckoning"]["by_relation_set"]["global"]["translation"]["abs"]["mean"]
    # the per-relation CSVs name each relation's set, and compare tests the sets one by one
    from slamrel.report.tables import compare_results, read_per_relation

    rec = read_per_relation(out / f"relations_{source}.csv", dataset="d", algorithm="slam")
    dr = read_per_relation(out / "relations_dead_reckoning.csv", dataset="d", algorithm="dr")
    by_set = metrics["trajectory"]["by_relation_set"]
    assert {s: int((rec.sets == s).sum()) for s in by_set} == {
        s: ev["translation"]["abs"]["count"] for s, ev in by_set.items()
    }
    tests = compare_results([rec, dr], resamples=199).tests
    assert [(t.relation_set, t.part) for t in tests] == [
        (s, p) for s in ("consecutive", "loops", "global") for p in ("translation", "rotation")
    ]


@pytest.mark.slow
def test_interrupted_run_leaves_no_partial_report(tmp_path, monkeypatch):
    out = tmp_path / "rep"

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "render_html", boom)
    assert main(["run", "simple1", "-o", str(out), "-q"]) == 130
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_run_on_a_bundle_directory(tmp_path):
    sim, slam, rep = tmp_path / "sim", tmp_path / "slam", tmp_path / "rep"
    assert main(["simulate", "simple2", "--seed", "3", "-o", str(sim), "-q"]) == 0
    assert main(["slam", str(sim), "-o", str(slam), "--store-online", "-q"]) == 0
    assert main(["run", str(slam), "-o", str(rep), "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    assert m["trajectory_source"] == "recovered" and "online" in m and "dead_reckoning" in m
    assert m["map"]["association"]["matched"] > 100
    assert (
        m["trajectory"]["by_relation_set"]["global"]["translation"]["abs"]["mean"]
        < (m["dead_reckoning"]["by_relation_set"]["global"]["translation"]["abs"]["mean"])
    )
    # without ground truth: a report of what needs none (tests/test_run_without_truth.py),
    # the online estimate compared with the recovered one instead of scored
    (slam / "groundtruth.csv").unlink()
    assert main(["run", str(slam), "-o", str(tmp_path / "rep2"), "-q"]) == 0
    m = json.loads((tmp_path / "rep2" / "metrics.json").read_text())
    assert "trajectory" not in m and "online" not in m and m["nees"] == {}
    diff = m["online_vs_recovered"]
    assert set(diff["by_relation_set"]) <= {"consecutive", "loops", "global"}
    assert 0 < diff["translation"]["abs"]["mean"] < 1.0


def test_run_on_a_broken_slam_run_reports_divergence(tmp_path, capsys, broken_run):
    """Divergence is a finding: exit 0, a report with the stretches; --fail-on-divergence
    exits 3 but still writes the report, scoring dead reckoning (and the online estimate)."""
    out, text = broken_run.folder, broken_run.printed  # slamrel run simple1 --corrupt 0.1
    assert "DISAGREE" in text and "np.float64" not in text
    m = json.loads((out / "metrics.json").read_text())
    assert m["trajectory_source"] == "recovered" and m["recovery_error"] is None
    d = m["divergence"]
    assert d["diverged"] and d["count"] == len(d["stretches"]) >= 1
    assert 0.0 < d["fraction_of_log"] <= 1.0
    # written once, at the top level (with the NEES blow-ups), not again in the recovery's part
    assert "divergence" not in m["recovery"] and m["recovery"]["nis"]["mean"] > 2.0
    assert "nees_stretches" in d
    # a broken run scores as broken: recovered far-apart error near the online one
    rec = m["trajectory"]["by_relation_set"]["global"]["translation"]["abs"]["mean"]
    onl = m["online"]["by_relation_set"]["global"]["translation"]["abs"]["mean"]
    assert rec > 0.5 * onl
    html = (out / "report.html").read_text()
    assert "Map–log agreement" in html and "stretches where the map and the log disagree" in html
    out2 = tmp_path / "rep2"
    assert main(["run", "simple1", "--corrupt", "0.1", "-o", str(out2), "-q",
                 "--fail-on-divergence"]) == 3  # fmt: skip
    err = capsys.readouterr().err
    assert "no trajectory recovered" in err and "np.float64" not in err
    m2 = json.loads((out2 / "metrics.json").read_text())
    assert m2["trajectory_source"] == "online" and "recovered" not in m2
    assert m2["dead_reckoning"]["translation"]["abs"]["count"] > 0
    assert "consecutive innovations" in m2["recovery_error"]
    assert "No trajectory was recovered" in (out2 / "report.html").read_text()
