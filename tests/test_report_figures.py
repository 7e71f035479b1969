"""The report's figures show what their captions claim (issue 24): NEES at its own times,
one time base (seconds since the run's start), readable intervals, per-set error panels,
trajectories aligned on the reference, relation sets described and counted."""

from __future__ import annotations

import re

import numpy as np
import pytest

from relation_metric.evaluate import evaluate, pose_errors
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory
from slamrel.report.html import format_intervals


def test_intervals_print_since_start_and_never_alike() -> None:
    assert format_intervals([(312.41, 318.94)]) == ["312.4–318.9 s"]
    # two stretches that one decimal cannot tell apart get more decimals, all of them
    two = format_intervals([(10.01, 10.52), (10.04, 10.53)])
    assert len(set(two)) == 2 and two == ["10.01–10.52 s", "10.04–10.53 s"]
    # a short interval keeps its two ends apart
    assert format_intervals([(5.0, 5.03)]) == ["5.00–5.03 s"]
    assert not any("e+" in t for t in format_intervals([(0.0, 891.6), (1e3, 2e3)]))


def test_pose_errors_average_the_relations_ending_at_each_pose() -> None:
    t = np.arange(5.0)
    truth = Trajectory(t, np.column_stack((t, np.zeros(5), np.zeros(5))))
    est = Trajectory(t, truth.poses + np.array([[0, 0, 0], [0, 0, 0], [0, 0.3, 0],
                                                [0, 0, 0], [0, 0, 0]]))  # fmt: skip
    rel = RelationSet.from_trajectory_pairs(truth, [0, 1, 2, 0], [1, 2, 3, 4])
    ev = evaluate(rel, est)
    pe = pose_errors(ev, len(est))
    e = ev.errors.translation
    assert pe.index.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_allclose(
        pe.mean, [(e[0] + e[3]) / 2, (e[0] + e[1]) / 2, (e[1] + e[2]) / 2, e[2], e[3]]
    )
    assert pe.relations.tolist() == [2, 2, 2, 1, 1]
    assert pe.quantile(1.0) == pytest.approx(pe.mean.max())
    with pytest.raises(Exception, match="part"):
        pose_errors(ev, 5, part="z")


def test_relation_sets_say_their_rule_and_why_one_is_absent() -> None:
    """A 60 s straight run at 10 Hz (600 poses): one pose a second gives 59 consecutive
    relations, and the run never comes back: no loop set, said so."""
    from slamrel import pipeline

    t = np.arange(600) * 0.1
    ref = Trajectory(t, np.column_stack((0.2 * t, np.zeros(600), np.zeros(600))))
    with pytest.warns(UserWarning, match="only 1035 distinct pose pairs"):
        made = pipeline.default_relations(ref, seed=0)
    rules = {r.name: r for r in made.rules}
    assert list(rules) == ["consecutive", "loops", "global"]
    assert set(made.sets) == {"consecutive", "global"}
    assert rules["consecutive"].generated == len(made.sets["consecutive"]) == 59
    assert "one pose every 1 s (60 poses)" in rules["consecutive"].rule
    assert rules["loops"].generated == 0 and "within 1 m" in rules["loops"].absent
    assert rules["loops"].parameters == {"radius_m": pipeline.LOOP_RADIUS,
                                         "min_separation_s": pipeline.LOOP_MIN_SEPARATION,
                                         "max_relations": pipeline.MAX_LOOPS}  # fmt: skip
    extent = 0.2 * 59.0
    assert rules["global"].parameters["min_distance_m"] == pytest.approx(extent / 4)
    # 60 poses, of which only 1035 pairs lie a quarter of the extent apart: said in the rule
    assert rules["global"].generated == len(made.sets["global"]) == 1035
    assert "only 1035 distinct pairs lie that far apart" in rules["global"].rule


def test_nees_is_never_drawn_against_times_it_does_not_have() -> None:
    from relation_metric.consistency import summarize_nees
    from slamrel.plots.run import nees_figure

    v = np.full(10, 3.0)
    s = {"recovered": summarize_nees(v, dof=3)}
    with pytest.raises(ValueError, match="10 values but 20 times"):
        nees_figure(np.arange(20.0), {"recovered": v}, s)
    fig = nees_figure({"recovered": np.arange(10.0) * 5}, {"recovered": v}, s, span=(0, 100))
    assert fig.axes[0].get_xlim() == (0.0, 100.0)
    assert fig.axes[0].get_xlabel() == "time since the run's start [s]"


@pytest.fixture(scope="module")
def simulated(broken_run):
    """simple1, noise a, seed 0, 10 % corrupted associations: the result and its page."""
    return broken_run.result, broken_run.html.read_text()


