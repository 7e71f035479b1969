"""Landmark map readers and writers: formats, exact round trips, strict errors with lines."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data

from landmark_graph.maps import LandmarkMap
from relation_metric.errors import InputError
from slamrel.formats.landmark_maps import MAP_FORMATS, read_map, write_map


def random_map(rng, n=25, *, cov="full"):
    ids = rng.permutation(1000)[:n] + 1
    xy = rng.normal(0, 30, (n, 2)) * 1.000000001  # digits beyond 9 significant places
    c = None
    if cov == "full":
        a = rng.normal(size=(n, 2, 2))
        c = a @ a.transpose(0, 2, 1) * 1e-3
    elif cov == "diag":
        c = np.zeros((n, 2, 2))
        c[:, 0, 0], c[:, 1, 1] = rng.uniform(1e-6, 1e-2, (2, n))
    return LandmarkMap(ids, xy, c)


@pytest.mark.parametrize(
    "fmt,cov", [("csv", "full"), ("csv", None), ("g2o", None), ("mrclam", "diag"), ("mrclam", None)]
)
def test_write_read_round_trip_is_exact(tmp_path, rng, fmt, cov):
    m = random_map(rng, cov=cov)
    f = tmp_path / f"map.{fmt}"
    write_map(f, m, format=fmt)
    back = read_map(f)
    np.testing.assert_array_equal(back.ids, m.ids)
    np.testing.assert_array_equal(back.xy, m.xy)  # bit for bit
    if fmt == "g2o":
        assert back.cov is None
    elif cov is None:
        assert back.cov is None or not back.cov.any()
    elif fmt == "mrclam":  # σ written, σ² read: equal to rounding
        np.testing.assert_allclose(back.cov, m.cov, rtol=1e-15, atol=0)
    else:
        np.testing.assert_array_equal(back.cov, m.cov)


def test_all_formats_named():
    assert MAP_FORMATS == ("csv", "g2o", "mrclam")


def test_mrclam_landmark_groundtruth():
    m = read_map(require_data("mrclam", "MRCLAM_Dataset7", "Landmark_Groundtruth.dat"))
    np.testing.assert_array_equal(m.ids, np.arange(6, 21))
    # first data line: "  6 	 0.58842660 	 -4.28209684 	 0.00003949 	 0.00059654"
    np.testing.assert_array_equal(m.xy[0], [0.58842660, -4.28209684])
    np.testing.assert_allclose(m.cov[0], [[0.00003949**2, 0], [0, 0.00059654**2]], rtol=1e-15)
    np.testing.assert_array_equal(m.xy[-1], [1.24714039, 4.46386435])


def test_csv_with_empty_covariances_and_g2o_with_other_records(tmp_path):
    f = tmp_path / "map.csv"
    f.write_text(
        "# a comment\nlandmark,x,y,cxx,cxy,cyy\n3,1.5,2,0.1,0.01,0.2\n4,0,-1,,,\n7,2,2,1,0,1\n"
    )
    m = read_map(f)
    np.testing.assert_array_equal(m.ids, [3, 4, 7])
    np.testing.assert_array_equal(m.cov[0], [[0.1, 0.01], [0.01, 0.2]])
    assert np.isnan(m.cov[1]).all()  # left empty in the file: unknown, not dropped
    out = tmp_path / "out.csv"
    write_map(out, m)
    assert out.read_text().splitlines()[2] == "4,0,-1,,,"
    g = tmp_path / "m.g2o"
    g.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_XY 5 1.25 -2\nEDGE_SE2_XY 0 5 1 1 1 0 1\n")
    m = read_map(g)
    np.testing.assert_array_equal(m.ids, [5])
    np.testing.assert_array_equal(m.xy, [[1.25, -2.0]])
    plain = tmp_path / "plain.txt"
    plain.write_text("1 0 0\n2 3.5 4\n")
    np.testing.assert_array_equal(read_map(plain).xy, [[0, 0], [3.5, 4]])


@pytest.mark.parametrize(
    "name,text,where,what",
    [
        ("a.csv", "landmark,x,y\n1,0,0\n2,nan,1\n", "a.csv:3", "finite"),
        (
            "a.csv",
            "landmark,x,y\n1,0,0\n2,1,1\n\n1,5,5\n",
            "a.csv:5",
            "duplicate landmark id 1 (first on line 2)",
        ),
        (
            "a.csv",
            "landmark,x,y,cxx,cxy,cyy\n1,0,0,1,0,1\n2,1,1,1,2,1\n",
            "a.csv:3",
            "positive semi-definite",
        ),
        ("a.csv", "landmark,x,y,cxx,cxy,cyy\n1,0,0,1,,1\n", "a.csv:2", "all three or none"),
        (
            "a.csv",
            "landmark,x,y\n1,0,0\n2,1\n3,0,0\n",
            "a.csv:3",
            "expected 3 comma-separated fields",
        ),
        ("a.csv", "landmark,x,y\n", "a.csv", "empty map"),
        ("a.dat", "# only a header\n", "a.dat", "empty map"),
        ("a.dat", "6 0.5 1.0 0.1 0.1\n7 inf 1.0 0.1 0.1\n", "a.dat:2", "finite"),
        ("a.dat", "6 0.5 1.0 0.1 0.1\n6 0.7 1.0 0.1 0.1\n", "a.dat:2", "duplicate landmark id 6"),
        ("a.dat", "6.5 0.5 1.0\n", "a.dat:1", "integer"),
        ("a.g2o", "VERTEX_SE2 0 0 0 0\n", "a.g2o", "empty map"),
        ("a.g2o", "VERTEX_XY 1 0 0\nVERTEX_XY 2 0\n", "a.g2o:2", "expected 4 fields"),
        ("a.txt", "1 2 3 4\n", "a.txt", "cannot recognise"),
    ],
)
def test_bad_maps_name_file_and_line(tmp_path, name, text, where, what):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(InputError) as exc:
        read_map(f)
    msg = str(exc.value)
    assert msg.startswith(str(tmp_path / where) + ":") and what in msg, msg


def test_landmark_map_checks_its_arrays():
    with pytest.raises(InputError, match="shape"):
        LandmarkMap([1, 2], [[0, 0]])
    with pytest.raises(InputError, match="non-finite"):
        LandmarkMap([1], [[0, np.nan]])
    with pytest.raises(InputError, match="duplicate landmark id 2"):
        LandmarkMap([2, 2], [[0, 0], [1, 1]])
    with pytest.raises(InputError, match="semi-definite"):
        LandmarkMap([1], [[0, 0]], [[[1.0, 0.0], [0.0, -1.0]]])
    m = LandmarkMap([1, 2], [[0, 0], [1, 1]])
    with pytest.raises(ValueError):
        m.xy[0, 0] = 5.0  # read-only
    with pytest.raises(InputError, match="diagonal"):
        write_map("unused.dat", LandmarkMap([1], [[0, 0]], [[[1, 0.5], [0.5, 1]]]), format="mrclam")


# ------------------------------------------- one landmark check: the same verdict everywhere


def _message(f) -> str:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError) as err:
        f()
    return err.value.message


LANDMARK_DEFECTS = {
    # name: (ids, xy, cov or None, the words every taker says)
    "duplicate": ([4, 2, 4], [[0, 0], [1, 1], [2, 2]], None, "duplicate landmark id 4"),
    "non-integer": ([1, 2.5], [[0, 0], [1, 1]], None, "expected an integer id, got 2.5"),
    "far": ([1, 2], [[0, 0], [1e31, 1]], None, "position (1e+31, 1) is beyond 1e+30 m"),
    "not psd": ([1, 2], [[0, 0], [1, 1]], [np.eye(2), [[1, 2], [2, 1]]], "landmark 2: covariance"),
}


@pytest.mark.parametrize("name", sorted(LANDMARK_DEFECTS))
def test_every_landmark_taker_gives_the_same_verdict(tmp_path, name):
    """The CSV reader, the 'id x y' reader, LandmarkMap and the Bundle's map all call
    relation_metric.landmarks.check_landmarks: the same words (files add their lines)."""
    from dataclasses import replace

    from slamrel.simulation.bundles import simulate_bundle

    ids, xy, cov, words = LANDMARK_DEFECTS[name]
    c = None if cov is None else np.asarray(cov, dtype=np.float64)
    rows = [f"{i},{x!r},{y!r}" for i, (x, y) in zip(ids, np.asarray(xy, float).tolist())]
    if c is None:
        text = "landmark,x,y\n" + "".join(r + "\n" for r in rows)
    else:
        cells = [",".join(repr(float(v)) for v in (k[0, 0], k[0, 1], k[1, 1])) for k in c]
        text = "landmark,x,y,cxx,cxy,cyy\n" + "".join(f"{r},{q}\n" for r, q in zip(rows, cells))
    (tmp_path / "m.csv").write_text(text)
    said = {
        "LandmarkMap": _message(lambda: LandmarkMap(np.asarray(ids, float), xy, c)),
        "csv": _message(lambda: read_map(tmp_path / "m.csv")),
    }
    if c is None:
        (tmp_path / "m.txt").write_text(text.replace(",", " ").split("\n", 1)[1])
        said["id x y"] = _message(lambda: read_map(tmp_path / "m.txt"))
    if name != "non-integer":  # a Bundle's ids are int64 by type
        b = simulate_bundle(1, steps=10)
        m = len(ids)
        assert not np.isin(ids, b.map_ids[m:]).any()  # the defect is the only one
        fields = {
            "map_ids": np.concatenate((ids, b.map_ids[m:])).astype(np.int64),
            "map_xy": np.concatenate((xy, b.map_xy[m:])),
            "map_marginals": b.map_marginals
            if c is None
            else np.concatenate((c, b.map_marginals[m:])),
            "map_covariance": None,
        }
        said["Bundle"] = _message(lambda: replace(b, **fields))
    for who, message in said.items():
        assert words in message, (who, message)
