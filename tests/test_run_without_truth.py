"""``slamrel run`` on a bundle without ground truth, with reference relations and a reference
map, and the report's figures showing what their captions say.

Each number is checked against the command that computes it on its own: the recovered
trajectory against ``slamrel recover``, the NIS against ``recover --report``, the scores on
reference relations against ``slamrel evaluate``, the map against ``slamrel map-compare``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main

ROOT = Path(__file__).resolve().parents[1]
SIM_BUNDLE = ROOT / "data" / "sim-bundle"


def _without_truth(tmp_path: Path) -> Path:
    """``data/sim-bundle`` copied, its ground truth (trajectory and landmarks) deleted."""
    b = tmp_path / "bundle"
    shutil.copytree(SIM_BUNDLE, b)
    (b / "groundtruth.csv").unlink()
    (b / "landmarks_groundtruth.csv").unlink()
    return b


def _verdict_rows(html: str) -> dict[str, str]:
    """The verdict's rows: what → level (the lamp's text)."""
    import re

    verdict = html.split('id="verdict"')[1].split("</section>")[0]
    rows = re.findall(r"<tr class=\"[^\"]+\"><td>([^<]+)</td><td>[^<]*</td><td><span "
                      r"class=\"lamp [^\"]+\">([^<]+)</span>", verdict)  # fmt: skip
    return {what.replace("&#x27;", "'"): level for what, level in rows}


def test_run_without_truth_reports_what_needs_none(tmp_path: Path) -> None:
    b = _without_truth(tmp_path)
    rep = tmp_path / "rep"
    assert main(["run", str(b), "-o", str(rep), "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    # no number that needs the truth
    for key in ("trajectory", "dead_reckoning", "online"):
        assert key not in m
    assert m["nees"] == {} and m["nees_truth_frame"] == {} and m["nees_frame"] is None
    assert m["relation_sets"] == [] and m["map"] is None
    assert not list(rep.glob("relations_*.csv"))
    # the recovered trajectory is `slamrel recover`'s, byte for byte; its NIS and robust
    # weights are those recover --report gives
    own = tmp_path / "recovered.txt"
    report = tmp_path / "recover.json"
    assert main(["recover", str(b), "-o", str(own), "--report", str(report), "-q"]) == 0
    assert (rep / "recovered.txt").read_bytes() == own.read_bytes()
    r = json.loads(report.read_text())
    assert m["recovery"]["nis"] == r["nis"] and m["recovery"]["nis"]["count"] > 0
    assert m["recovery"]["measurements"] == r["measurements"]
    assert m["divergence"]["stretches"] == r["divergence"]["stretches"]
    # the verdict judges what needs no truth and names, lamp by lamp, what it could not
    rows = _verdict_rows((rep / "report.html").read_text())
    assert rows["map–log agreement (NIS)"] in ("green", "amber", "red")
    assert rows["down-weighted information"] in ("green", "amber", "red")
    for what in ("recovered vs dead reckoning", "consistency (recovered)", "NEES excursions",
                 "map consistency"):  # fmt: skip
        assert rows[what] == "not judged"
    html = (rep / "report.html").read_text()
    assert "needs ground truth" in html and "as estimated, in the SLAM map" in html


def test_relations_scores_equal_evaluate(tmp_path: Path) -> None:
    """``--relations``: every estimate scored as ``slamrel evaluate RELATIONS EST`` scores it;
    with ground truth nothing else in metrics.json changes."""
    rel = tmp_path / "global.relations"
    assert main(["relations", "generate", str(SIM_BUNDLE), "--strategy", "global",
                 "--count", "300", "-o", str(rel), "-q"]) == 0  # fmt: skip
    b = _without_truth(tmp_path)
    rep = tmp_path / "rep"
    assert main(["run", str(b), "--relations", str(rel), "-o", str(rep), "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    assert "trajectory" not in m
    got = m["reference_relations"]["estimates"]["recovered"]
    ev = tmp_path / "evaluate.json"
    assert main(["evaluate", str(rel), str(rep / "recovered.txt"), "--json", str(ev), "-q"]) == 0
    want = json.loads(ev.read_text())
    for part in ("translation", "rotation"):
        for stat in ("mean", "std", "max", "count"):
            assert got[part]["abs"][stat] == pytest.approx(want[part]["abs"][stat], rel=1e-12)
    assert m["reference_relations"]["relations"] == want["translation"]["abs"]["count"]
    # the accuracy lamp is judged on them: the recovered trajectory beats dead reckoning
    dr = m["reference_relations"]["estimates"]["dead_reckoning"]
    assert got["translation"]["abs"]["mean"] < dr["translation"]["abs"]["mean"]
    rows = _verdict_rows((rep / "report.html").read_text())
    assert rows["recovered vs dead reckoning (on the reference relations)"] == "green"
    assert rows["consistency (recovered)"] == "not judged"
    # the relation-errors figure is drawn on the reference relations given, with no truth line
    html = " ".join((rep / "report.html").read_text().split())
    assert "one panel for the reference relations given (" in html
    assert "global.relations): each pose" in html
    assert (rep / "figure_2.png").exists()
    # with ground truth, --relations adds its scores and changes nothing else
    plain, with_rel = tmp_path / "plain", tmp_path / "with"
    assert main(["run", str(SIM_BUNDLE), "-o", str(plain), "-q"]) == 0
    assert main(["run", str(SIM_BUNDLE), "--relations", str(rel), "-o", str(with_rel), "-q"]) == 0
    a = json.loads((plain / "metrics.json").read_text())
    w = json.loads((with_rel / "metrics.json").read_text())
    assert w.pop("reference_relations")["estimates"]["recovered"] == got
    assert w == a
    for csv in plain.glob("relations_*.csv"):
        assert (with_rel / csv.name).read_bytes() == csv.read_bytes()


def test_reference_map_is_compared_as_map_compare_does(tmp_path: Path) -> None:
    b = _without_truth(tmp_path)
    survey = tmp_path / "survey.csv"
    shutil.copy(SIM_BUNDLE / "landmarks_groundtruth.csv", survey)
    rep = tmp_path / "rep"
    assert main(["run", str(b), "--reference-map", str(survey), "-o", str(rep), "-q"]) == 0
    m = json.loads((rep / "metrics.json").read_text())
    out = tmp_path / "mc.json"
    assert main(["map-compare", str(b / "map.csv"), str(survey), "--json", str(out), "-q"]) == 0
    want = json.loads(out.read_text())
    assert m["map"]["association"]["matched"] == want["association"]["matched"] > 0
    assert m["map"]["ospa"]["value"] == pytest.approx(want["ospa"]["value"], rel=1e-12)
    assert m["map"]["translation"] == want["translation"]
    # no true trajectory, no reach: the report must not call an unseen landmark unobserved
    html = " ".join((rep / "report.html").read_text().split())
    assert "unobserved, not missed" not in html
    assert "no landmark is told unobserved" in html
    assert m["map"]["association"]["unobserved"] == 0


def test_reference_options_refused_where_they_do_not_fit(tmp_path: Path) -> None:
    # the bundle's own true landmarks are the reference map: a second one is refused
    assert main(["run", str(SIM_BUNDLE), "--reference-map",
                 str(SIM_BUNDLE / "landmarks_groundtruth.csv"), "-o", str(tmp_path / "r"),
                 "-q"]) == 2  # fmt: skip
    # a trajectory is no .relations file
    b = _without_truth(tmp_path)
    traj = tmp_path / "traj.txt"
    traj.write_text("0 0 0 0\n1 1 0 0\n2 2 0 0\n")
    assert main(["run", str(b), "--relations", str(traj), "-o", str(tmp_path / "r"), "-q"]) == 3
    assert not (tmp_path / "r").exists()


def test_trajectory_figure_draws_estimates_over_the_reference() -> None:
    """Figure 1: the reference beneath the estimates (an estimate lying on it shows), the
    main estimate on top, the SLAM map not red (red is the map/log disagreement)."""
    from matplotlib.colors import to_rgba

    from relation_metric.trajectory import Trajectory
    from slamrel.plots.run import trajectories_figure

    t = np.arange(5.0)
    poses = np.column_stack((t, np.zeros(5), np.zeros(5)))
    ests = {k: Trajectory(t, poses) for k in ("recovered", "dead_reckoning", "online")}
    xy = np.array([[0.0, 1.0], [2.0, 1.0]])
    fig = trajectories_figure(Trajectory(t, poses), ests, landmarks=xy, mapped=xy)
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    ref = lines["ground truth"]
    est_z = [lines[k].get_zorder() for k in ests]
    assert ref.get_zorder() < min(est_z)
    assert est_z[0] == max(est_z)  # the main estimate on top
    assert to_rgba(lines["SLAM map"].get_color()) != to_rgba("tab:red")
    # without a reference: no grey line, nothing claims to be the truth
    fig = trajectories_figure(None, ests)
    assert "ground truth" not in {ln.get_label() for ln in fig.axes[0].get_lines()}


def test_map_figure_title_fits_and_legend_covers_no_landmark() -> None:
    from landmark_graph.map_compare import compare_maps
    from landmark_graph.maps import LandmarkMap
    from slamrel.plots.maps import map_figure

    rng = np.random.default_rng(4)
    xy = rng.uniform(-5.0, 15.0, size=(200, 2))
    ref = LandmarkMap(np.arange(200), xy)
    est = LandmarkMap(np.arange(200), xy + rng.normal(0.0, 0.05, size=xy.shape))
    fig = map_figure(compare_maps(est, ref))
    fig.canvas.draw()
    ax = fig.axes[0]
    box = fig.bbox
    title = ax.title.get_window_extent()
    assert box.x0 <= title.x0 and title.x1 <= box.x1 and title.y1 <= box.y1
    legend = ax.get_legend().get_window_extent()
    points = ax.transData.transform(xy)
    inside = (
        (points[:, 0] >= legend.x0) & (points[:, 0] <= legend.x1)
        & (points[:, 1] >= legend.y0) & (points[:, 1] <= legend.y1)
    )  # fmt: skip
    assert not inside.any()
