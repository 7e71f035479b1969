"""Every reader, one set of rules: BOM and CRLF accepted, a cut-off last line skipped with a
warning, and for any mutated input a result or one project error naming the file.

Each reader starts from a valid small file (written here). The fuzz tests mutate it (bytes
flipped, inserted, deleted; lines dropped, duplicated, swapped; cut at a random offset; a
BOM, CRLF line ends, NaN/inf/huge numbers, words and extra fields inserted) and require a
result or an :class:`InputError` whose message names the file — never another exception
(numpy's RuntimeWarnings are errors in this suite), never a numpy repr or a traceback.
"""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from landmark_graph.maps import LandmarkMap
from relation_metric.errors import InputError
from slamrel.formats.associations import read_association_csv
from slamrel.formats.bundle import read_bundle
from slamrel.formats.g2o import read_g2o_graph
from slamrel.formats.isam import read_isam
from slamrel.formats.landmark_maps import read_map
from slamrel.formats.relations import read_relations
from slamrel.formats.text import TruncatedLineWarning, read_keyword_records
from slamrel.formats.trajectories import read_trajectory
from slamrel.importers.mrclam import read_mrclam_robot
from slamrel.report.tables import read_per_relation

# ----------------------------------------------------------------------- valid small files

PLAIN = "# t x y theta\n0 0 0 0\n1 1 0 0.1\n2 2 0.5 0.2\n3 2.5 1 0.3\n"
TUM = (
    "# t x y z qx qy qz qw\n"
    "0 0 0 0 0 0 0 1\n"
    "1 1 0 0 0 0 0.0499792 0.9987503\n"
    "2 2 0.5 0 0 0 0.0998334 0.9950042\n"
    "3 2.5 1 0 0 0 0.1494381 0.9887711\n"
)
CARMEN = (
    "PARAM robot_width 0.5\n"
    "FLASER 2 1.5 1.6 0 0 0 0 0 0 10.0 h 10.0\n"
    "ODOM 0.5 0 0.05 0.1 0 0 10.5 h 10.5\n"
    "FLASER 2 1.5 1.6 1 0 0.1 1 0 0.1 11.0 h 11.0\n"
    "FLASER 2 1.4 1.5 2 0.5 0.2 2 0.5 0.2 12.0 h 12.0\n"
)
G2O_TRAJ = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0.1\nVERTEX_SE2 2 2 0.5 0.2\nFIX 0\n"
CSV_TRAJ = "t,x,y,theta\n0,0,0,0\n1,1,0,0.1\n2,2,0.5,0.2\n3,2.5,1,0.3\n"
RELATIONS = (
    "# t1 t2 x y z roll pitch yaw\n"
    "0.000000 1.000000 1.0 0.0 0 0 0 0.1\n"
    "1.000000 2.000000 1.1 0.4 0 0 0 0.1\n"
    "0.000000 3.000000 2.7 0.6 0 0 0 0.3\n"
)
MAP_CSV = "landmark,x,y,cxx,cxy,cyy\n1,0,0,0.01,0.001,0.02\n2,1,1,,,\n3,1,0,0.5,0,0.5\n"
MAP_G2O = "VERTEX_SE2 0 0 0 0\nVERTEX_XY 1 0 0\nVERTEX_XY 2 1 1\nVERTEX_XY 3 1 0\n"
MAP_MRCLAM = "# Subject x y sx sy\n6\t0.5\t1.0\t0.1\t0.1\n7 2.0 -1.0 0.2 0.1\n8 3 3 0 0\n"
ASSOCIATION = "# a comment\nestimate,reference\n1,3\n2,2\n3,1\n"
PER_RELATION = (
    "t1,t2,i,j,trans_error,rot_error_rad,valid,via_odometry\n"
    "0.000000,1.000000,0,1,0.1,0.01,1,0\n"
    "1.000000,2.000000,1,2,0.2,0.02,1,0\n"
    "2.000000,3.000000,-1,-1,,,0,0\n"
    "0.000000,3.000000,0,3,0.3,0.03,1,0\n"
)
ISAM = (
    "ODOMETRY 0 1 1 0 0.1 0.0001 0 0 0.0001 0 4e-06\n"
    "LANDMARK 1 5 2 0.5 0.0001 0 0.0001\n"
    "ODOMETRY 1 2 1 0 0.1 0.0001 0 0 0.0001 0 4e-06\n"
    "LANDMARK 2 5 1 0.4 0.0001 0 0.0001\n"
    "ODOMETRY 2 3 1 0.1 0.1 0.0001 0 0 0.0001 0 4e-06\n"
)
G2O_GRAPH = (
    "VERTEX_SE2 0 0 0 0\n"
    "VERTEX_SE2 1 1 0 0.1\n"
    "VERTEX_SE2 2 2 0.1 0.2\n"
    "VERTEX_XY 10 2 1\n"
    "EDGE_SE2 0 1 1 0 0.1 100 0 0 100 0 400\n"
    "EDGE_SE2 1 2 1 0 0.1 100 0 0 100 0 400\n"
    "EDGE_SE2_XY 1 10 1 1 100 0 100\n"
    "EDGE_SE2_XY 2 10 0.1 0.9 100 0 100\n"
)
KEYWORDS = "A 1 2\n# note\nB 3\nA 4 5\n"
MRCLAM_HEAD = "# Time [s]    fields\n"
MRCLAM = {
    "Barcodes.dat": MRCLAM_HEAD + "  1 \t 5\n  2 \t 14\n  6 \t 63\n  7 \t 81\n",
    "Robot1_Odometry.dat": MRCLAM_HEAD + "10.0 \t 0.1 \t 0.0\n10.5 \t 0.1 \t 0.2\n11.0 0 0\n",
    "Robot1_Measurement.dat": MRCLAM_HEAD
    + "10.1 \t 63 \t 1.5 \t 0.1\n10.1 \t 14 \t 2.0 \t -0.3\n10.7 \t 81 \t 3.0 \t 0.5\n",
    "Robot1_Groundtruth.dat": MRCLAM_HEAD + "10.0 1 2 0.1\n10.5 1.05 2 0.1\n11.0 1.1 2 0.12\n",
}
BUNDLE_JSON = json.dumps(
    {
        "format": "slamrel-bundle/1",
        "motion_model": {"type": "velocity", "sigma_v": 0.1, "sigma_omega": 0.05},
        "sensor_model": {"type": "range_bearing", "sigma_range": 0.1, "sigma_bearing": 0.02},
        "initial_pose": [0, 0, 0],
        "initial_covariance": [[1e-6, 0, 0], [0, 1e-6, 0], [0, 0, 1e-6]],
    },
    indent=2,
)
BUNDLE = {
    "bundle.json": BUNDLE_JSON + "\n",
    "controls.csv": "t,v,omega\n0,1,0\n1,1,0.1\n2,1,0.1\n3,0,0\n",
    "measurements.csv": "t,range,bearing,landmark\n0.5,1.5,0.1,1\n1.5,2.0,-0.3,\n2.5,3.0,0.5,2\n",
    "map.csv": "landmark,x,y,cxx,cxy,cyy\n1,1.5,0.2,0.01,0,0.01\n2,3,1,0.02,0.001,0.02\n"
    "3,5,5,0.01,0,0.01\n",
    "groundtruth.csv": "t,x,y,theta\n0,0,0,0\n1,1,0,0\n2,2,0.1,0.1\n3,3,0.3,0.2\n",
    "landmarks_groundtruth.csv": "landmark,x,y\n1,1.5,0.2\n2,3,1\n3,5,5\n",
}


