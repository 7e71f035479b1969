"""The numeric-table reader: fast path equals the exact path, bad files fall back to diagnosis."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data
from hypothesis import given, settings
from hypothesis import strategies as st

from relation_metric.errors import InputError
from slamrel.formats.text import _fast_table, read_numeric_table

decimal = st.decimals(
    min_value=-1e9, max_value=1e9, places=6, allow_nan=False, allow_infinity=False
)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(decimal, decimal, decimal, decimal), min_size=1, max_size=30))
def test_fast_path_equals_python_float(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("t") / "a.txt"
    text = "".join(" ".join(f"{v:f}" for v in row) + "\n" for row in rows)  # plain decimals
    path.write_text(text)
    fast = _fast_table(path, 4, "#")
    assert fast is not None
    expected = np.array([[float(f"{v:f}") for v in row] for row in rows])
    np.testing.assert_array_equal(fast[0], expected)  # bit for bit
    values, _ = read_numeric_table(path, columns=("a", "b", "c", "d"))
    np.testing.assert_array_equal(values, expected)


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["aces", "fr079", "intel", "mit-csail"])
def test_real_relation_files_fast_equals_loadtxt(name):
    path = require_data("freiburg", f"{name}.relations")
    fast = _fast_table(path, 8, "#")
    assert fast is not None
    np.testing.assert_array_equal(fast[0], np.loadtxt(path, comments="#", ndmin=2))


def test_row_lines_skip_comments(tmp_path):
    p = tmp_path / "c.txt"
    p.write_text("# head\n1 2\n\n# mid\n3 4  # a trailing comment, as np.loadtxt allows\n")
    values, lines = read_numeric_table(p, columns=("a", "b"))
    np.testing.assert_array_equal(values, [[1, 2], [3, 4]])
    assert (lines(0), lines(1)) == (2, 5)


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("1 2\n3 inf\n", 2, "finite"),
        ("1 2\n3 0x4\n", 2, "got '0x4'"),
    ],
)
def test_fast_path_refuses_what_the_strict_reader_rejects(tmp_path, text, line, msg):
    p = tmp_path / "b.txt"
    p.write_text(text)
    assert _fast_table(p, 2, "#") is None
    assert_error_at(lambda: read_numeric_table(p, columns=("a", "b")), f"b.txt:{line}:", msg)


def assert_error_at(read, where, msg):
    """``read()`` raises an :class:`InputError` naming ``where`` (``FILE:LINE:``) and ``msg``."""
    with pytest.raises(InputError) as err:
        read()
    assert where in str(err.value) and msg in str(err.value)


# --- the one header-CSV table reader --------------------------------------------------

from slamrel.formats.text import (  # noqa: E402
    SourceText,
    format_csv_table,
    read_csv_table,
    read_source,
)


def test_csv_table_header_case_blanks_alternatives_and_empty_cells(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("# c\n T , X,Rot_Error_Deg,extra,W\n1, 2.5,3,word,\n\n4,5,6,x,7\n")
    cols, lines = read_csv_table(
        p,
        required=("t", "x", ("rot_error_rad", "rot_error_deg")),
        optional=("w", "q"),
        empty_ok=("w",),
    )
    assert sorted(cols) == ["rot_error_deg", "t", "w", "x"]
    assert cols["x"].tolist() == [2.5, 5.0] and lines.tolist() == [3, 5]
    assert np.isnan(cols["w"][0]) and cols["w"][1] == 7.0


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("", None, "empty file (a test table): expected a header t,x"),
        ("t,y\n1,2\n", 1, "missing column(s) x (a test table); expected a header t,x"),
        ("t,x\n1,2\n1,2,3\n", 3, "expected 2 comma-separated fields (t,x) (a test table), got 3"),
        ("t,x\n1,2\n1,\n", 3, "column 'x': expected a number, got ''"),
        ("t,x\n1,inf\n", 2, "column 'x': expected a finite number, got 'inf'"),
        ("t,x\n1,1_0\n", 2, "column 'x': expected a number, got '1_0'"),
        ("t,x\n1,\ufeff2\n", 2, "column 'x': expected a number, got '<U+FEFF>2'"),
    ],
)
def test_csv_table_errors_name_file_and_line(tmp_path, text, line, msg):
    p = tmp_path / "a.csv"
    p.write_text(text)
    with pytest.raises(InputError) as err:
        read_csv_table(p, required=("t", "x"), describe="a test table")
    where = f"{p}:{line}: " if line else f"{p}: "
    assert str(err.value) == where + msg


cells = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["", " 1.5 ", "nan", "-inf", "x", "1e5", "+2", "1_0", ".5", "5."]),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(cells, cells), min_size=1, max_size=8))
def test_csv_table_numpy_path_equals_line_by_line(tmp_path_factory, rows):
    """Whatever numpy's parser accepts, the exact line-by-line reader gives the same."""
    from slamrel.formats.text import _parse_csv_lines

    p = tmp_path_factory.mktemp("c") / "a.csv"
    text = "a,b\n" + "".join(f"{x},{y}\n" for x, y in rows)
    p.write_text(text)
    src = read_source(p)
    data = list(src.data_lines())
    try:
        exact = _parse_csv_lines(src, data[1:], ["a", "b"], ["a", "b"], ["b"], "")
    except InputError as err:
        with pytest.raises(InputError) as got:
            read_csv_table(p, required=("a", "b"), empty_ok=("b",))
        assert str(got.value) == str(err)
        return
    cols, _ = read_csv_table(p, required=("a", "b"), empty_ok=("b",))
    got = np.column_stack((cols["a"], cols["b"]))
    assert np.array_equal(got.view(np.int64), exact.view(np.int64))  # bit for bit


