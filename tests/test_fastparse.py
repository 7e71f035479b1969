"""slamrel.formats.fastparse: bit-exact against Python's float(), refuses what it cannot do.

Oracles: ``float(token)`` per token (CPython's correctly rounded ``strtod``), a regular
expression that states the accepted subset independently of the vectorised code, and the
exact reader (``read_numeric_table(..., source=read_source(path))`` skips every fast path).
"""

from __future__ import annotations

import math
import os
import re
import warnings
from decimal import ROUND_DOWN, ROUND_UP, Decimal, localcontext

import numpy as np
import pytest
from conftest import require_data
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import slamrel.formats.fastparse as fastparse
from relation_metric.errors import InputError
from slamrel.formats.fastparse import parse_decimal_table, read_decimal_table
from slamrel.formats.relations import read_relations
from slamrel.formats.text import TruncatedLineWarning, read_numeric_table, read_source

NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
REL_COLUMNS = ("t1", "t2", "x", "y", "z", "roll", "pitch", "yaw")


def in_subset(token: str) -> bool:
    """The fast path's token grammar, written independently of its code: a decimal number
    (sign, point and exponent optional) with a finite value; no nan, inf, hex, '_'."""
    return NUMBER.fullmatch(token) is not None and math.isfinite(float(token))


def python_table(text: str) -> np.ndarray:
    """float() of every field of every non-blank line after stripping ``#`` comments."""
    rows = [line.split("#", 1)[0].split() for line in text.splitlines()]
    return np.array([[float(t) for t in row] for row in rows if row], dtype=np.float64)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


@st.composite
def decimal_tokens(draw: st.DrawFn) -> str:
    """Plain decimals: signs, leading zeros, '.5', '5.', -0, up to 24 digits (mantissas
    beyond 2**53 and 2**63), now and then an exponent or a '+' sign."""
    mantissa = draw(
        st.integers(0, 2**53 - 1)
        | st.integers(0, 10**6)
        | st.integers(2**53, 10**19)
        | st.integers(0, 10**24)
        | st.integers(2**53 - 4, 2**53 + 4)
    )
    frac_len = draw(st.integers(0, 24))
    zeros = draw(st.integers(0, 2))
    digits = "0" * zeros + str(mantissa).rjust(frac_len, "0")
    int_part, frac_part = digits[: len(digits) - frac_len], digits[len(digits) - frac_len :]
    if frac_part:
        if int_part == "" or draw(st.booleans()):
            int_part = int_part if int_part else draw(st.sampled_from(["", "0"]))
        token = f"{int_part}.{frac_part}"
    else:
        token = int_part + draw(st.sampled_from(["", "."]))
    token = draw(st.sampled_from(["", "", "", "-", "-", "+"])) + token
    if draw(st.integers(0, 9)) == 0:
        token += draw(st.sampled_from(["e", "E"])) + str(draw(st.integers(-30, 30)))
    assume(in_subset(token))
    return token


@st.composite
def tables(draw: st.DrawFn, tokens: st.SearchStrategy[str]) -> tuple[str, int]:
    ncols = draw(st.integers(1, 5))
    nrows = draw(st.integers(1, 12))
    blank = st.text(" \t", min_size=1, max_size=3)
    end = st.sampled_from(["\n", "\r\n", " \n", "\t\n", "  # note\n"])
    lines = []
    for _ in range(nrows):
        if draw(st.integers(0, 5)) == 0:
            lines.append(draw(st.sampled_from(["\n", "# comment 1.5e3 nan\n", "  \t\n"])))
        fields = [draw(tokens) for _ in range(ncols)]
        lead = draw(st.sampled_from(["", " ", "\t "]))
        seps = [draw(blank) for _ in range(ncols - 1)]
        line = lead + "".join(f + s for f, s in zip(fields, seps)) + fields[-1]
        lines.append(line + draw(end))
    text = "".join(lines)
    if draw(st.booleans()):
        text = text.rstrip("\r\n")  # no final newline: the last line is still a complete row
        assume("#" not in text.rsplit("\n", 1)[-1])
    return text, ncols


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(tables(decimal_tokens()))
def test_equals_python_float_bit_for_bit(table):
    text, ncols = table
    values = parse_decimal_table(text.encode(), ncols)
    assert values is not None
    assert same_bits(values, python_table(text).reshape(-1, ncols))


