"""Comparison tables and paired significance tests."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.errors import InputError
from slamrel.cli import main
from slamrel.report.tables import ResultErrors, compare_results, holm


def result(ds, alg, keys, trans, rot):
    return ResultErrors(
        ds, alg, np.asarray(keys), np.asarray(trans, float), np.asarray(rot, float), "rad"
    )


def test_holm_against_hand_values():
    # m = 3: sorted p (0.01, 0.03, 0.04) -> (0.03, 0.06, 0.06) after monotone max
    np.testing.assert_allclose(holm(np.array([0.04, 0.01, 0.03])), [0.06, 0.03, 0.06])
    np.testing.assert_allclose(holm(np.array([0.5, 0.9])), [1.0, 1.0])


def test_clearly_different_algorithms_are_significant(rng):
    keys = [f"{k} {k + 1}" for k in range(200)]
    base = rng.gamma(2.0, 0.01, 200)
    good = result("d", "good", keys, base, base / 10)
    bad = result("d", "bad", keys, base * 3, base / 10 + 0.01)
    same = result("d", "same", keys, base + rng.normal(0, 1e-6, 200), base / 10)
    comp = compare_results([good, bad, same])
    tests = {(t.a, t.b, t.part): t for t in comp.tests}
    assert tests[("good", "bad", "translation")].significant
    assert tests[("good", "bad", "translation")].median_difference < 0
    assert not tests[("good", "same", "translation")].significant
    assert not tests[("good", "same", "rotation")].significant  # identical: p = 1
    st = comp.stats[("d", "bad")]["translation"]["abs"]
    assert st.mean == pytest.approx(np.mean(base * 3)) and st.count == 200


def test_pairs_only_common_relations():
    a = result("d", "a", ["1 2", "2 3", "3 4"], [0.1, 0.2, 0.3], [0, 0, 0])
    b = result("d", "b", ["2 3", "3 4", "4 5"], [0.2, 0.1, 0.9], [0, 0, 0])
    with pytest.warns(UserWarning, match="different relation sets.*2 relations common"):
        comp = compare_results([a, b])
    t = [x for x in comp.tests if x.part == "translation"][0]
    assert t.n == 2 and t.median_difference == pytest.approx(0.1)
    # means side by side are over the same two relations (hand: a 0.25, b 0.15), counted
    assert comp.stats[("d", "a")]["translation"]["abs"].mean == pytest.approx(0.25)
    assert comp.stats[("d", "b")]["translation"]["abs"].mean == pytest.approx(0.15)
    assert comp.left_out == {("d", "a"): 1, ("d", "b"): 1}
    assert "left out" in comp.markdown()


def test_results_sharing_no_relation_are_refused():
    a = result("d", "a", ["1 2"], [0.1], [0.0])
    b = result("d", "b", ["2 3"], [0.2], [0.0])
    with pytest.raises(InputError, match="share no relation"):
        compare_results([a, b])


@pytest.mark.parametrize(
    ("trans", "keys", "match"),
    [([np.nan, 0.1], ["1 2", "2 3"], "expected finite errors"),
     ([np.inf, 0.1], ["1 2", "2 3"], "expected finite errors"),
     ([], [], "no scored relations")],
)  # fmt: skip
def test_bad_errors_are_refused_with_the_file(trans, keys, match):
    r = ResultErrors(
        "d", "a", np.asarray(keys, dtype=str), np.asarray(trans, float),
        np.zeros(len(trans)), "rad", source="a.csv",
    )  # fmt: skip
    with pytest.raises(InputError, match=match) as err:
        compare_results([r])
    assert str(err.value).startswith("a.csv: ")


@pytest.mark.parametrize("alpha", [0.0, 1.0, 2.0, -0.1, float("nan")])
def test_alpha_must_be_a_probability(alpha):
    r = result("d", "a", ["1 2", "2 3"], [0.1, 0.2], [0, 0])
    with pytest.raises(InputError, match="alpha"):
        compare_results([r], alpha=alpha)


def test_cli_end_to_end(tmp_path):
    assert main(["example", "-o", str(tmp_path / "ex"), "-q"]) == 0
    ex = tmp_path / "ex"
    per = {}
    for name, est in (("drift", "estimate.txt"), ("truth", "reference.txt")):
        per[name] = tmp_path / f"{name}.csv"
        assert (
            main(
                [
                    "evaluate",
                    str(ex / "reference.relations"),
                    str(ex / est),
                    "--per-relation",
                    str(per[name]),
                    "-q",
                ]
            )
            == 0
        )
    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                f"example:drift={per['drift']}",
                f"example:truth={per['truth']}",
                "-o",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    md = (out / "table.md").read_text()
    assert "| example | drift |" in md and "| example | drift | truth | translation |" in md
    assert "\\begin{tabular}" in (out / "table.tex").read_text()
    assert (out / "errors.png").stat().st_size > 5000
    rows = (out / "table.csv").read_text().splitlines()
    assert len(rows) == 3


def test_bad_specs(tmp_path, capsys):
    assert main(["compare", "nonsense", "-o", str(tmp_path / "o")]) == 3
    assert "expected DATASET:ALGORITHM=PER_RELATION.csv" in capsys.readouterr().err
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    assert main(["compare", f"d:a={bad}", "-o", str(tmp_path / "o")]) == 3
    with pytest.raises(InputError, match="given twice"):
        r = result("d", "a", ["1 2"], [0.1], [0.0])
        compare_results([r, r])