def _npy(m: int, blocks: list[list[float]] | None = None) -> bytes:
    """``0.01 I`` (2m × 2m), or the block-diagonal of the ``[cxx, cxy, cyy]`` ``blocks`` (a
    joint covariance must agree with map.csv's covariances)."""
    cov = 0.01 * np.eye(2 * m)
    for k, (cxx, cxy, cyy) in enumerate(blocks or []):
        cov[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = [[cxx, cxy], [cxy, cyy]]
    buf = io.BytesIO()
    np.save(buf, cov, allow_pickle=False)
    return buf.getvalue()


EST_MAP = LandmarkMap(np.array([1, 2, 3]), np.array([[0.0, 0], [1, 1], [1, 0]]))
REF_MAP = LandmarkMap(np.array([1, 2, 3]), np.array([[1.0, 0], [1, 1], [0, 0]]))


TUM_3D = (
    "# t x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n1 1 0 0.5 0.1 0 0 0.994987437\n2 2 0.1 0.7 0 0 0 1\n"
)
KITTI = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0.5\n0 -1 0 2 1 0 0 0.1 0 0 1 0.7\n"
EUROC = (
    "#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n"
    "1403636579758555392,0,0,0,1,0,0,0\n"
    "1403636579763555584,1,0,0.5,0.994987437,0.1,0,0\n"
    "1403636579768555520,2,0.1,0.7,1,0,0,0\n"
)


class Reader(NamedTuple):
    """A reader and its valid input: ``files`` (name → content) in one folder."""

    files: dict[str, str | bytes]
    read: Callable[[Path], Any]
    mutable: tuple[str, ...]  # the text files the tests mutate
    whole_folder: bool = False  # messages name a file inside the folder


def _one(name: str, text: str, read: Callable[[Path], Any]) -> Reader:
    return Reader({name: text}, lambda d: read(d / name), (name,))


def _traj(fmt: str) -> Callable[[Path], Any]:
    return lambda p: read_trajectory(p, format=fmt, skip_invalid=True)


READERS: dict[str, Reader] = {
    "trajectory-plain": _one("t.txt", PLAIN, _traj("plain")),
    "trajectory-tum": _one("t.tum", TUM, _traj("tum")),
    "trajectory-carmen": _one("t.log", CARMEN, _traj("carmen")),
    "trajectory-g2o": _one("t.g2o", G2O_TRAJ, _traj("g2o")),
    "trajectory-csv": _one("t.csv", CSV_TRAJ, _traj("csv")),
    "trajectory-detected": _one("t.dat", PLAIN, lambda p: read_trajectory(p)),
    "trajectory-tum-3d": _one("t3.tum", TUM_3D, _traj("tum")),
    "trajectory-kitti": _one("k.txt", KITTI, _traj("kitti")),
    "trajectory-euroc": _one("data.csv", EUROC, _traj("euroc")),
    "relations": _one("r.relations", RELATIONS, read_relations),
    "map-csv": _one("m.csv", MAP_CSV, read_map),
    "map-g2o": _one("m.g2o", MAP_G2O, read_map),
    "map-mrclam": _one("m.dat", MAP_MRCLAM, read_map),
    "association": _one("a.csv", ASSOCIATION, lambda p: read_association_csv(p, EST_MAP, REF_MAP)),
    "per-relation": _one(
        "p.csv", PER_RELATION, lambda p: read_per_relation(p, dataset="d", algorithm="a")
    ),
    "isam": _one("v.txt", ISAM, lambda p: read_isam(p, noise="covariance")),
    "g2o-graph": _one("g.g2o", G2O_GRAPH, read_g2o_graph),
    "keyword-records": _one("k.txt", KEYWORDS, lambda p: read_keyword_records(p, {"A": 3, "B": 2})),
    "mrclam-robot": Reader(MRCLAM, lambda d: read_mrclam_robot(d, 1), tuple(MRCLAM), True),
    "bundle": Reader(
        {
            **BUNDLE,
            "map_covariance.npy": _npy(3, [[0.01, 0, 0.01], [0.02, 0.001, 0.02], [0.01, 0, 0.01]]),
        },  # fmt: skip
        read_bundle,
        (*BUNDLE, "map_covariance.npy"),
        True,
    ),
}
TEXT_TABLES = {k: r for k, r in READERS.items()}  # every reader reads text tables


def _write(folder: Path, files: dict[str, str | bytes]) -> None:
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    for name, content in files.items():
        data = content.encode() if isinstance(content, str) else content
        (folder / name).write_bytes(data)


def _arrays(obj: Any) -> list[Any]:
    """The numbers in a reader's result, flattened (strings and paths left out)."""
    if isinstance(obj, np.ndarray):
        return [obj]
    if isinstance(obj, bool | int | float | np.number):
        return [np.asarray(obj)]
    if isinstance(obj, str | bytes | Path) or obj is None:
        return []
    if isinstance(obj, dict):
        return [x for k in sorted(obj, key=str) for x in _arrays(obj[k])]
    if dataclasses.is_dataclass(obj):
        return [x for f in dataclasses.fields(obj) for x in _arrays(getattr(obj, f.name))]
    if isinstance(obj, tuple | list):
        return [x for item in obj for x in _arrays(item)]
    if hasattr(obj, "__dict__"):
        return _arrays(vars(obj))
    return []


def _same(a: Any, b: Any) -> bool:
    xa, xb = _arrays(a), _arrays(b)
    return len(xa) == len(xb) and all(
        x.shape == y.shape
        and (
            np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
            if x.dtype.kind in "fc"
            else np.array_equal(x, y)
        )
        for x, y in zip(xa, xb)
    )


def _read_quietly(reader: Reader, folder: Path, allow: str | None = None) -> Any:
    """Read with every warning an error, except those whose message matches ``allow``."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if allow is not None:
            warnings.filterwarnings("ignore", message=allow)
        return reader.read(folder)


# ------------------------------------------------------------------- deterministic rules


def test_every_valid_file_reads_without_warning(tmp_path):
    for name, reader in READERS.items():
        _write(tmp_path / name, reader.files)
        _read_quietly(reader, tmp_path / name)


@pytest.mark.parametrize("name", sorted(READERS))
def test_bom_and_crlf_read_as_the_clean_file(tmp_path, name):
    reader = READERS[name]
    _write(tmp_path / "clean", reader.files)
    clean = _read_quietly(reader, tmp_path / "clean")
    for target in reader.mutable:
        if target.endswith(".npy"):
            continue
        text = reader.files[target]
        assert isinstance(text, str)
        odd = dict(reader.files)
        odd[target] = ("\ufeff" + text.replace("\n", "\r\n")).encode()
        _write(tmp_path / "odd", odd)
        got = _read_quietly(reader, tmp_path / "odd")
        assert _same(got, clean), (name, target)


@pytest.mark.parametrize("name", sorted(READERS))
def test_cut_off_last_line_is_skipped_even_when_it_parses(tmp_path, name):
    """``A\\nB\\nC`` reads as ``A\\nB\\n`` (C parses but has no newline), with a warning."""
    reader = READERS[name]
    for target in reader.mutable:
        if target.endswith((".json", ".npy")):
            continue
        files = {k: v for k, v in reader.files.items() if not k.endswith(".npy")}
        text = files[target]
        assert isinstance(text, str) and text.endswith("\n")
        cut = text[:-1]
        shorter = cut[: cut.rfind("\n") + 1]
        _write(tmp_path / "short", {**files, target: shorter})
        # a control row fewer can leave a measurement past the log: warned about, not an error
        expected = _read_quietly(reader, tmp_path / "short", allow=".*outside the span")
        _write(tmp_path / "cut", {**files, target: cut})
        line = cut.count("\n") + 1
        where = f"{tmp_path / 'cut' / target}:{line}: no newline at the end: the last line looks"
        with pytest.warns(TruncatedLineWarning) as caught:
            got = reader.read(tmp_path / "cut")
        # a cut-off last control row can leave a measurement past the log: warned about too
        caught = [w for w in caught if "outside the span" not in str(w.message)]
        assert [str(w.message).startswith(where) for w in caught] == [True], (name, target)
        if hasattr(got, "skipped"):  # a trajectory counts what it left out
            assert got.skipped == {**expected.skipped, "truncated last line": 1}
            got, expected = got.trajectory, expected.trajectory
        assert _same(got, expected), (name, target)


@pytest.mark.parametrize("name", sorted(READERS))
def test_comment_last_line_without_newline_is_ignored(tmp_path, name):
    reader = READERS[name]
    _write(tmp_path / "clean", reader.files)
    clean = _read_quietly(reader, tmp_path / "clean")
    for target in reader.mutable:
        if target.endswith((".json", ".npy")):
            continue
        _write(tmp_path / "c", {**reader.files, target: reader.files[target] + "# the end"})
        assert _same(_read_quietly(reader, tmp_path / "c"), clean), (name, target)


def test_a_cut_off_last_line_that_does_not_parse_is_also_skipped(tmp_path):
    (tmp_path / "r.relations").write_text(RELATIONS + "4.0 5.0 1.")
    with pytest.warns(TruncatedLineWarning, match=r"r\.relations:5: no newline"):
        assert len(read_relations(tmp_path / "r.relations")) == 3


def test_bom_cli_map_compare_same_numbers(tmp_path, capsys):
    from slamrel.cli import main

    (tmp_path / "est.csv").write_text(MAP_CSV)
    (tmp_path / "ref.csv").write_text("landmark,x,y\n1,0.1,0\n2,1,1.1\n3,1,0.1\n")
    (tmp_path / "odd.csv").write_bytes(("\ufeff" + MAP_CSV.replace("\n", "\r\n")).encode())
    ref = str(tmp_path / "ref.csv")
    ja, jb = str(tmp_path / "a.json"), str(tmp_path / "b.json")
    assert main(["map-compare", str(tmp_path / "est.csv"), ref, "--json", ja, "-q"]) == 0
    assert main(["map-compare", str(tmp_path / "odd.csv"), ref, "--json", jb, "-q"]) == 0
    capsys.readouterr()
    a = json.loads(Path(ja).read_text())
    b = json.loads(Path(jb).read_text())
    a.pop("inputs", None), b.pop("inputs", None)
    assert json.dumps(a, sort_keys=True).replace("est.csv", "odd.csv") == json.dumps(
        b, sort_keys=True
    )


def test_bom_crlf_cli_evaluate_same_numbers(tmp_path, capsys):
    from slamrel.cli import main

    odd = {
        n: ("\ufeff" + t.replace("\n", "\r\n")).encode()
        for n, t in (("r.relations", RELATIONS), ("e.txt", PLAIN))
    }
    (tmp_path / "r.relations").write_text(RELATIONS)
    (tmp_path / "e.txt").write_text(PLAIN)
    for name, data in odd.items():
        (tmp_path / f"odd-{name}").write_bytes(data)
    runs = []
    for prefix in ("", "odd-"):
        out = tmp_path / f"{prefix}out.json"
        args = [str(tmp_path / f"{prefix}r.relations"), str(tmp_path / f"{prefix}e.txt")]
        assert main(["evaluate", *args, "--json", str(out), "-q"]) == 0
        runs.append({k: v for k, v in json.loads(out.read_text()).items() if k != "inputs"})
    capsys.readouterr()
    assert json.dumps(runs[0], sort_keys=True) == json.dumps(runs[1], sort_keys=True).replace(
        "odd-", ""
    )


# ----------------------------------------------------------------------------- the fuzz

ODD_TOKENS = [
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b"1e400",
    b"1e308",
    b"-1e308",
    b"1e-320",
    b"0",
    b"-0",
    b"1e20",
    b"abc",
    b",",
    b" ",
    b"\t",
    b"\r",
    b"\n",
    b"\r\n",
    b"\x00",
    b"\xef\xbb\xbf",
    b"#",
    b"1.5.5",
    "\uff19".encode(),
    b"\xff\xfe",
    b"99999999999999999999",
    b"-",
    b".",
    b"1_0",
    b"0x10",
    b'"',
    b"FLASER",
    b"VERTEX_SE2",
    b"ODOMETRY",
    b"LANDMARK",
    b"\\u0000",
]


@st.composite
def mutations(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` after one to three random edits."""
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.integers(0, 11))
        n = len(data)
        pos = draw(st.integers(0, n))
        lines = data.splitlines(keepends=True)
        if op == 0 and n:  # flip a byte
            pos = min(pos, n - 1)
            data = data[:pos] + bytes([draw(st.integers(0, 255))]) + data[pos + 1 :]
        elif op == 1:  # insert an odd token
            data = data[:pos] + draw(st.sampled_from(ODD_TOKENS)) + data[pos:]
        elif op == 2:  # delete a few bytes
            data = data[:pos] + data[pos + draw(st.integers(1, 8)) :]
        elif op == 3:  # cut the file
            data = data[:pos]
        elif op in (4, 5, 6) and lines:
            k = draw(st.integers(0, len(lines) - 1))
            if op == 4:  # drop a line
                del lines[k]
            elif op == 5:  # duplicate a line
                lines.insert(k, lines[k])
            else:  # swap two lines
                j = draw(st.integers(0, len(lines) - 1))
                lines[k], lines[j] = lines[j], lines[k]
            data = b"".join(lines)
        elif op == 7:
            data = b"\xef\xbb\xbf" + data
        elif op == 8:
            data = data.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")
        elif op == 9 and lines:  # an extra field
            k = draw(st.integers(0, len(lines) - 1))
            sep = draw(st.sampled_from([b" ", b",", b"\t"]))
            body = lines[k].rstrip(b"\r\n")
            lines[k] = body + sep + draw(st.sampled_from(ODD_TOKENS[:12])) + lines[k][len(body) :]
            data = b"".join(lines)
        elif op == 10:  # replace a number by an odd one
            tokens = data.split(b" ")
            if len(tokens) > 1:
                k = draw(st.integers(0, len(tokens) - 1))
                tokens[k] = draw(st.sampled_from(ODD_TOKENS[:12]))
                data = b" ".join(tokens)
        elif op == 11:  # replace a comma-separated cell
            cells = data.split(b",")
            if len(cells) > 1:
                k = draw(st.integers(0, len(cells) - 1))
                cells[k] = draw(st.sampled_from(ODD_TOKENS[:12] + [b""]))
                data = b",".join(cells)
    return data


