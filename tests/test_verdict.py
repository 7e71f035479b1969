"""The report's verdict block: each rule against hand-made typed facts, and how it is rendered."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from recovery.recover import RecoveryCounts
from relation_metric.consistency import NeesSummary
from relation_metric.stats import summarize
from slamrel.pipeline import MapSummary
from slamrel.report.html import Section, _number, render_html
from slamrel.report.verdict import RunFacts, nees_excursions, run_verdict


def _counts(gated: float = 0.0, downweighted: float = 0.0) -> RecoveryCounts:
    return RecoveryCounts(
        measurements=100, used=100, gated=0, unassociated=0, outside=0, skipped_unknown=0,
        gated_fraction=gated, downweighted=0, downweighted_fraction=downweighted,
        downweight_loss=0.0,
    )  # fmt: skip


def _map(edge: float, ospa: float) -> MapSummary:
    return MapSummary(
        edge=summarize([edge]), corner=summarize([0.01]), matched=10, missed=1, spurious=0,
        ospa=ospa, gospa=ospa, cutoff=1.0, order=1.0,
    )  # fmt: skip


def _metrics(
    *, ours=0.1, dr=1.0, online=0.12, inside=0.95, edge=0.05, ospa=0.1, gated=0.0, curve=None
):
    return RunFacts(
        main="recovered",
        translation_errors={"recovered": ours, "dead_reckoning": dr, "online": online},
        relations=100,
        nees=NeesSummary(mean=3.1, band=(0.2, 9.3), inside=inside, runs=1, dof=3),
        nees_values=np.ones(50) if curve is None else curve,
        map=_map(edge, ospa),
        counts=_counts(gated),
        poses=50,
    )


def _levels(v) -> dict[str, str]:
    return {j.what: j.level for j in v.lines}


def test_all_green_and_the_evidence():
    v = run_verdict(_metrics())
    assert set(_levels(v).values()) == {"green"} and v.level == "green"
    assert len(v.lines) == 8
    assert (
        v.evidence
        == "Based on 100 relations, 50 poses, 10 matched landmarks (1 missed, 0 spurious)."
    )


@pytest.mark.parametrize(
    ("change", "what", "level"),
    [
        ({"ours": 0.5}, "recovered vs dead reckoning", "green"),  # ratio 0.5: boundary
        ({"ours": 0.51}, "recovered vs dead reckoning", "amber"),
        ({"ours": 1.2, "online": 1.2}, "recovered vs dead reckoning", "red"),
        ({"online": 0.2}, "online vs recovered", "green"),  # factor 2
        ({"online": 0.3}, "online vs recovered", "amber"),
        ({"online": 0.02}, "online vs recovered", "red"),  # factor 5 the other way
        ({"inside": 0.8}, "consistency (recovered)", "amber"),
        ({"inside": 0.5}, "consistency (recovered)", "red"),
        ({"edge": 0.2}, "map edge error", "amber"),
        ({"edge": 0.31}, "map edge error", "red"),
        ({"ospa": 0.4}, "map OSPA", "amber"),
        ({"ospa": 0.6}, "map OSPA", "red"),
        ({"gated": 0.03}, "gated measurements", "amber"),
        ({"gated": 0.2}, "gated measurements", "red"),
    ],
)
def test_each_rule_and_the_worst_line_wins(change, what, level):
    v = run_verdict(_metrics(**change))
    assert _levels(v)[what] == level
    order = ("green", "amber", "red")
    assert v.level == max(_levels(v).values(), key=order.index)


def test_nees_excursions_are_runs_above_the_band():
    nees = np.array([1, 20, 20, 20, 1, 20, 20, 1, 20, 20, 20, 20, 1.0])
    assert nees_excursions(nees, 9.3) == [3, 4]  # the run of 2 is too short
    assert nees_excursions(nees, 9.3, min_length=2) == [3, 2, 4]  # not merged across gaps
    assert nees_excursions(np.full(5, 20.0), 9.3) == [5]
    assert nees_excursions(np.array([20, 20, np.nan, 20.0]), 9.3, min_length=2) == [2]
    assert nees_excursions(np.empty(0), 9.3) == []
    curve = np.ones(100)
    curve[10:15] = 50  # 5 % of the steps
    assert _levels(run_verdict(_metrics(curve=curve)))["NEES excursions"] == "amber"
    curve[40:60] = 50  # 25 %
    v = run_verdict(_metrics(curve=curve))
    assert _levels(v)["NEES excursions"] == "red"
    assert "longest 20 steps" in next(j.value for j in v.lines if j.what == "NEES excursions")


def test_missing_parts_are_left_out():
    m = replace(_metrics(), translation_errors={"recovered": 0.1}, map=None, nees_values=None)
    v = run_verdict(m)
    assert list(_levels(v)) == [
        "consistency (recovered)",
        "downweighted measurements",
        "gated measurements",
    ]
    assert v.evidence == "Based on 100 relations, 50 poses."
    assert run_verdict(replace(m, nees=None, counts=None, poses=None)).lines == []


def test_dead_reckoning_alone_is_not_compared_with_itself():
    m = replace(
        _metrics(), main="dead_reckoning", translation_errors={"dead_reckoning": 1.0},
        nees=None, counts=None, poses=None,
    )  # fmt: skip
    assert [j.what for j in run_verdict(m).lines] == ["map edge error", "map OSPA"]


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (0.0565346, "0.0565"),
        (0.00182431, "0.00182"),
        (2089.4, "2089"),
        (12345.6, "12346"),
        (1.0, "1"),
        (0.0, "0"),
        (-0.123456, "-0.123"),
        (float("nan"), "–"),
        (float("inf"), "∞"),
    ],
)
def test_numbers_in_tables_have_three_significant_digits(value, text):
    assert _number(value) == text


def test_verdict_comes_first_then_the_contents():
    v = run_verdict(_metrics(gated=0.2))
    text = render_html("r", [Section("One <a>"), Section("Two")], verdict=v)
    assert text.index('id="verdict"') < text.index("Contents") < text.index('id="s0"')
    assert '<a href="#s0">One &lt;a&gt;</a>' in text and '<a href="#s1">Two</a>' in text
    assert 'class="verdict red"' in text
    assert "green ≤ 1 %, amber ≤ 5 %, red above" in text  # the rule is written next to it
