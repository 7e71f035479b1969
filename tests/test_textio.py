"""The numeric-table reader: fast path equals the exact path, bad files fall back to diagnosis."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data
from hypothesis import given, settings
from hypothesis import strategies as st

from relation_metric.errors import InputError
from relation_metric.textio import _fast_table, read_numeric_table

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
    with pytest.raises(InputError) as err:
        read_numeric_table(p, columns=("a", "b"))
    assert f"b.txt:{line}:" in str(err.value) and msg in str(err.value)
