"""Comparison tables and paired significance tests."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.errors import InputError
from relation_metric.evaluate import UnassociatedRelationsWarning, evaluate
from relation_metric.relations import generate_relations
from relation_metric.significance import holm_adjust
from relation_metric.trajectory import Trajectory
from slamrel.cli import main
from slamrel.formats.results import read_per_relation_csv, write_per_relation_csv
from slamrel.report.tables import ResultErrors, compare_results, read_per_relation


def result(ds, alg, keys, trans, rot):
    return ResultErrors(
        ds, alg, np.asarray(keys), np.asarray(trans, float), np.asarray(rot, float), "rad"
    )


def test_clearly_different_algorithms_are_significant(rng):
    keys = [f"{k} {k + 1}" for k in range(200)]
    base = rng.gamma(2.0, 0.01, 200)
    good = result("d", "good", keys, base, base / 10)
    bad = result("d", "bad", keys, base * 3, base / 10 + 0.01)
    same = result("d", "same", keys, base + rng.normal(0, 1e-6, 200), base / 10)
    comp = compare_results([good, bad, same])
    tests = {(t.a, t.b, t.part): t for t in comp.tests}
    assert tests[("good", "bad", "translation")].significant
    assert tests[("good", "bad", "translation")].mean_difference < 0
    assert tests[("good", "bad", "translation")].better == "good"
    assert not tests[("good", "same", "translation")].significant
    assert not tests[("good", "same", "rotation")].significant  # identical: p = 1
    assert tests[("good", "same", "rotation")].p_value == 1.0
    assert {t.relation_set for t in comp.tests} == {"all"}  # no set column: one set
    st = comp.stats[("d", "bad")].translation.abs
    assert st.mean == pytest.approx(np.mean(base * 3)) and st.count == 200


def test_pairs_only_common_relations():
    a = result("d", "a", ["1 2", "2 3", "3 4"], [0.1, 0.2, 0.3], [0, 0, 0])
    b = result("d", "b", ["2 3", "3 4", "4 5"], [0.2, 0.1, 0.9], [0, 0, 0])
    with pytest.warns(UserWarning, match="different relation sets.*2 relations common"):
        comp = compare_results([a, b])
    t = [x for x in comp.tests if x.part == "translation"][0]
    assert t.n == 2 and t.mean_difference == pytest.approx(0.1)
    # two relations are no basis for a test: said, not a p-value
    assert not t.difference.tested and np.isnan(t.p_value) and not t.significant
    # means side by side are over the same two relations (hand: a 0.25, b 0.15), counted
    assert comp.stats[("d", "a")].translation.abs.mean == pytest.approx(0.25)
    assert comp.stats[("d", "b")].translation.abs.mean == pytest.approx(0.15)
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


def test_cli_end_to_end(tmp_path, capsys):
    assert main(["example", "-o", str(tmp_path / "ex"), "-q"]) == 0
    ex = tmp_path / "ex"
    per = {}
    for name, est in (("drift", "estimate.txt"), ("truth", "reference.txt")):
        # relations generated from the reference: the CSV names their set
        per[name] = tmp_path / f"{name}.csv"
        argv = ["evaluate", str(ex / "reference.txt"), str(ex / est), "--strategy",
                "consecutive", "--per-relation", str(per[name]), "-q"]  # fmt: skip
        assert main(argv) == 0
        # the example's .relations file mixes consecutive and loop relations, unlabelled
        per[f"{name}-file"] = tmp_path / f"{name}-file.csv"
        argv = ["evaluate", str(ex / "reference.relations"), str(ex / est), "--per-relation",
                str(per[f"{name}-file"]), "-q"]  # fmt: skip
        assert main(argv) == 0
    assert per["drift"].read_text().splitlines()[1].endswith(",consecutive")
    assert per["drift-file"].read_text().splitlines()[0].endswith(",via_odometry")
    out = tmp_path / "cmp"
    argv = ["compare", f"example:drift={per['drift']}", f"example:truth={per['truth']}",
            f"file:drift={per['drift-file']}", f"file:truth={per['truth-file']}",
            "-o", str(out), "-q", "--resamples", "999"]  # fmt: skip
    assert main(argv) == 0
    md = (out / "table.md").read_text()
    assert "| example | drift |" in md
    # the truth scores 0 on every relation: better beyond doubt, p at the floor (not 0)
    row = next(x for x in md.splitlines() if x.startswith("| example | consecutive | transl"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3:5] == ["drift", "truth"] and cells[8].startswith("+0.02")
    assert cells[8].endswith(" m") and cells[9].startswith("[+0.02")
    assert cells[10] == "n/a"  # the truth's mean error is 0: no relative difference
    assert cells[11:13] == ["< 0.001", "< 0.002"]  # B = 999, two tests in the table
    assert cells[13].startswith("truth by 0.02") and cells[14].startswith("block bootstrap")
    # the pooled file: its loop relations overlap everything: no test, and why
    row = next(x for x in md.splitlines() if x.startswith("| file | all | translation"))
    assert "— (no test)" in row and "later ones in time" in row
    test_rows = [x for x in md.splitlines() if x.startswith(("| example | consec", "| file | all"))]
    p_cells = [c.strip() for x in test_rows for c in x.strip("|").split("|")[11:13]]
    assert len(p_cells) == 8 and not set(p_cells) & {"0", "0.0", "0e+00"}  # never p = 0
    tests = (out / "tests.csv").read_text().splitlines()
    assert len(tests) == 5 and tests[0].startswith("dataset,relation_set,part,unit,a,b,n,")
    assert "\\begin{tabular}" in (out / "table.tex").read_text()
    assert (out / "errors.png").stat().st_size > 5000
    rows = (out / "table.csv").read_text().splitlines()
    assert len(rows) == 5
    # the test is explained in --help
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "circular block bootstrap" in text and "never 0" in text and "Holm" in text


def evaluation_of(n: int, seed: int):
    """A small evaluation: n consecutive relations of a straight drive, a noisy estimate."""
    t = np.arange(n + 1, dtype=float)
    truth = Trajectory(t, np.column_stack((t, np.zeros_like(t), np.zeros_like(t))))
    noisy = truth.poses + np.random.default_rng(seed).normal(0, 0.01, truth.poses.shape)
    return evaluate(generate_relations(truth, "consecutive"), Trajectory(t, noisy))


def test_set_column_round_trip(tmp_path):
    ev = evaluation_of(4, 0)
    sets = ["consecutive", "consecutive", "loops", "global"]
    path = tmp_path / "p.csv"
    write_per_relation_csv(path, ev, relation_sets=sets)
    assert path.read_text().splitlines()[0].endswith(",via_odometry,set")
    r = read_per_relation(path, dataset="d", algorithm="a")
    assert r.sets.tolist() == sets
    np.testing.assert_array_equal(r.translation, ev.errors.translation)
    assert r.times[0].tolist() == [0.0, 1.0, 2.0, 3.0]
    # without the column: one set "all"
    write_per_relation_csv(path, ev)
    assert read_per_relation(path, dataset="d", algorithm="a").sets.tolist() == ["all"] * 4


@pytest.mark.parametrize("degrees", [False, True])
def test_per_relation_csv_round_trip_is_exact(tmp_path, degrees):
    # times near 1.7e9 s with 0.1 s steps need all 17 digits; relations #4-#7 end at poses
    # the estimate lacks, so they are written invalid with empty errors
    rng = np.random.default_rng(3)
    t = 1.7e9 + np.arange(12) * 0.1
    poses = np.column_stack((np.cumsum(rng.normal(1, 0.1, 12)), rng.normal(0, 1, (12, 2))))
    keep = np.r_[0:5, 8:12]
    est = Trajectory(t[keep], poses[keep] + rng.normal(0, 0.01, (9, 3)))
    with pytest.warns(UnassociatedRelationsWarning, match="4 of 11 relations could not"):
        ev = evaluate(generate_relations(Trajectory(t, poses), "consecutive"), est,
                      max_time_diff=0.01)  # fmt: skip
    sets = np.array(["consecutive"] * 6 + ["loops"] * 5)
    path = tmp_path / "p.csv"
    write_per_relation_csv(path, ev, degrees=degrees, relation_sets=sets)
    r = read_per_relation_csv(path)
    valid = ev.association.valid
    assert valid.tolist() == [True] * 4 + [False] * 4 + [True] * 3
    np.testing.assert_array_equal(r.valid, valid)
    np.testing.assert_array_equal(r.t1, ev.relations.first)
    np.testing.assert_array_equal(r.t2, ev.relations.second)
    np.testing.assert_array_equal(r.translation, np.where(valid, ev.errors.translation, np.nan))
    rot = np.degrees(ev.errors.rotation) if degrees else ev.errors.rotation
    np.testing.assert_array_equal(r.rotation, np.where(valid, rot, np.nan))
    assert r.rotation_unit == ("deg" if degrees else "rad")
    assert r.relation_set is not None and r.relation_set.tolist() == sets.tolist()
    assert r.lines.tolist() == list(range(2, 13))  # line 1 is the header
    write_per_relation_csv(path, ev, degrees=degrees)
    assert read_per_relation_csv(path).relation_set is None


@pytest.mark.parametrize("name", ["", " loops", "a,b", "two\nlines"])
def test_set_names_the_writer_cannot_write_are_refused(tmp_path, name):
    with pytest.raises(InputError, match="relation set name"):
        write_per_relation_csv(tmp_path / "p.csv", evaluation_of(2, 0), relation_sets=["x", name])
    with pytest.raises(InputError, match="one set per relation"):
        write_per_relation_csv(tmp_path / "p.csv", evaluation_of(2, 0), relation_sets=["x"])


def test_set_column_reader_rules(tmp_path):
    head = "t1,t2,i,j,trans_error,rot_error_rad,valid,via_odometry,set\n"
    p = tmp_path / "p.csv"
    # one relation in two sets is two relations; twice in one set cannot be paired
    p.write_text(head + "0,1,0,1,0.1,0.01,1,0,loops\n0,1,0,1,0.1,0.01,1,0,global\n")
    assert read_per_relation(p, dataset="d", algorithm="a").sets.tolist() == ["loops", "global"]
    p.write_text(head + "0,1,0,1,0.1,0.01,1,0,loops\n0,1,0,1,0.2,0.02,1,0,loops\n")
    with pytest.raises(InputError, match="appears twice in relation set 'loops'") as err:
        read_per_relation(p, dataset="d", algorithm="a")
    assert err.value.line == 3
    p.write_text(head + "0,1,0,1,0.1,0.01,1,0,loops\n1,2,1,2,0.1,0.01,1,0, \n")
    with pytest.raises(InputError, match="column 'set': an empty cell") as err:
        read_per_relation(p, dataset="d", algorithm="a")
    assert err.value.line == 3


def test_one_test_per_relation_set_and_holm_over_the_table(rng):
    n = 300
    keys = np.array([f"{k} {k + 1}" for k in range(n)] * 2)
    sets = np.repeat(["consecutive", "other"], n)
    base = rng.gamma(2.0, 0.01, 2 * n)
    shift = np.where(sets == "consecutive", 0.002, 0.0)  # a real difference in one set only
    noise = rng.normal(0, 0.004, 2 * n)
    a = ResultErrors("d", "a", keys, base + shift + noise, base, "rad", relation_set=sets)
    b = ResultErrors("d", "b", keys, base, base + 0.001, "rad", relation_set=sets)
    c = result("e", "c", keys[:n], base[:n], base[:n])
    d = result("e", "d", keys[:n], base[:n] + noise[:n], base[:n])
    comp = compare_results([a, b, c, d], resamples=999)
    got = [(t.dataset, t.relation_set, t.part) for t in comp.tests]
    assert got == [
        ("d", "consecutive", "translation"), ("d", "consecutive", "rotation"),
        ("d", "other", "translation"), ("d", "other", "rotation"),
        ("e", "all", "translation"), ("e", "all", "rotation"),
    ]  # fmt: skip
    by = {(t.dataset, t.relation_set, t.part): t for t in comp.tests}
    # each set is tested on its own relations: the means are per set
    t = by[("d", "consecutive", "translation")]
    sel = sets == "consecutive"
    assert t.n == n and t.mean_difference == pytest.approx(np.mean(shift[sel] + noise[sel]))
    assert t.significant and t.better == "b" and t.unit == "m"
    assert by[("d", "other", "rotation")].better == "a"  # b is worse by 0.001 rad everywhere
    assert by[("e", "all", "rotation")].p_value == 1.0  # identical
    # Holm over every test of the table, across datasets (hand: holm of the six p-values)
    p = np.array([x.p_value for x in comp.tests])
    np.testing.assert_allclose([x.p_holm for x in comp.tests], holm_adjust(p))
    assert "over the 6 tests of this table" in comp.markdown()


def test_result_records_check_themselves():
    with pytest.raises(InputError, match='keys must be "t1 t2"'):
        result("d", "a", ["first second"], [0.1], [0.0])
    with pytest.raises(InputError, match="relation times must be finite"):
        ResultErrors("d", "a", np.array(["x"]), np.array([0.1]), np.array([0.0]), "rad",
                     t1=np.array([np.nan]), t2=np.array([1.0]))  # fmt: skip
    with pytest.raises(InputError, match="relation_set has shape"):
        ResultErrors("d", "a", np.array(["0 1"]), np.array([0.1]), np.array([0.0]), "rad",
                     relation_set=np.array(["a", "b"]))  # fmt: skip
    twice = result("d", "a", ["0 1", "0 1"], [0.1, 0.2], [0.0, 0.0])
    with pytest.raises(InputError, match="appears twice in relation set 'all'"):
        compare_results([twice])


def test_results_naming_different_sets_are_told_so():
    a = ResultErrors("d", "a", np.array(["0 1"]), np.array([0.1]), np.array([0.0]), "rad",
                     relation_set=np.array(["consecutive"]))  # fmt: skip
    b = result("d", "b", ["0 1"], [0.2], [0.0])
    with pytest.raises(InputError, match="share no relation.*sets differ.*'set' column"):
        compare_results([a, b])


def test_bad_specs(tmp_path, capsys):
    assert main(["compare", "nonsense", "-o", str(tmp_path / "o")]) == 2  # an option mistake
    assert "expected DATASET:ALGORITHM=PER_RELATION.csv" in capsys.readouterr().err
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    assert main(["compare", f"d:a={bad}", "-o", str(tmp_path / "o")]) == 3
    with pytest.raises(InputError, match="given twice"):
        r = result("d", "a", ["1 2"], [0.1], [0.0])
        compare_results([r, r])
