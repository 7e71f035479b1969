"""The association review: what the page shows (alignment, residuals, margins) and its CLI.

The page's behaviour in a browser (clicks, keys, Save, timing) is tested in
tests/test_review_browser.py.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from landmark_graph.landmark_association import Association, associate_by_id
from landmark_graph.maps import LandmarkMap
from slamrel.cli import main
from slamrel.formats.associations import read_association_csv
from slamrel.formats.landmark_maps import write_map
from slamrel.review.page import implied_alignment, review_data, review_html


def _rot(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def page_data(text: str) -> dict:
    """The JSON embedded in a review page."""
    m = re.search(r'<script id="review-data" type="application/json">(.*?)</script>', text, re.S)
    assert m, "no review data in the page"
    return json.loads(m.group(1))


def _maps(rng, n=30, angle=0.7, t=(12.0, -4.0), noise=0.02):
    ref = LandmarkMap(np.arange(n), rng.uniform(0, 50, (n, 2)))
    est_xy = (ref.xy - np.asarray(t)) @ _rot(-angle).T + rng.normal(0, noise, (n, 2))
    return LandmarkMap(np.arange(n), est_xy), ref


def test_alignment_recovers_the_rigid_transform_and_residuals_are_distances(rng):
    est, ref = _maps(rng, noise=0.0)
    data = review_data(est, ref, associate_by_id(est, ref), cutoff=1.0)
    # noiseless: the implied alignment is the true one, every residual is 0
    assert data.alignment.angle == pytest.approx(0.7, abs=1e-9)
    np.testing.assert_allclose(data.alignment.translation, [12.0, -4.0], atol=1e-9)
    np.testing.assert_allclose(data.estimate_xy, ref.xy, atol=1e-9)
    np.testing.assert_allclose(data.residual, 0.0, atol=1e-9)
    np.testing.assert_allclose(data.suspicion, 0.0, atol=1e-9)


def test_margin_and_suspicion_against_brute_force(rng):
    est, ref = _maps(rng, n=25, noise=0.4)
    # swap two estimated landmarks' ids: two wrong pairs with large residuals
    ids = est.ids.copy()
    ids[[3, 7]] = ids[[7, 3]]
    est = LandmarkMap(ids, est.xy)
    assoc = associate_by_id(est, ref)
    data = review_data(est, ref, assoc, cutoff=1.5)
    e, r = data.estimate_xy, ref.xy
    er, rr = assoc.estimate_rows, assoc.reference_rows
    d = np.linalg.norm(e[:, None, :] - r[None, :, :], axis=-1)  # (M, N), brute force
    for k, (i, j) in enumerate(zip(er, rr)):
        res = d[i, j]
        second = min(np.delete(d[i], j).min(), np.delete(d[:, j], i).min())
        assert data.residual[k] == pytest.approx(res, abs=1e-12)
        assert data.margin[k] == pytest.approx(second - res, abs=1e-12)
        assert data.suspicion[k] == pytest.approx(max(res / 1.5, res / second), abs=1e-12)
    # the swapped pairs are the two most suspicious
    top = set(est.ids[er[np.argsort(-data.suspicion)[:2]]].tolist())
    assert top == {int(ids[3]), int(ids[7])}


def test_implied_alignment_for_few_pairs():
    est = LandmarkMap([1, 2], [[0.0, 0.0], [5.0, 5.0]])
    ref = LandmarkMap([1, 3], [[2.0, 1.0], [9.0, 9.0]])
    one = associate_by_id(est, ref)
    al, how = implied_alignment(est, ref, one)
    np.testing.assert_allclose(al.translation, [2.0, 1.0])
    assert al.angle == 0.0 and "one pair" in how
    none = Association(*(np.empty(0, np.int64),) * 2, np.arange(2), np.arange(2))
    al, how = implied_alignment(est, ref, none)
    np.testing.assert_allclose(al.translation, [0.0, 0.0])
    data = review_data(est, ref, none)
    assert data.residual.size == 0 and data.missed.size == 2


def test_single_landmark_maps_have_an_infinite_margin_shown_as_null():
    est = LandmarkMap([4], [[0.0, 0.0]])
    ref = LandmarkMap([4], [[0.5, 0.0]])
    data = review_data(est, ref, associate_by_id(est, ref))
    assert np.isinf(data.margin[0])
    blob = page_data(review_html(data))
    assert blob["pairs"]["margin"] == [None]
    assert blob["pairs"]["residual"] == [0.0]  # translated onto each other


def test_page_is_self_contained_and_names_cannot_break_out_of_the_script(rng):
    est, ref = _maps(rng, n=12)
    data = review_data(est, ref, associate_by_id(est, ref))
    evil = "</script><script>alert(1)</script><!--"
    text = review_html(data, title="<b>t</b>", names=(evil, "ref.csv"))
    assert text.count("</script>") == 2  # the data element and the page's script only
    assert "<b>t</b>" not in text
    blob = page_data(text)
    assert blob["names"]["estimate"] == evil
    assert blob["estimate"]["ids"] == est.ids.tolist()
    assert blob["pairs"]["estimate"] == list(range(12))
    # no network: nothing is fetched from elsewhere
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    assert "http://" not in text and "https://" not in text


def _write_maps(tmp_path, rng, n=30):
    est, ref = _maps(rng, n=n, noise=0.05)
    write_map(tmp_path / "est.csv", est.subset(np.arange(n - 2)))  # 2 reference missed
    write_map(tmp_path / "ref.csv", ref)
    return tmp_path / "est.csv", tmp_path / "ref.csv"


@pytest.mark.parametrize("mode", ["id", "auto", "id-or-auto"])
def test_cli_review_writes_the_page(tmp_path, rng, capsys, mode):
    est, ref = _write_maps(tmp_path, rng)
    out = tmp_path / "review.html"
    assert main(["review", str(est), str(ref), "-o", str(out), "--associate", mode]) == 0
    printed = capsys.readouterr().out
    assert "28 proposed pairs" in printed and "2 missed, 0 spurious" in printed
    blob = page_data(out.read_text())
    assert len(blob["pairs"]["estimate"]) == 28
    assert max(blob["pairs"]["residual"]) < 0.3
    # one frame rule: the fit on the pairs, whatever proposed them (map-compare's frame)
    assert blob["alignment"]["source"] == "least-squares rigid fit of the 28 pairs"


def test_cli_review_from_a_file_and_map_compare_review(tmp_path, rng, capsys):
    est, ref = _write_maps(tmp_path, rng)
    (tmp_path / "a.csv").write_text("# hand-made\nestimate,reference\n0,1\n1,0\n5,5\n")
    out = tmp_path / "r.html"
    assert main(["review", str(est), str(ref), "--associate", str(tmp_path / "a.csv"),
                 "-o", str(out), "-q"]) == 0  # fmt: skip
    blob = page_data(out.read_text())
    assert sorted(zip(blob["pairs"]["estimate"], blob["pairs"]["reference"])) == [
        (0, 1), (1, 0), (5, 5)
    ]  # fmt: skip
    capsys.readouterr()
    page = tmp_path / "mc.html"
    rc = main(["map-compare", str(est), str(ref), "--review", str(page), "--plot",
               str(tmp_path / "f.png")])  # fmt: skip
    assert rc == 0
    assert f"review the association: {page}" in capsys.readouterr().out
    assert len(page_data(page.read_text())["pairs"]["estimate"]) == 28


def test_cli_review_refuses_bad_options_and_outputs(tmp_path, rng, capsys):
    est, ref = _write_maps(tmp_path, rng)
    with pytest.raises(SystemExit) as e:
        main(["review", str(est), str(ref), "--cutoff", "-1"])
    assert e.value.code == 2
    assert "argument --cutoff" in capsys.readouterr().err
    # the output is an input: refused before anything is read
    assert main(["review", str(est), str(ref), "-o", str(ref)]) == 3
    assert "ref.csv" in capsys.readouterr().err
    # a bad association file names its line
    (tmp_path / "bad.csv").write_text("estimate,reference\n0,999\n")
    assert main(["review", str(est), str(ref), "--associate", str(tmp_path / "bad.csv"),
                 "-o", str(tmp_path / "x.html")]) == 3  # fmt: skip
    err = capsys.readouterr().err
    assert "bad.csv:2:" in err and "unknown reference landmark id 999" in err
    assert not (tmp_path / "x.html").exists()
    (tmp_path / "words.csv").write_text("hello world\n")
    assert main(["review", str(tmp_path / "words.csv"), str(ref), "-o", str(tmp_path / "y.html")])
    assert "words.csv" in capsys.readouterr().err


def test_saved_csv_format_is_what_map_compare_reads(tmp_path, rng):
    """The page's CSV layout (comment lines, header, pairs), written here by hand as the page
    writes it, reads back with read_association_csv (the browser test saves a real one)."""
    est, ref = _maps(rng, n=6)
    text = (
        "# slamrel association review: estimate e.csv, reference r.csv\n"
        "# missed reference ids: 5\n# spurious estimate ids: 5\n# unreviewed: 0:0 1:1\n"
        "estimate,reference\n0,0\n1,1\n2,2\n3,4\n4,3\n"
    )
    (tmp_path / "a.csv").write_text(text)
    a = read_association_csv(tmp_path / "a.csv", est, ref)
    assert a.estimate_rows.size == 5 and ref.ids[a.missed].tolist() == [5]


def test_run_report_links_the_review(quickstart_run):
    html = quickstart_run.html
    assert '<a href="review.html">' in html.read_text()
    blob = page_data((html.parent / "review.html").read_text())
    assert blob["pairs"]["estimate"]  # the SLAM map against the true landmarks


@pytest.mark.parametrize("kind", ["missing", "empty", "binary", "words", "nan", "folder"])
def test_hostile_inputs_give_one_clean_error(tmp_path, rng, capsys, kind):
    est, ref = _write_maps(tmp_path, rng)
    bad = {
        "missing": tmp_path / "missing.csv",
        "empty": tmp_path / "empty.csv",
        "binary": tmp_path / "binary.csv",
        "words": tmp_path / "words.csv",
        "nan": tmp_path / "nan.csv",
        "folder": tmp_path,
    }[kind]
    (tmp_path / "empty.csv").write_bytes(b"")
    (tmp_path / "binary.csv").write_bytes(bytes(range(256)))
    (tmp_path / "words.csv").write_text("hello world\n")
    (tmp_path / "nan.csv").write_text("landmark,x,y\n1,nan,0\n")
    out = tmp_path / "out" / "r.html"
    for argv in (
        [str(bad), str(ref)],
        [str(est), str(bad)],
        [str(est), str(ref), "--associate", str(bad)],
    ):
        code = main(["review", *argv, "-o", str(out), "-q"])
        err = capsys.readouterr().err
        assert code == 3 and err.startswith("slamrel review: error: "), (argv, err)
        assert len(err.strip().splitlines()) == 1 and "np.float64" not in err, err
        assert not out.exists()
