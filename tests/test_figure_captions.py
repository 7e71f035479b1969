"""The report's figures show what their captions say (issue 38): caption words come from the
legend's own artists, and the share of a line hidden under another is measured as drawn."""

from __future__ import annotations

import re

import numpy as np
import pytest

from relation_metric.trajectory import Trajectory
from slamrel.plots.legend_words import artist_words, colour_word, hidden_share, legend_words
from slamrel.plots.relation_errors import pyplot


def test_colour_words_name_the_colours_drawn():
    assert colour_word("tab:red") == "red"
    assert colour_word("tab:purple") == "purple"
    assert colour_word("#1f77b4") == "blue"
    assert colour_word("k") == "black"
    assert colour_word("0.6") == "grey"
    assert colour_word("0.85") == "light grey"


def test_artist_words_read_marker_fill_and_style():
    plt = pyplot()
    fig, ax = plt.subplots()
    hollow = ax.plot([0], [0], "o", mfc="none", color="tab:purple")[0]
    dots = ax.plot([0], [0], ".", color="tab:red")[0]
    dashed = ax.plot([0, 1], [0, 1], "--", color="tab:blue")[0]
    crosses = ax.plot([0], [0], "k+")[0]
    assert artist_words(hollow) == "hollow purple circles"
    assert artist_words(dots) == "red dots"
    assert artist_words(dashed) == "dashed blue line"
    assert artist_words(crosses) == "black crosses"
    plt.close(fig)


def _segments_hand_count():
    """A horizontal line y = 0 from x = 0 to 10 and the points (i, y_i) of another line: the
    points within half a line width of y = 0 are the hidden ones, counted by hand."""
    ys = np.array([0.0, 0.1, 0.2, 0.5, 1.0, 2.0, 0.05, 3.0, 0.0, 0.3, 5.0])
    return np.arange(11.0), ys


def test_hidden_share_equals_a_hand_count():
    plt = pyplot()
    # 1 data unit = 100 px on both axes (an 11 × 11 in figure at dpi 100, axes filling it)
    fig = plt.figure(figsize=(11, 11), dpi=100)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(-0.5, 10.5)
    ax.set_ylim(-5.5, 5.5)
    x, ys = _segments_hand_count()
    under = ax.plot(x, ys, "-", lw=1)[0]
    # 36 pt wide = 50 px at dpi 100: half a width is 25 px = 0.25 data units
    over = ax.plot([0.0, 10.0], [0.0, 0.0], "-", lw=36)[0]
    fig.canvas.draw()
    # by hand: |y| <= 0.25 for y = 0, 0.1, 0.2, 0.05, 0 → 5 of 11 points
    assert hidden_share(under, over) == pytest.approx(5 / 11)
    # and the other way round: the y = 0 line's two points lie under the thin line only
    # where it passes through them (x = 0: y = 0; x = 10: y = 5, not) → 1 of 2
    assert hidden_share(over, under) == pytest.approx(1 / 2)
    plt.close(fig)


def test_trajectory_caption_words_match_the_legend():
    """Every 'label (words)' the caption of figure 1 states is what the legend's handle of
    that label looks like; a red dot is never called a circle or the map."""
    from slamrel.plots.run import trajectories_figure

    t = np.arange(30.0)
    truth = Trajectory(t, np.column_stack((t, np.sin(t / 5), np.zeros(30))))
    ests = {
        "recovered": Trajectory(t, truth.poses + [0.0, 0.02, 0.0]),
        "online": Trajectory(t, truth.poses + [0.0, 0.5, 0.0]),
    }
    xy = np.array([[0.0, 2.0], [10.0, -2.0]])
    fig = trajectories_figure(truth, ests, landmarks=xy, mapped=xy + 0.1)
    words = legend_words(fig.axes[0])
    assert words["ground truth"] == "grey line"
    assert words["recovered"] == "blue line"
    assert words["online"] == "orange line"
    assert words["true landmarks"] == "black crosses"
    assert words["SLAM map"] == "hollow purple circles"
    pyplot().close(fig)


@pytest.mark.slow
def test_report_caption_matches_its_figure():
    """On a real run: the caption's words for each drawn thing are its legend handle's, and
    the stated hidden shares are those measured on the figure."""
    from slamrel.pipeline import run_pipeline, simulate_run_input
    from slamrel.plots.run import mark_stretches_xy, trajectories_figure
    from slamrel.report.run_page import report_figures

    result = run_pipeline(simulate_run_input("simple1", noise="a", seed=0))
    caption = report_figures(result).trajectories.caption
    assert "Red dots" not in caption or "map/log" in caption
    frames = result.display_frames
    drawn = {
        k: Trajectory(e.timestamps, frames[k].apply(e.poses)) for k, e in result.estimates.items()
    }
    lgt = result.bundle.landmarks_groundtruth
    fig = mark_stretches_xy(
        trajectories_figure(
            result.bundle.groundtruth, drawn,
            labels={k: f"{k} ({frames[k].short})" for k in drawn if frames[k].short},
            landmarks=lgt[1] if lgt else None,
            mapped=frames["map"].apply(result.bundle.map_xy),
        ),
        result.agreement.stretches if result.agreement else (), drawn.get("recovered"),
    )  # fmt: skip
    fig.canvas.draw()
    words = legend_words(fig.axes[0])
    for name in result.estimates:
        label = f"{name} ({frames[name].short})" if frames[name].short else name
        assert f"{name} {words[label]}" in caption
    assert f"ground truth ({words['ground truth']}" in caption
    assert f"SLAM map ({words['SLAM map']})" in caption
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    stated = dict(re.findall(r"ground truth under (\w+) (\d+) %", caption))
    for name, pct in stated.items():
        label = f"{name} ({frames[name].short})" if frames[name].short else name
        assert int(pct) == round(100 * hidden_share(lines["ground truth"], lines[label]))
    assert stated  # the caption does say it
    pyplot().close(fig)


def test_one_panel_timeline_legend_clears_its_title():
    """Without ground truth, --relations gives one panel: the timelines' legend (right) must
    not overlap their title (left), as it did at one panel's width."""
    from slamrel.plots.run import SetPanel, relation_sets_figure

    rng = np.random.default_rng(1)
    n = 50
    xy = np.column_stack((np.arange(n, dtype=float), np.zeros(n)))
    panel = SetPanel(
        "reference", np.arange(n, dtype=float), rng.uniform(0.01, 0.1, n),
        rng.uniform(0.001, 0.01, n), xy, rng.uniform(0.0, 0.1, n), high=0.1,
    )  # fmt: skip
    fig = relation_sets_figure([panel], xy)
    fig.canvas.draw()
    ax = fig.axes[0]
    title, legend = ax.title.get_window_extent(), ax.get_legend().get_window_extent()
    assert title.x1 <= legend.x0 or legend.y0 >= title.y1
    pyplot().close(fig)