def test_csv_table_bom_crlf_and_cut_off_line(tmp_path):
    from slamrel.formats.text import TruncatedLineWarning

    p = tmp_path / "a.csv"
    p.write_bytes(b"\xef\xbb\xbft,x\r\n1,2\r\n3,4")
    with pytest.warns(TruncatedLineWarning, match=r"a\.csv:3: no newline at the end"):
        cols, lines = read_csv_table(p, required=("t", "x"))
    assert cols["x"].tolist() == [2.0] and lines.tolist() == [2]


def test_format_csv_table_exact_and_empty_nan():
    text = format_csv_table(
        ["id", "v", "w"], [[3, 4], [0.1, 1 / 3], [np.nan, 2.0]], ["%d", "%.17g", "%.17g"]
    )
    assert text == "id,v,w\n3,0.10000000000000001,\n4,0.33333333333333331,2\n"
    assert float(text.splitlines()[2].split(",")[1]) == 1 / 3


def test_source_text_cut_off_line_rules():
    s = SourceText("f", ["1 2", "3 4"], ends_with_newline=False)
    assert s.cut_off_line() == 2
    assert SourceText("f", ["1 2", "# c"], ends_with_newline=False).cut_off_line() is None
    assert SourceText("f", ["1 2", "  "], ends_with_newline=False).cut_off_line() is None
    assert SourceText("f", ["1 2", "3 4"], ends_with_newline=True).cut_off_line() is None


# --- keyword records (g2o, iSAM text): the one-pass path and the diagnosing fallback -------

from slamrel.formats.text import (  # noqa: E402
    _keyword_records_fast,
    read_keyword_records,
)

KINDS = {"A": 3, "B": 2}


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from("AB"), decimal, decimal), min_size=0, max_size=30))
def test_keyword_records_one_pass_equals_python_float(tmp_path_factory, records):
    path = tmp_path_factory.mktemp("k") / "k.txt"
    lines = ["# a comment", ""]  # line numbers count these
    for kind, u, v in records:
        lines.append(f"{kind} {u:f} {v:f}" if kind == "A" else f"{kind}  {u:e}")
    path.write_text("\n".join(lines) + "\n")
    fast = _keyword_records_fast(read_source(path), KINDS)
    assert fast is not None
    got = read_keyword_records(path, KINDS)
    for kind, n in KINDS.items():
        rows = [(i + 3, r) for i, r in enumerate(records) if r[0] == kind]  # 1-based, 2 skipped
        want = [[float(f"{u:f}"), float(f"{v:f}")] if kind == "A" else [float(f"{u:e}")]
                for _, (_, u, v) in rows]  # fmt: skip
        for values, numbers in (fast[kind], got[kind]):
            assert values.shape == (len(rows), n - 1)
            np.testing.assert_array_equal(values, np.reshape(want, (-1, n - 1)))  # bit for bit
            np.testing.assert_array_equal(numbers, [i for i, _ in rows])


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("A 1 2\nB nan\nC 1\n", 2, "finite"),  # the first bad line wins, not the unknown record
        ("A 1 2\nB 1\nA 1 0x2\nB 1 2\n", 3, "got '0x2'"),
        ("A 1 2\nB 1 2\nA 1 inf\n", 2, "expected 2 fields"),
        ("A 1 2\nB 1\nA 1 1_0\n", 3, "got '1_0'"),
        ("A 1 2\nD 4\n", 2, "unknown record 'D'"),
    ],
)
def test_keyword_records_errors_name_the_first_bad_line(tmp_path, text, line, msg):
    p = tmp_path / "k.txt"
    p.write_text(text)
    assert _keyword_records_fast(read_source(p), KINDS) is None
    assert_error_at(lambda: read_keyword_records(p, KINDS), f"k.txt:{line}:", msg)
