"""One covariance check with one tolerance, one landmark CSV: the same verdict everywhere.

Oracles: eigenvalues computed here with ``numpy.linalg.eigvalsh`` on hand-built matrices
(rotations of chosen spectra); the same map file fed to ``read_bundle`` (``recover``) and
``read_map`` (``map-compare``); byte-exact round trips of the landmark CSV writer.
"""

from __future__ import annotations

import io
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest

from landmark_graph.maps import LandmarkMap
from relation_metric.checks import (
    COV_RTOL,
    bad_covariances,
    check_covariances,
    check_joint_covariance,
)
from relation_metric.errors import InputError
from slamrel.cli import main
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.formats.landmark_csv import read_landmark_csv, write_landmark_csv
from slamrel.formats.landmark_maps import read_map, write_map
from slamrel.formats.text import TruncatedLineWarning
from slamrel.simulation.bundles import simulate_bundle


def _rotated(eigenvalues, angles):
    """2 x 2 matrices R(a) diag(l) R(a)^T with the given spectra, shape (N, 2, 2)."""
    c, s = np.cos(angles), np.sin(angles)
    r = np.stack((np.stack((c, -s), -1), np.stack((s, c), -1)), -2)
    return r @ (np.asarray(eigenvalues)[..., None] * np.swapaxes(r, 1, 2))


def test_verdict_follows_the_smallest_eigenvalue(rng):
    n = 400
    big = 10.0 ** rng.uniform(-8, 4, n)
    # smallest eigenvalue from -3 to +3 tolerances of the block's largest entry
    rel = rng.uniform(-3, 3, n)
    cov = _rotated(np.column_stack((rel * COV_RTOL * big, big)), rng.uniform(0, np.pi, n))
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))  # exactly symmetric
    rows, _ = bad_covariances(cov)
    low = np.linalg.eigvalsh(cov)[:, 0]
    scale = np.abs(cov).reshape(n, -1).max(axis=1)
    clear = np.abs(low / (COV_RTOL * scale) + 1) > 0.01  # away from the boundary
    expected = np.flatnonzero((low < -COV_RTOL * scale) & clear)
    assert set(expected.tolist()) <= set(rows.tolist())
    assert not (set(rows.tolist()) & set(np.flatnonzero((low >= -COV_RTOL * scale) & clear)))


def test_symmetry_uses_the_same_tolerance():
    a = np.array([[[1.0, 0.5 + 0.5e-9], [0.5, 1.0]]])  # within 1e-9 of the scale 1
    b = np.array([[[1.0, 0.5 + 2e-9], [0.5, 1.0]]])
    assert bad_covariances(a)[0].size == 0
    rows, why = bad_covariances(b)
    assert rows.tolist() == [0] and "symmetric" in why[0]


def test_unknown_partial_and_definite():
    nan = np.nan
    cov = np.array([[[nan, nan], [nan, nan]], [[1, nan], [nan, 1]], [[0, 0], [0, 0]]])
    rows, why = bad_covariances(cov, allow_unknown=True)
    assert rows.tolist() == [1] and "partly" in why[0]
    assert bad_covariances(cov)[0].tolist() == [0, 1]
    assert bad_covariances(np.zeros((1, 2, 2)))[0].size == 0  # zero: PSD
    assert bad_covariances(np.zeros((1, 2, 2)), definite=True)[0].tolist() == [0]
    assert bad_covariances(np.eye(3)[None], definite=True)[0].size == 0


def test_message_names_file_line_and_numbers_without_numpy_reprs():
    cov = np.array([[[1.0, 0], [0, 1]], [[0.01, 0.5], [0.5, 0.01]]])
    with pytest.raises(InputError) as err:
        check_covariances(cov, path="m.csv", lines=[2, 7], what=lambda k: f"landmark {k + 10}")
    msg = str(err.value)
    assert msg.startswith("m.csv:7: landmark 11: expected a positive semi-definite matrix")
    assert "smallest eigenvalue -0.49" in msg and "np." not in msg