ALLOWED_WARNINGS = ("relation_metric", "recovery", "landmark_graph", "slamrel")


def _check_one(reader: Reader, folder: Path, target: str) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.filterwarnings("error", category=RuntimeWarning)
        try:
            reader.read(folder)
        except InputError as err:
            msg = str(err)
            named = str(folder) if reader.whole_folder else str(folder / target)
            assert named in msg, msg
            assert "np." not in msg and "Traceback" not in msg and "\\ufeff" not in msg, msg
            assert "allow_pickle" not in msg, msg
    for w in caught:
        module = type(w.message).__module__
        assert module.startswith(ALLOWED_WARNINGS), f"{type(w.message).__name__}: {w.message}"
        assert str(folder) in str(w.message)


def _fuzz(name: str, target: str, data: st.DataObject) -> None:
    reader = READERS[name]
    base = reader.files[target]
    raw = base.encode() if isinstance(base, str) else base
    mutated = data.draw(mutations(raw), label=target)
    folder = Path(_SCRATCH) / name
    _write(folder, {**reader.files, target: mutated})
    _check_one(reader, folder, target)


_SCRATCH = tempfile.mkdtemp(prefix="slamrel-fuzz-")
CASES = [(name, target) for name, r in sorted(READERS.items()) for target in r.mutable]