@settings(max_examples=200, deadline=None)
@given(tables(st.text("0123456789.-+eE:/;x", min_size=1, max_size=22)))
def test_accepts_exactly_the_subset(table):
    """Arbitrary tokens: parsed bit-exactly when all are in the subset, refused otherwise."""
    text, ncols = table
    tokens = python_tokens(text)
    values = parse_decimal_table(text.encode(), ncols)
    if all(in_subset(t) for t in tokens):
        assert values is not None
        assert same_bits(values, python_table(text).reshape(-1, ncols))
    else:
        assert values is None


def python_tokens(text: str) -> list[str]:
    return [t for line in text.splitlines() for t in line.split("#", 1)[0].split()]


def test_seeded_random_decimals(rng, monkeypatch):
    """10^5 numbers printed with 0..20 decimals, %.15g..%.19g and repr at magnitudes
    1e-6 .. 1e12, both signs (repr and %.17g hold 17 significant digits: above 2**53)."""
    monkeypatch.setattr(fastparse, "MIN_ODD_ALLOWANCE", 10**9)  # exponents, 20 digits
    n = 100_000
    magnitude = 10.0 ** rng.integers(-6, 13, n)
    numbers = rng.uniform(-1, 1, n) * magnitude
    decimals = rng.integers(0, 21, n)
    tokens = [f"{x:.{d}f}" for x, d in zip(numbers.tolist(), decimals.tolist())]
    tokens += [f"{x:.{d}g}" for x, d in zip(numbers.tolist(), (15 + decimals % 5).tolist())]
    tokens += [repr(x) for x in numbers.tolist()]
    tokens = tokens[: len(tokens) // 4 * 4]
    text = "\n".join(" ".join(tokens[k : k + 4]) for k in range(0, len(tokens), 4)) + "\n"
    values = parse_decimal_table(text.encode(), 4)
    assert values is not None
    assert same_bits(values.ravel(), np.array([float(t) for t in tokens]))


def near_midpoints(rng, n: int) -> list[str]:
    """Decimals of 16–19 significant digits just above and below the midpoints between
    doubles (and their neighbours at powers of two): the hardest cases for rounding."""
    exponent = rng.integers(-30, 63, n)
    base = np.ldexp(1.0, exponent)
    doubles = base * rng.uniform(1, 2, n)
    doubles[: n // 10] = base[: n // 10]  # powers of two
    doubles[n // 10 : n // 5] = np.nextafter(base[n // 10 : n // 5], 0)  # just below them
    tokens = []
    for v in doubles.tolist():
        for w in (float(np.nextafter(v, np.inf)), float(np.nextafter(v, 0))):
            mid = (Decimal(v) + Decimal(w)) / 2
            for sig in (16, 17, 18, 19):
                scaled = mid.scaleb(sig - 1 - mid.adjusted())
                for rounding in (ROUND_UP, ROUND_DOWN):
                    digits = scaled.quantize(Decimal(1), rounding=rounding)
                    tokens.append(format(digits.scaleb(mid.adjusted() - sig + 1), "f"))
    return tokens


def test_near_midpoints_and_ties_bit_for_bit(rng, monkeypatch):
    """Adversarial decimals a few units beyond the 17th digit from a rounding midpoint,
    exact ties (2**53 + odd, 2**62 + odd multiples of 2**9) and powers of two written with
    17–19 digits: every one equals float(token)."""
    monkeypatch.setattr(fastparse, "MIN_ODD_ALLOWANCE", 10**9)  # ties go to float()
    with localcontext() as ctx:
        ctx.prec = 60
        tokens = near_midpoints(rng, 3000)
    tokens += [str(2**53 + k) for k in range(-50, 50)]
    tokens += [str(2**62 + k * 2**9) for k in range(-50, 50)]
    tokens += ["1.0000000000000000", "0.50000000000000000", "0.99999999999999999", "-2.0e0"]
    tokens = tokens[: len(tokens) // 4 * 4]
    text = "\n".join(" ".join(tokens[k : k + 4]) for k in range(0, len(tokens), 4)) + "\n"
    values = parse_decimal_table(text.encode(), 4)
    assert values is not None
    assert same_bits(values.ravel(), np.array([float(t) for t in tokens]))


def test_many_odd_tokens_are_left_to_numpy(tmp_path):
    """A table of exponent tokens only is refused (numpy's parser reads it faster); the
    reader then reads it exactly."""
    rows = np.random.default_rng(3).normal(0, 1e3, (400, 8))
    path = write(tmp_path, "".join(" ".join(f"{v:.6e}" for v in row) + "\n" for row in rows))
    assert read_decimal_table(path, 8) is None
    values, _ = read_numeric_table(path, columns=REL_COLUMNS)
    assert same_bits(values, python_table(path.read_text()))
    few = write(tmp_path, "1e3 -2.5E-1 +3 4 5 6 7 8\n", "few.relations")
    fast = read_decimal_table(few, 8)
    assert fast is not None and fast.values[0, :3].tolist() == [1000.0, -0.25, 3.0]


def test_freiburg_style_timestamps_and_signed_zero():
    text = (
        "1134864645.90321 1134864646.32420 0.31293 -0.00000\n"
        "976052905.167303 976052911.885496 -0.056990 -1.682210\n"
        "1134864645.903210 9007199254740991 .5 5.\n"
    )
    values = parse_decimal_table(text.encode(), 4)
    assert values is not None
    assert same_bits(values, python_table(text))
    assert np.signbit(values[0, 3]) and values[0, 3] == 0.0


def test_many_blocks(monkeypatch, rng):
    """Blocks of a few lines each (comments, CRLF and blank lines across block cuts)."""
    monkeypatch.setattr(fastparse, "_BLOCK", 40)
    rows = rng.normal(0, 100, (500, 3))
    lines = []
    for k, row in enumerate(rows):
        if k % 7 == 0:
            lines.append("# a comment line\r\n" if k % 2 else "\n")
        end = "  # trailing\n" if k % 5 == 0 else ("\r\n" if k % 3 == 0 else "\n")
        lines.append("\t".join(f"{v:.{k % 9}f}" for v in row) + end)
    text = "".join(lines)
    values = parse_decimal_table(text.encode(), 3)
    assert values is not None
    assert same_bits(values, python_table(text))


@pytest.mark.parametrize("workers", [1, 3])
def test_blocks_in_threads_equal_one_by_one(monkeypatch, rng, workers):
    """Blocks parsed by several threads (or one) fill the rows in order, the gaps of blank
    and comment lines closed."""
    monkeypatch.setattr(fastparse, "_BLOCK", 64)
    monkeypatch.setattr(fastparse, "_workers", lambda: workers)
    rows = rng.normal(0, 10, (300, 2))
    lines = [
        ("# c\n\n" if k % 4 == 0 else "") + f"{a!r} {b:.3f}\n"
        for k, (a, b) in enumerate(rows.tolist())
    ]
    text = "".join(lines)
    values = parse_decimal_table(text.encode(), 2)
    assert values is not None
    assert same_bits(values, python_table(text))


def _parse_many_blocks(text: str) -> np.ndarray | None:
    fastparse._BLOCK = 64
    fastparse._workers = lambda: 2  # type: ignore[assignment]
    return parse_decimal_table(text.encode(), 2)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_forked_child_parses_with_its_own_threads(monkeypatch):
    """A process forked after the parent started its parsing threads (as Dask's and
    multiprocessing's workers are) has no copy of them: it must start its own, not wait."""
    import multiprocessing

    text = "".join(f"{k}.5 {k}.25\n" for k in range(400))
    monkeypatch.setattr(fastparse, "_BLOCK", 64)
    monkeypatch.setattr(fastparse, "_workers", lambda: 2)
    assert parse_decimal_table(text.encode(), 2) is not None  # the parent's pool exists
    with multiprocessing.get_context("fork").Pool(1) as pool:
        child = pool.apply_async(_parse_many_blocks, (text,)).get(timeout=60)
    assert child is not None and same_bits(child, python_table(text))


@pytest.mark.parametrize("name", ["aces", "fr079", "intel", "mit-csail"])
def test_real_relations_files(name):
    path = require_data("freiburg", f"{name}.relations")
    raw = path.read_bytes()
    fast = read_decimal_table(path, 8)
    assert fast is not None
    values, text, cut_off = fast
    assert bytes(text) == raw and cut_off is None
    assert same_bits(values, python_table(raw.decode()))
    exact, _ = read_numeric_table(path, columns=REL_COLUMNS, source=read_source(path))
    assert same_bits(values, exact)


@pytest.mark.parametrize(
    "text",
    [
        "1 nan\n",
        "1 inf\n",
        "1 -inf\n",
        "1 1e999\n",  # overflows to inf
        "1 2.3.4\n",
        "1 --2\n",
        "1 ++2\n",
        "1 2-3\n",
        "1 2e\n",
        "1 e5\n",
        "1 2e+-3\n",
        "1 2e3.5\n",
        "1 0x10\n",
        "1 1_000\n",
        "1 .\n",
        "1 -\n",
        "1 -.\n",
        "1 1,5\n",
        "1 2\n3\n",  # a short row
        "1 2 3\n",  # a long row
        "1\n2\n",  # one row split over two lines
        "",  # empty
        "# only a comment\n\n",
        "1 2\n3 4 # note",  # comment on a last line without newline
        "1 2\n3",  # cut-off last line
        "1 2\n3 4\r",  # lone CR at the end
        "1 2\r3 4\n",  # lone CR: a line break for str.splitlines
        "1 2\x0b\n",  # vertical tab
        "1 2\x0c\n",  # form feed
        "1 \x002\n",  # NUL
        "1 2 # caf\u00e9\n",  # non-ASCII in a comment: the exact path checks UTF-8
        "1 \u00b2\n",
    ],
)
def test_refuses_what_it_cannot_do_exactly(text):
    assert parse_decimal_table(text.encode(), 2) is None


def test_every_non_digit_byte_in_every_position_is_caught():
    """Exhaustive over printable ASCII: one foreign byte anywhere in a token of 8, 16 or 24
    digits (read as one, two or three words) refuses the table."""
    foreign = [chr(c) for c in range(33, 127) if not chr(c).isdigit() and chr(c) not in "#."]
    for digits in ("12345678", "9" * 16, "1234567890" * 2 + "1234"):
        for k in range(len(digits)):
            for c in foreign:
                token = digits[:k] + c + digits[k + 1 :]
                if NUMBER.fullmatch(token):
                    continue  # e.g. "1234e678": a number (odd token), not a foreign byte
                assert parse_decimal_table(f"1 {token}\n".encode(), 2) is None, token


def test_comment_character_must_not_be_part_of_numbers():
    assert parse_decimal_table(b"1 2\n", 2, comment="-") is None
    assert parse_decimal_table(b"1 2\n", 2, comment="##") is None
    assert parse_decimal_table(b"1 2\n; x\n", 2, comment=";") is not None


def test_read_decimal_table_unreadable(tmp_path):
    assert read_decimal_table(tmp_path / "missing.txt", 2) is None
    assert read_decimal_table(tmp_path, 2) is None


# --- the reader in textio: same values, same line numbers, same messages ------------------


def write(tmp_path, text: str, name: str = "t.relations"):
    path = tmp_path / name
    path.write_bytes(text.encode())
    return path


GOOD = (
    "# t1 t2 x y z roll pitch yaw\n"
    "90.239599 90.719599 0.422330 -0.000750 0.000000 0.000000 0.000000 0.017260\n"
    "\n"
    "90.719599\t91.321399  0.213430 -0.014750 0.000000  0.000000 0.000000 -0.405780 # c\n"
    "  # an indented comment\n"
    "94.399600 94.759600 0.277100 0.063830 0.000000 0.000000 0.000000 0.097740\r\n"
)


def test_read_numeric_table_fast_equals_exact(tmp_path):
    path = write(tmp_path, GOOD)
    assert read_decimal_table(path, 8) is not None  # the fast path takes this file
    values, lines = read_numeric_table(path, columns=REL_COLUMNS)
    exact, exact_lines = read_numeric_table(path, columns=REL_COLUMNS, source=read_source(path))
    assert same_bits(values, exact)
    assert [lines(k) for k in range(3)] == [exact_lines(k) for k in range(3)] == [2, 4, 6]
    rel = read_relations(path)
    assert rel.delta[1, 2] == float("-0.405780") and rel.first[0] == float("90.239599")


BAD = [
    # (text, line, message after "path:line: ")
    (
        "1 2 3 4 5 6 7 8\n1 2 0.1a 4 5 6 7 8\n",
        2,
        "field 'x': expected a number, got '0.1a'",
    ),
    ("1 2 3 4 5 6 7 8\n1 2 3 NaN 5 6 7 8\n", 2, "field 'y': expected a finite number, got 'NaN'"),
    (
        "# h\n1 2 3 4 5 6 7 8\n1 2 3 4 5 6 7\n",
        3,
        "expected 8 fields (t1 t2 x y z roll pitch yaw) (a Freiburg .relations file), got 7",
    ),
    (
        "1 2 3 4 5 6 7 8\n1 2 3 4 5\n1 2 3 4 5 6 7 8\n",
        2,
        "expected 8 fields (t1 t2 x y z roll pitch yaw) (a Freiburg .relations file), got 5",
    ),
]


@pytest.mark.parametrize("text,line,message", BAD)
def test_error_messages_unchanged(tmp_path, text, line, message):
    path = write(tmp_path, text)
    assert read_decimal_table(path, 8) is None
    with pytest.raises(InputError) as fast_err:
        read_relations(path)
    with pytest.raises(InputError) as exact_err:
        read_numeric_table(
            path,
            columns=REL_COLUMNS,
            describe="a Freiburg .relations file",
            source=read_source(path),
        )
    assert str(fast_err.value) == str(exact_err.value) == f"{path}:{line}: {message}"
    assert fast_err.value.line == line


def test_empty_file_message_unchanged(tmp_path):
    for text in ("", "# only a header\n\n"):
        path = write(tmp_path, text)
        with pytest.raises(InputError) as err:
            read_relations(path)
        assert str(err.value) == (
            f"{path}: no data (a Freiburg .relations file): expected at least 1 line(s) of 8 "
            "numbers (t1 t2 x y z roll pitch yaw)"
        )


CUT = r"t\.relations:3: no newline at the end: the last line looks cut off; skipped"


def test_truncated_last_line_still_warned_and_skipped(tmp_path):
    path = write(tmp_path, "1 2 3 4 5 6 7 8\n1 2 3 4 5 6 7 8\n1 2 3 4.")
    with pytest.warns(TruncatedLineWarning, match=CUT):
        rel = read_relations(path)
    assert len(rel) == 2


@pytest.mark.parametrize("exact", [False, True])
def test_parsing_last_line_without_newline_is_cut_off(tmp_path, exact):
    """``... -2.`` may be what is left of ``-2.575``: skipped with a warning, fast or exact."""
    path = write(tmp_path, "1 2 3 4 5 6 7 8\n1 2 3 4 5 6 7 8\n1 2 3 4 5 6 7 -2.")
    fast = read_decimal_table(path, 8)
    assert fast is not None and fast.values.shape == (2, 8) and fast.cut_off_line == 3
    source = read_source(path) if exact else None
    with pytest.warns(TruncatedLineWarning, match=CUT) as caught:
        values, lines = read_numeric_table(path, columns=REL_COLUMNS, source=source)
    assert len(caught) == 1
    assert values.shape == (2, 8) and lines(1) == 2


@pytest.mark.parametrize("tail", ["", "  ", "# a comment", "\t# c 1 2"])
def test_blank_or_comment_last_line_without_newline_is_ignored(tmp_path, tail):
    path = write(tmp_path, "1 2 3 4 5 6 7 8\n" + tail)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values, _ = read_numeric_table(path, columns=REL_COLUMNS)
        exact, _ = read_numeric_table(path, columns=REL_COLUMNS, source=read_source(path))
    assert values.shape == exact.shape == (1, 8)


def test_bom_and_crlf_fast_path_bit_exact(tmp_path):
    clean = write(tmp_path, GOOD, "clean.relations")
    crlf = GOOD.replace("\r\n", "\n").replace("\n", "\r\n")
    odd = write(tmp_path, "\ufeff" + crlf, "odd.relations")
    fast = read_decimal_table(odd, 8)
    assert fast is not None  # the fast path takes it
    ref, ref_lines = read_numeric_table(clean, columns=REL_COLUMNS)
    values, lines = read_numeric_table(odd, columns=REL_COLUMNS)
    exact, exact_lines = read_numeric_table(odd, columns=REL_COLUMNS, source=read_source(odd))
    assert same_bits(values, ref) and same_bits(exact, ref) and same_bits(fast.values, ref)
    assert [lines(k) for k in range(3)] == [exact_lines(k) for k in range(3)] == [2, 4, 6]
    assert [ref_lines(k) for k in range(3)] == [2, 4, 6]


def test_bom_error_names_the_real_line(tmp_path):
    path = write(tmp_path, "\ufeff1 2 3 4 5 6 7 x\n")
    with pytest.raises(
        InputError, match=r"t\.relations:1: field 'yaw': expected a number, got 'x'"
    ):
        read_relations(path)


def test_fallback_still_reads_what_the_fast_path_refuses(tmp_path):
    path = write(tmp_path, "1e3 -2.5E-1 +3 4 5 6 7 8\n" * 300 + "1 2 3 4 5 6 7 8\n")
    assert read_decimal_table(path, 8) is None  # 900 odd tokens of 2408
    values, _ = read_numeric_table(path, columns=REL_COLUMNS)
    assert values[0, :3].tolist() == [1000.0, -0.25, 3.0] and values.shape == (301, 8)