def test_huge_entries_no_overflow_warning():
    cov = np.array([[[1e308, 1e308], [1e308, 1e308]], [[1e308, 0], [0, -1e308]]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert bad_covariances(cov)[0].tolist() == [1]
        with pytest.raises(InputError):
            check_joint_covariance(cov[1])
        check_joint_covariance(cov[0])


def test_joint_check_agrees_with_the_block_check(rng):
    """A block-diagonal joint matrix passes exactly when all its blocks pass."""
    for trial in range(40):
        n = 30
        rel = rng.uniform(-3, 3, n) if trial % 2 else rng.uniform(0.01, 3, n)
        big = 10.0 ** rng.uniform(-3, -1, n)
        big[0] = 0.1  # the joint matrix's scale is the largest block's
        blocks = _rotated(np.column_stack((rel * COV_RTOL * 0.1, big)), rng.uniform(0, 3, n))
        blocks = 0.5 * (blocks + np.swapaxes(blocks, 1, 2))
        joint = np.zeros((2 * n, 2 * n))
        for k in range(n):
            joint[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = blocks[k]
        low = np.linalg.eigvalsh(joint)[0]
        if abs(low / (COV_RTOL * 0.1) + 1) < 0.01:
            continue  # too close to the boundary to call
        try:
            check_joint_covariance(joint)
            joint_ok = True
        except InputError:
            joint_ok = False
        assert joint_ok == (low >= -COV_RTOL * 0.1)


# ------------------------------------------------ the same map file, recover and map-compare


def _bundle(tmp_path: Path) -> Path:
    b = simulate_bundle(2, steps=40, map_sigma=(0.02, 0.05))
    write_bundle(tmp_path / "b", b)
    return tmp_path / "b"


ODD_MAPS = {
    # name: rows after the header "landmark,x,y,cxx,cxy,cyy" (landmark ids of the bundle)
    "det slightly negative, within tolerance": "{i},1,2,0.1,0.1000000000499,0.1\n",
    "det -2e-11": "{i},1,2,0.01,0.010000001,0.01\n",  # smallest eigenvalue -1e-9
    "clearly not PSD": "{i},1,2,0.01,0.5,0.01\n",
    "negative variance": "{i},1,2,-0.01,0,0.01\n",
    "partly given": "{i},1,2,0.01,,0.01\n",
    "unknown covariance": "{i},1,2,,,\n",
    "non-integer id": "{i}.5,1,2,0.01,0,0.01\n",
    "NaN position": "{i},nan,2,0.01,0,0.01\n",
    "cut-off last line": None,
    "BOM and CRLF": None,
}


@pytest.mark.parametrize("case", sorted(ODD_MAPS))
def test_same_map_file_same_verdict_in_recover_and_map_compare(tmp_path, case):
    root = _bundle(tmp_path)
    p = root / "map.csv"
    text = p.read_text()
    lines = text.splitlines(keepends=True)
    row = ODD_MAPS[case]
    if row is not None:
        i = lines[2].split(",")[0]
        lines[2] = row.format(i=i)
        text = "".join(lines)
    elif case == "cut-off last line":  # a landmark no measurement refers to, cut off
        text = text + "999,1,2,0.01,0,0.01"
    else:
        text = "\ufeff" + text.replace("\n", "\r\n")
    p.write_text(text, newline="")
    verdicts = []
    for read in (read_bundle, lambda d: read_map(d / "map.csv")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                read(root)
                outcome = ("ok",)
            except InputError as err:
                outcome = ("error", err.path, err.line)
        cut = [str(w.message) for w in caught if issubclass(w.category, TruncatedLineWarning)]
        verdicts.append((outcome, cut))
    assert verdicts[0] == verdicts[1], case
    expect_ok = case in (
        "det slightly negative, within tolerance",
        "unknown covariance",
        "cut-off last line",
        "BOM and CRLF",
    )
    assert (verdicts[0][0][0] == "ok") == expect_ok, verdicts


def test_cli_recover_and_map_compare_agree_on_a_bad_covariance(tmp_path, capsys):
    root = _bundle(tmp_path)
    lines = (root / "map.csv").read_text().splitlines(keepends=True)
    lines[1] = lines[1].split(",")[0] + ",1,2,0.01,0.010000001,0.01\n"  # det -2e-11
    (root / "map.csv").write_text("".join(lines))
    assert main(["recover", str(root), "-o", str(tmp_path / "out"), "-q"]) == 3
    err1 = capsys.readouterr().err
    assert main(["map-compare", str(root / "map.csv"), str(root / "map.csv"), "-q"]) == 3
    err2 = capsys.readouterr().err
    where = f"{root / 'map.csv'}:2: landmark"
    assert where in err1 and where in err2
    assert "positive semi-definite" in err1 and "positive semi-definite" in err2


# ---------------------------------------------------------------- map_covariance.npy


@pytest.mark.parametrize("kind", ["pickled", "corrupt", "cut off", "wrong shape", "object"])
def test_bad_map_covariance_npy_is_a_clear_input_error(tmp_path, kind):
    b = simulate_bundle(2, steps=40, map_sigma=(0.02, 0.05), map_covariance=True)
    write_bundle(tmp_path / "b", b)
    p = tmp_path / "b" / "map_covariance.npy"
    m = b.map_ids.size
    if kind == "pickled":
        p.write_bytes(pickle.dumps(np.eye(2 * m)))
    elif kind == "corrupt":
        p.write_bytes(b"\x93NUMPY\x01\x00garbage" + bytes(range(50)))
    elif kind == "cut off":
        p.write_bytes(p.read_bytes()[:-17])
    elif kind == "wrong shape":
        np.save(p, np.eye(2 * m + 2))
    else:
        buf = io.BytesIO()
        np.save(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        p.write_bytes(buf.getvalue())
    with pytest.raises(InputError) as err:
        read_bundle(tmp_path / "b")
    msg = str(err.value)
    assert msg.startswith(str(p) + ": ")
    assert f"float array of shape ({2 * m}, {2 * m})" in msg
    assert "allow_pickle" not in msg and "np." not in msg


# ---------------------------------------------------------------- one landmark writer


def test_landmark_csv_round_trip_is_exact(tmp_path, rng):
    n = 50
    ids = rng.permutation(10_000)[:n]
    xy = rng.normal(size=(n, 2)) * 10.0 ** rng.uniform(-12, 12, (n, 1))
    cov = _rotated(
        np.column_stack((rng.uniform(0, 1, n), rng.uniform(1, 2, n))), rng.uniform(0, 3, n)
    )
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    cov[3] = np.nan  # unknown: empty cells
    write_landmark_csv(tmp_path / "a.csv", ids, xy, cov)
    back = read_landmark_csv(tmp_path / "a.csv")
    np.testing.assert_array_equal(back.ids, ids)
    assert np.array_equal(back.xy.view(np.int64), xy.view(np.int64))  # bit for bit
    assert np.array_equal(back.cov, cov, equal_nan=True)
    row = (tmp_path / "a.csv").read_text().splitlines()[4]
    assert row.endswith(",,,")
    # the three writers of the project write the same bytes
    write_map(tmp_path / "b.csv", LandmarkMap(ids, xy, cov))
    assert (tmp_path / "b.csv").read_bytes() == (tmp_path / "a.csv").read_bytes()


def test_bundle_map_csv_written_by_the_one_writer(tmp_path):
    b = simulate_bundle(1, steps=40, map_sigma=(0.02, 0.05))
    write_bundle(tmp_path / "b", b)
    write_landmark_csv(tmp_path / "m.csv", b.map_ids, b.map_xy, b.map_marginals)
    assert (tmp_path / "b" / "map.csv").read_bytes() == (tmp_path / "m.csv").read_bytes()


def test_solve_landmarks_csv_round_trips_exactly(tmp_path, capsys):
    g = tmp_path / "g.g2o"
    g.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 7 1.3333333 0.7777777\n"
        "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 100\n"
        "EDGE_SE2_XY 0 7 1.3 0.7 100 0 100\nEDGE_SE2_XY 1 7 0.35 0.8 100 0 100\n"
    )
    assert main(["solve", str(g), "-o", str(tmp_path / "out"), "-q"]) == 0
    capsys.readouterr()
    text = (tmp_path / "out" / "landmarks.csv").read_text()
    head, row = text.splitlines()
    assert head == "landmark,x,y"
    x, y = (float(v) for v in row.split(",")[1:])
    assert len(row.split(",")[1]) > 12  # %.17g, not %.9f
    solved = read_map(tmp_path / "out" / "landmarks.csv")
    assert solved.xy[0].tolist() == [x, y]