def test_nees_figure_spans_the_run_at_the_recovered_times(simulated) -> None:
    from slamrel.report.run_page import report_figures

    result, _ = simulated
    curve = result.nees["recovered"]
    assert curve.times is not None and curve.times.shape == curve.values.shape
    np.testing.assert_array_equal(curve.times, result.estimates["recovered"].timestamps[1:])
    data = report_figures(result).nees.data
    tb = result.time_base
    assert data["run-duration"] == tb.duration
    assert data["x-min"] <= 0.0 and data["x-max"] >= tb.duration
    assert data["data-min"] == pytest.approx(curve.times[0] - tb.t0)
    assert data["data-max"] == pytest.approx(curve.times[-1] - tb.t0)


def test_page_counts_and_describes_the_relation_sets(simulated) -> None:
    result, page = simulated
    ev = result.recovered.all
    scored, unassociated = int(ev.valid.sum()), int((~ev.valid).sum())
    assert f"Based on {scored} scored relations" in page
    assert "relation sets (from the ground truth; scored for the recovered estimate)" in page
    for r in result.relation_sets:
        assert r.rule.replace("'", "&#x27;") in page
    assert (f"({unassociated} more generated but unassociated" in page) == (unassociated > 0)
    m = result.metrics()
    assert [r["name"] for r in m["relation_sets"]] == ["consecutive", "loops", "global"]
    assert m["time_base"]["duration"] == result.time_base.duration


def test_intervals_on_the_page_are_since_start(simulated) -> None:
    result, page = simulated
    st = result.agreement.stretches
    assert st  # the corrupted map disagrees with the log
    shown = re.findall(r"<td[^>]*>(\d+\.\d+)–(\d+\.\d+) s</td>", page)
    assert len(shown) == min(len(st), 50)
    t0 = result.time_base.t0
    assert float(shown[0][0]) == pytest.approx(st[0].t0 - t0, abs=0.051)


def test_trajectories_are_drawn_on_the_reference(simulated) -> None:
    """A corrupted map: each estimate is drawn by its SE(2) fit on the reference, as close to
    it as a rigid motion brings it."""
    result, page = simulated
    frames = result.display_frames
    truth = result.bundle.groundtruth

    def rms(xy, ref):
        return float(np.sqrt(np.mean(np.sum((xy - ref) ** 2, axis=1))))

    assert "in the ground truth&#x27;s frame" in page
    # the corrupted map's ids pair mostly landmarks farther apart than c: the default
    # (id-or-auto) associates automatically, whose fit is within c and places the map
    m = result.nees_frame.map_anchoring
    assert m.association == "auto" and m.rms_residual <= result.map_comparison.cutoff
    assert frames["recovered"].short == "landmark fit"
    # dead reckoning never saw the map: its own SE(2) fit, as close as a rigid motion gets
    est = result.estimates["dead_reckoning"]
    drawn = frames["dead_reckoning"].apply(est.poses)[:, :2]
    ref = truth.poses_at(est.timestamps)[:, :2]
    assert rms(drawn, ref) <= rms(est.poses[:, :2], ref) + 1e-9


@pytest.mark.slow
def test_a_landmark_fit_beyond_c_does_not_place_the_map() -> None:
    """The same corrupted map paired by id (forced): its fit leaves metres of residual, so
    every estimate is drawn by its own SE(2) fit on the reference, and the caption says why."""
    from landmark_graph.map_compare import AssociationWarning
    from slamrel.pipeline import run_pipeline
    from slamrel.report.run_page import report_figures

    with pytest.warns(AssociationWarning, match="coincide by accident"):
        result = run_pipeline("simple1", noise="a", seed=0, corrupt_fraction=0.1, associate="id")
    m = result.nees_frame.map_anchoring
    assert m.rms_residual > result.map_comparison.cutoff
    frames = result.display_frames
    truth = result.bundle.groundtruth
    for name, est in result.estimates.items():
        assert frames[name].short == "SE(2) fit on the truth", name
        drawn = frames[name].apply(est.poses)[:, :2]
        ref = truth.poses_at(est.timestamps)[:, :2]
        before = np.sqrt(np.mean(np.sum((est.poses[:, :2] - ref) ** 2, axis=1)))
        assert np.sqrt(np.mean(np.sum((drawn - ref) ** 2, axis=1))) <= before + 1e-9, name
    assert "it does not place the map" in report_figures(result).trajectories.caption


def test_a_good_landmark_fit_places_the_map_frame_estimates(quickstart_run) -> None:
    result = quickstart_run.result
    frames = result.display_frames
    assert frames["recovered"].short == frames["map"].short == "landmark fit"
    assert frames["dead_reckoning"].short == "SE(2) fit on the truth"
    m = result.nees_frame.map_anchoring
    assert frames["map"].alignment.angle == m.dtheta
    est = result.estimates["recovered"]
    drawn = frames["recovered"].apply(est.poses)[:, :2]
    ref = result.bundle.groundtruth.poses_at(est.timestamps)[:, :2]
    assert np.sqrt(np.mean(np.sum((drawn - ref) ** 2, axis=1))) < 0.5