@pytest.mark.parametrize("name,target", CASES, ids=[f"{n}:{t}" for n, t in CASES])
@settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(data=st.data())
def test_mutated_input_gives_a_result_or_one_input_error(name, target, data):
    _fuzz(name, target, data)


# ------------------------------------------------ duplicated timestamps on the estimate side


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    repeats=st.lists(st.tuples(st.integers(0, 7), st.booleans()), min_size=1, max_size=4),
    seed=st.integers(0, 2**16),
)
def test_estimate_with_repeated_timestamps_scores_the_clean_estimate_or_is_refused(
    repeats: list[tuple[int, bool]], seed: int
) -> None:
    """Rows repeated (exactly or with another pose) and shuffled: the score is that of the
    clean estimate whatever the row order, or one InputError naming the file and a line."""
    from slamrel.evaluation import evaluate_files

    rng = np.random.default_rng(seed)
    t = np.arange(8) * 0.5
    poses = np.column_stack((t, 0.1 * t**2, 0.2 * t))
    rows = np.column_stack((t, poses))
    extra = []
    for k, differ in repeats:
        row = rows[k].copy()
        if differ:
            row[1 + int(rng.integers(0, 3))] += 0.25
        extra.append(row)
    noisy = rows + np.column_stack((np.zeros(8), 0.01 * rng.standard_normal((8, 3))))
    table = np.vstack(
        (noisy, [r + (noisy[int(r[0] / 0.5)] - rows[int(r[0] / 0.5)]) for r in extra])
    )
    table = table[rng.permutation(table.shape[0])]
    folder = Path(tempfile.mkdtemp(dir=_SCRATCH))
    ref = folder / "ref.txt"
    ref.write_text("".join(" ".join(f"{v:.17g}" for v in r) + "\n" for r in rows))
    clean, est = folder / "clean.txt", folder / "est.txt"
    clean.write_text("".join(" ".join(f"{v:.17g}" for v in r) + "\n" for r in noisy))
    est.write_text("".join(" ".join(f"{v:.17g}" for v in r) + "\n" for r in table))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = evaluate_files(ref, clean).translation.abs.mean
        if any(differ for _, differ in repeats):
            with pytest.raises(InputError) as err:
                evaluate_files(ref, est)
            assert f"{est}:" in str(err.value) and "two different estimate poses" in str(err.value)
        else:
            assert evaluate_files(ref, est).translation.abs.mean == expected
            with pytest.raises(InputError, match="--strict|strict"):
                evaluate_files(ref, est, strict=True)
