"""Strict reading of whitespace-separated text tables, and atomic writing.

Readers in slamrel share three rules:

* a bad line raises :class:`~relation_metric.errors.InputError` with the file, the 1-based
  line number and what was expected;
* the only tolerated defect is a **cut-off last line**: a file whose last line has no final
  newline was cut off (a log whose writer was stopped), so that line is skipped with a
  :class:`TruncatedLineWarning` naming ``file:line`` even when it parses (``-2.`` may be
  what is left of ``-2.575``). A blank or comment last line without newline is just ignored.
  JSON documents are exempt (a JSON parser sees a cut-off document);
* a leading UTF-8 byte order mark is ignored and lines may end with ``\r\n``;
* ``#`` starts a comment line; blank lines are ignored.

The rule lives in one place, :class:`SourceText` (and the byte-level fast path of
:func:`read_numeric_table`), so that no reader can differ. Numeric tables take a fast path
(:mod:`slamrel.formats.fastparse`, then numpy's C parser); only when it fails, or finds a
non-finite value, the file is re-read line by line to say exactly where and why. Header CSV
tables are read by :func:`read_csv_table` and written by :func:`write_csv_table`.
"""

from __future__ import annotations

import json
import math
import os
import re
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.arrays import PathLike
from relation_metric.errors import InputError
from relation_metric.ids import integer_ids
from slamrel.formats.fastparse import UTF8_BOM, read_decimal_table
from slamrel.outputs import (
    atomic_write,
    write_bytes_atomic,
    write_text_atomic,
)

__all__ = [
    "NUMBER_FORMAT",
    "TruncatedLineWarning",
    "SourceText",
    "read_source",
    "read_head",
    "read_numeric_table",
    "atomic_write",
    "RowLines",
    "CsvTable",
    "read_csv_table",
    "csv_header",
    "read_csv_text_column",
    "read_csv_id_column",
    "exact_integer_tokens",
    "record_id_tokens",
    "exact_record_ids",
    "format_csv_table",
    "write_csv_table",
    "parse_float",
    "loads_json",
    "quote_token",
    "write_text_atomic",
    "write_bytes_atomic",
]

NUMBER_FORMAT = "%.17g"
"""How the files slamrel writes spell a double: 17 significant digits, the fewest that read
back bit for bit for every finite double (``float(NUMBER_FORMAT % x) == x``). Every writer of
:mod:`slamrel.formats` uses it; a format whose tradition differs names its own constant."""


class TruncatedLineWarning(UserWarning):
    """A last line without final newline (cut off) was skipped."""


def cut_off_message(path: str, line: int) -> str:
    """The text of the :class:`TruncatedLineWarning` for ``path:line``."""
    return f"{path}:{line}: no newline at the end: the last line looks cut off; skipped"


@dataclass(frozen=True)
class SourceText:
    """The lines of a text file, ready for parsing.

    Attributes
    ----------
    path : str
        The file name used in messages.
    lines : list of str
        All lines without their line ends (the possibly cut-off last one included; a
        leading byte order mark removed).
    ends_with_newline : bool
        False when the last line has no newline: it is then cut off (see the module
        docstring) and :meth:`data_lines` skips it with a warning.
    """

    path: str
    lines: list[str]
    ends_with_newline: bool
    _warned: list[bool] = field(default_factory=list, repr=False, compare=False)

    def cut_off_line(self, comment: str = "#") -> int | None:
        """The 1-based number of the cut-off last line, or ``None``.

        A last line without newline is cut off when it holds data (it is neither blank nor
        a ``comment`` line).
        """
        if self.ends_with_newline or not self.lines:
            return None
        text = self.lines[-1].strip()
        if not text or text.startswith(comment):
            return None
        return len(self.lines)

    def data_lines(self, comment: str = "#") -> Iterator[tuple[int, str]]:
        """Yield ``(line_number, stripped_text)`` for the non-blank, non-comment lines.

        The cut-off last line is not yielded: reaching it issues the
        :class:`TruncatedLineWarning` (once per :class:`SourceText`).
        """
        cut = self.cut_off_line(comment)
        for number, raw in enumerate(self.lines, start=1):
            text = raw.strip()
            if text and not text.startswith(comment):
                if number == cut:
                    self.warn_cut_off(number)
                    return
                yield number, text

    def warn_cut_off(self, number: int) -> None:
        """Issue the warning for the skipped, cut-off last line (once)."""
        if self._warned:
            return
        self._warned.append(True)
        warnings.warn(cut_off_message(self.path, number), TruncatedLineWarning, stacklevel=3)


def _decode(raw: bytes, name: str) -> str:
    if raw.startswith(UTF8_BOM):
        raw = raw[len(UTF8_BOM) :]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise InputError("not UTF-8 text", path=name, line=line) from None
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise InputError("contains a NUL byte; expected a text file", path=name, line=line)
    return text


def read_bytes(path: PathLike) -> bytes:
    """The bytes of a file, with a clear :class:`InputError` for a missing or odd path."""
    name = os.fspath(path)
    try:
        return Path(name).read_bytes()
    except FileNotFoundError:
        raise InputError("no such file", path=name) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a text file", path=name) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=name) from None


def read_text(path: PathLike) -> str:
    """A whole UTF-8 text file (a byte order mark removed) for a document parser (JSON).

    No cut-off rule: the document parser sees a cut-off document.
    """
    name = os.fspath(path)
    return _decode(read_bytes(name), name)


def read_source(path: PathLike) -> SourceText:
    """Read a text file, with a clear :class:`InputError` for missing or binary files.

    A leading UTF-8 byte order mark is dropped; ``\\n``, ``\\r\\n`` and ``\\r`` end lines.
    """
    name = os.fspath(path)
    text = _decode(read_bytes(name), name)
    ends = text == "" or text[-1] in "\n\r"
    lines = text.splitlines()
    return SourceText(path=name, lines=lines, ends_with_newline=ends)


HEAD_BYTES = 1 << 16
"""How much of a file :func:`read_head` reads."""


def read_head(path: PathLike) -> SourceText:
    """The complete lines among the first :data:`HEAD_BYTES` of a text file, to recognise
    its format without reading all of it (the whole file when it is that short).

    A file that cannot be read or decoded is read by :func:`read_source`, which says why.
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as handle:
            raw = handle.read(HEAD_BYTES + 1)
    except OSError:
        return read_source(path)
    if len(raw) <= HEAD_BYTES:
        return read_source(path)
    try:
        text = _decode(raw[: raw.rfind(b"\n") + 1], name)
    except InputError:
        return read_source(path)
    return SourceText(path=name, lines=text.splitlines(), ends_with_newline=True)


def parse_float(token: str, *, source: SourceText, line: int, what: str) -> float:
    """Parse one finite float or raise :class:`InputError` naming ``what``.

    Accepts what ``np.loadtxt`` accepts (no ``_`` digit separators, ASCII digits only).
    """
    try:
        if not token.isascii() or "_" in token:
            raise ValueError
        value = float(token)
    except ValueError:
        raise InputError(
            f"{what}: expected a number, got {quote_token(token)}", path=source.path, line=line
        ) from None
    if not math.isfinite(value):
        raise InputError(
            f"{what}: expected a finite number, got {quote_token(token)}",
            path=source.path,
            line=line,
        )
    return value


def quote_token(token: str, limit: int = 40) -> str:
    """``token`` quoted for a message (shortened when long; odd characters as ``<U+XXXX>``)."""
    short = token if len(token) <= limit else token[:limit] + "..."
    return "'" + "".join(c if c.isprintable() else f"<U+{ord(c):04X}>" for c in short) + "'"


def read_numeric_table(
    path: PathLike,
    *,
    columns: Sequence[str],
    min_rows: int = 1,
    comment: str = "#",
    describe: str | None = None,
    source: SourceText | None = None,
) -> tuple[NDArray[np.float64], RowLines]:
    """Read a whitespace-separated table of finite floats with a fixed number of columns.

    Parameters
    ----------
    path : str or PathLike
        The file.
    columns : sequence of str
        Column names; their count is the number of fields every data line must have.
    min_rows : int
        Fewer data rows raise :class:`InputError` (an empty file is an error by default).
    comment : str
        Lines starting with this (after leading blanks) are comments; on a data line it
        starts a trailing comment.
    describe : str, optional
        What the file is, for messages (e.g. ``"a Freiburg .relations file"``).
    source : SourceText, optional
        Already-read text of ``path``.

    Returns
    -------
    values : ndarray, shape (N, len(columns))
    line_numbers : RowLines
        ``line_numbers(k)`` is the 1-based file line of row ``k`` (computed on first use,
        for messages about a row).

    A cut-off last line (no final newline) is skipped with a :class:`TruncatedLineWarning`.
    """
    ncols = len(columns)
    if source is None:
        fast = _fast_table(path, ncols, comment)
        if fast is not None and fast[0].shape[0] >= min_rows:
            return fast
    src = read_source(path) if source is None else source
    layout = " ".join(columns)
    kind = f" ({describe})" if describe else ""
    lines = src.lines
    cut = src.cut_off_line(comment)
    body = lines[: cut - 1] if cut is not None else lines
    values: NDArray[np.float64] | None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # loadtxt warns on empty input
            values = np.loadtxt(body, comments=comment, ndmin=2, dtype=np.float64)
    except ValueError:
        values = None
    if values is not None and values.size and values.shape[1] != ncols:
        values = None
    if values is not None and not np.isfinite(values).all():
        values = None
    if values is None:
        # Slow path: find the first bad line and say what is wrong with it (or read the
        # table line by line where numpy refused a line that float() reads).
        values = _parse_lines(
            src, body_len=len(body), ncols=ncols, layout=layout, kind=kind, comment=comment
        )
    if cut is not None:
        src.warn_cut_off(cut)
    numbers = RowLines(body, comment, cut)
    if values.size == 0:
        values = np.empty((0, ncols))
    if values.shape[0] < min_rows:
        raise InputError(
            f"no data{kind}: expected at least {min_rows} line(s) of {ncols} numbers ({layout})",
            path=src.path,
        )
    return values, numbers


class RowLines:
    """Maps a data-row index to its 1-based line in the file, computed on first use.

    ``lines`` is the list of the file's lines, or a callable that produces it (so that a
    fast reader need not split the file unless a message needs a line number).
    ``cut_off_line`` is the cut-off last line the reader skipped, if any.
    """

    def __init__(
        self,
        lines: Sequence[str] | Callable[[], Sequence[str]],
        comment: str,
        cut_off_line: int | None = None,
    ) -> None:
        self._lines = lines
        self._comment = comment
        self._numbers: NDArray[np.int64] | None = None
        self.cut_off_line = cut_off_line
        """1-based number of the cut-off last line that was skipped (``None``: none)."""

    def __call__(self, row: int) -> int:
        if self._numbers is None:
            lines = self._lines() if callable(self._lines) else self._lines
            self._numbers = np.asarray(
                [
                    i
                    for i, raw in enumerate(lines, start=1)
                    if (s := raw.strip()) and s[0] != self._comment
                ],
                dtype=np.int64,
            )
        return int(self._numbers[row])


def _fast_table(
    path: PathLike, ncols: int, comment: str
) -> tuple[NDArray[np.float64], RowLines] | None:
    """The whole-file parser, or ``None`` to take the exact, diagnosing path.

    :func:`slamrel.formats.fastparse.read_decimal_table` (vectorised numpy, plain decimals
    only, bit for bit ``float()``; a byte order mark and ``\r\n`` line ends accepted; a
    cut-off last line not parsed, warned about here). Only a clean file takes this path:
    every data line with ``ncols`` finite plain decimals. Anything else (a bad token, NaN,
    exponents, a missing file) returns ``None``; ``np.loadtxt`` then reads it, or the
    line-by-line reader says what is wrong.
    """
    plain = read_decimal_table(path, ncols, comment=comment)
    if plain is None:
        return None
    values, text, cut = plain
    if cut is not None:
        warnings.warn(cut_off_message(os.fspath(path), cut), TruncatedLineWarning, stacklevel=4)
    text_lines = lambda: bytes(text).decode("ascii").splitlines()  # noqa: E731
    return values, RowLines(text_lines, comment, cut)


def _parse_lines(
    src: SourceText, *, body_len: int, ncols: int, layout: str, kind: str, comment: str
) -> NDArray[np.float64]:
    """The table line by line: the first bad line raises, else the values (N, ncols)."""
    rows: list[list[float]] = []
    names = layout.split()
    for number, text in src.data_lines(comment):
        if number > body_len:
            break
        fields = text.split(comment, 1)[0].split()
        if len(fields) != ncols:
            raise InputError(
                f"expected {ncols} fields ({layout}){kind}, got {len(fields)}",
                path=src.path,
                line=number,
            )
        rows.append(
            [
                parse_float(token, source=src, line=number, what=f"field '{name}'")
                for name, token in zip(names, fields)
            ]
        )
    return np.asarray(rows, dtype=np.float64).reshape(-1, ncols)


# ------------------------------------------------------------------ header CSV tables


class CsvTable(NamedTuple):
    """Columns of a header CSV file (see :func:`read_csv_table`).

    Attributes
    ----------
    columns : dict of str → ndarray, shape (N,)
        By the name the file gives (lower case), for the required and present optional
        columns; empty cells of ``empty_ok`` columns are NaN.
    lines : ndarray of int, shape (N,)
        The 1-based file line of each row.
    """

    columns: dict[str, NDArray[np.float64]]
    lines: NDArray[np.int64]


Column = str | tuple[str, ...]


def read_csv_table(
    path: PathLike,
    *,
    required: Sequence[Column],
    optional: Sequence[Column] = (),
    empty_ok: Sequence[str] = (),
    describe: str | None = None,
    source: SourceText | None = None,
    nonfinite_ok: Sequence[str] = (),
) -> CsvTable:
    """Read a comma-separated table of finite numbers with a header line.

    The first data line is the header; names are matched case-insensitively (and without
    surrounding blanks). Every row must have as many fields as the header; the wanted
    columns must hold finite numbers (an empty cell of an ``empty_ok`` column is NaN);
    the other columns are not read. ``#`` comment lines and blank lines are ignored; a
    byte order mark, ``\r\n`` line ends and a cut-off last line follow the module's rules.

    Parameters
    ----------
    path : str or PathLike
    required : sequence of str or tuple of str
        Column names (lower case) that must be present; a tuple gives alternatives (the
        first present one is read, under its own name).
    optional : sequence of str or tuple of str
        Columns read when present.
    empty_ok : sequence of str
        Columns whose cells may be empty (NaN).
    nonfinite_ok : sequence of str
        Columns whose cells may be empty, ``nan`` or ``inf`` (the caller counts them).
    describe : str, optional
        What the file is, for messages (e.g. ``"a landmark map"``).
    source : SourceText, optional
        Already-read text of ``path``.

    Returns
    -------
    CsvTable
        ``(columns, lines)``.

    Raises
    ------
    InputError
        An empty file, a column name given twice or a missing required column (at the
        header line), a row with another number of fields or a cell that is not a finite
        number (at its line).
    """
    src = read_source(path) if source is None else source
    name = src.path
    kind = f" ({describe})" if describe else ""
    expected = ",".join(_column_name(c) for c in required)
    data = list(src.data_lines())
    if not data:
        raise InputError(f"empty file{kind}: expected a header {expected}", path=name)
    head_line, head_text = data[0]
    header = csv_header(head_text, path=name, line=head_line, kind=kind)
    missing = [c for c in required if _find(header, c) is None]
    if missing:
        raise InputError(
            f"missing column(s) {', '.join(_column_name(c) for c in missing)}{kind}; "
            f"expected a header {expected}",
            path=name,
            line=head_line,
        )
    wanted = [h for c in (*required, *optional) if (h := _find(header, c)) is not None]
    wanted = list(dict.fromkeys(wanted))
    cols = [header.index(c) for c in wanted]
    rows = data[1:]
    numbers = np.array([n for n, _ in rows], dtype=np.int64)
    body = [t for _, t in rows]
    maybe_empty = [c for c in wanted if c in empty_ok or c in nonfinite_ok]
    loose = [c for c in wanted if c in nonfinite_ok]
    values: NDArray[np.float64] | None = None
    if body:
        conv: dict[int | str, Callable[[str], float]] = {
            header.index(c): _float_or_nan for c in maybe_empty
        }
        conv.update({header.index(c): _float_any for c in loose})
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                values = np.loadtxt(
                    body,
                    delimiter=",",
                    usecols=cols,
                    ndmin=2,
                    dtype=np.float64,
                    converters=conv or None,
                    comments=None,
                    quotechar=None,
                )
        except (ValueError, TypeError):
            values = None
        if values is not None:
            fields_ok = values.shape == (len(body), len(wanted)) and all(
                t.count(",") == len(header) - 1 for t in body
            )
            strict = [i for i, c in enumerate(wanted) if c not in maybe_empty]
            if not (fields_ok and np.isfinite(values[:, strict]).all()):
                values = None
        if values is None:
            values = _parse_csv_lines(src, rows, header, wanted, maybe_empty, kind, loose)
    else:
        values = np.empty((0, len(wanted)))
    return CsvTable({c: values[:, i] for i, c in enumerate(wanted)}, numbers)


def csv_header(text: str, *, path: str, line: int, kind: str = "") -> list[str]:
    """The column names of a CSV header line: lower case, stripped of surrounding blanks.

    A name given twice is refused (:class:`InputError` at ``line`` naming it): a reader
    looks a column up by its name, so the second column of that name would be ignored
    without a word. Empty names (cells of no column a reader asks for) may repeat.
    """
    header = [h.strip().lower() for h in text.split(",")]
    seen: dict[str, int] = {}
    for k, h in enumerate(header):
        if h and h in seen:
            raise InputError(
                f"the header{kind} names column {h!r} twice (columns {seen[h] + 1} and "
                f"{k + 1}); expected each column name once (names are matched case-"
                "insensitively)",
                path=path,
                line=line,
            )
        seen.setdefault(h, k)
    return header


def read_csv_text_column(source: SourceText, name: str) -> NDArray[np.str_] | None:
    """The cells of a text column ``name`` of a header CSV, row by row (``None`` if absent).

    For a file that :func:`read_csv_table` has read (pass it the same ``source``): the rows
    are the same (data lines after the header) and their field counts already checked.
    Cells are stripped of surrounding blanks, as the header names are.
    """
    data = source.data_lines()
    first = next(data, None)
    if first is None:
        return None
    header = csv_header(first[1], path=source.path, line=first[0])
    if name not in header:
        return None
    k = header.index(name)
    return np.array([text.split(",")[k].strip() for _, text in data], dtype=np.str_)


_INT64_MAX = str(np.iinfo(np.int64).max)


def read_csv_id_column(
    source: SourceText,
    name: str,
    lines: NDArray[np.int64],
    *,
    empty_ok: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The integer ids of column ``name``, exactly as written: int64 from the text, never via
    float64 (``2**53 + 1`` stays itself; GTSAM symbol keys near 8e18 are read).

    For a file that :func:`read_csv_table` has read (the same ``source`` and its ``lines``).
    A cell is an optional sign and ASCII digits, optionally followed by ``.`` and zeros
    (``3.0``); anything else (``2.5``, ``1e3``, a value beyond int64) raises
    :class:`InputError` at its line. Returns the ids (0 where empty) and the mask of
    non-empty cells; empty cells raise unless ``empty_ok``.
    """
    cells = read_csv_text_column(source, name)
    if cells is None:
        raise InputError(f"missing column {name!r}", path=source.path)
    if cells.size == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=bool)
    empty = cells == ""
    ids = exact_integer_tokens(
        cells, lines, source.path, name, empty_ok=empty_ok, hint="an optional sign and digits"
    )
    return ids, ~empty


def exact_integer_tokens(
    cells: NDArray[np.str_],
    lines: NDArray[np.int64],
    path: str,
    column: str,
    *,
    empty_ok: bool = False,
    hint: str = "an optional sign and digits",
) -> NDArray[np.int64]:
    """Text cells as exact int64 ids, never via float64 (``2**53 + 1`` stays itself).

    A cell is an optional sign and ASCII digits, optionally followed by ``.`` and zeros
    (``3.0``); anything else (``2.5``, ``1e3``, a value beyond int64) raises
    :class:`InputError` at its line (``lines[k]`` for cell ``k``). Empty cells become 0
    (they raise unless ``empty_ok``).
    """
    if cells.size == 0:
        return np.empty(0, dtype=np.int64)
    empty = cells == ""
    part = np.strings.partition(cells, ".")
    head, dot, frac = part[0], part[1], part[2]
    digits = np.strings.lstrip(head, "+-")
    n_digits = np.strings.str_len(digits)
    ok = (
        np.strings.isdigit(digits)
        & (np.strings.str_len(head) - n_digits <= 1)
        & (np.strings.str_len(np.strings.encode(cells, "utf-8")) == np.strings.str_len(cells))
        & ((dot == "") | (np.strings.strip(frac, "0") == ""))
    )
    long = n_digits >= len(_INT64_MAX)
    if long.any():  # the few cells that may not fit in int64: compare as text
        stripped = np.strings.lstrip(digits, "0")
        width = np.strings.str_len(stripped)
        fits = (width < len(_INT64_MAX)) | ((width == len(_INT64_MAX)) & (stripped <= _INT64_MAX))
        ok &= ~long | fits
    bad = np.flatnonzero(~ok & ~(empty & empty_ok))
    if bad.size:
        k = int(bad[0])
        text = str(cells[k])
        plain = text.isascii() and text.isprintable()
        got = (text if plain else quote_token(text)) if text else "an empty cell"
        raise InputError(
            f"column '{column}': expected an integer id, got {got} (ids are read exactly as "
            f"written: {hint})",
            path=path,
            line=int(lines[k]),
        )
    ids = np.zeros(cells.shape[0], dtype=np.int64)
    if (~empty).any():
        ids[~empty] = head[~empty].astype(np.int64)
    return ids


def record_id_tokens(
    source: SourceText, lines: NDArray[np.int64], field: int, column: str
) -> NDArray[np.int64]:
    """Whitespace-separated field ``field`` (0-based, the keyword being field 0) of each of
    ``lines`` of a keyword-record file, as exact int64 ids (:func:`exact_integer_tokens`).

    For ids that a float64 column cannot hold (``|id| ≥ 2**53``: GTSAM symbol keys); the
    fields are split in Python, so readers call it only when such an id is present.
    """
    if lines.size == 0:
        return np.empty(0, dtype=np.int64)
    text = source.lines
    cells = np.array([text[n - 1].split()[field] for n in lines.tolist()], dtype=np.str_)
    return exact_integer_tokens(cells, lines, source.path, column, hint="an integer")


# From 2**53 on a double no longer holds every integer: such ids are re-read from the text.
_EXACT_FLOAT_IDS = 2.0**53


def exact_record_ids(
    values: NDArray[np.float64],
    lines: NDArray[np.int64],
    source: SourceText,
    field: int,
    column: str,
) -> NDArray[np.int64]:
    """An id column of keyword records (field ``field``, the keyword being field 0) as exact
    int64: through the parsed floats where they hold every integer (``|id| < 2**53``),
    re-read from the text where they do not.

    The one id rule of the keyword-record graph readers (g2o, TORO): a value that is not an
    integer (``3.5``) or does not fit in int64 raises :class:`InputError` at its line, so no
    id is ever rounded or truncated onto another.
    """
    big = np.abs(values) >= _EXACT_FLOAT_IDS
    if not big.any():
        return integer_ids(values, lines, source.path, column)
    out = np.empty(values.shape[0], dtype=np.int64)
    out[~big] = integer_ids(values[~big], lines[~big], source.path, column)
    out[big] = record_id_tokens(source, lines[big], field, column)
    return out


def _column_name(c: Column) -> str:
    return c if isinstance(c, str) else "|".join(c)


def _find(header: list[str], c: Column) -> str | None:
    for alt in (c,) if isinstance(c, str) else c:
        if alt in header:
            return alt
    return None


def _float_or_nan(cell: str) -> float:
    """An ``empty_ok`` cell for ``np.loadtxt``: NaN when empty, else as :func:`parse_float`."""
    value = _float_any(cell)
    if not math.isfinite(value) and cell.strip():
        raise ValueError(cell)  # the exact path says which line
    return value


def _float_any(cell: str) -> float:
    """A ``nonfinite_ok`` cell for ``np.loadtxt``: NaN when empty, ``nan``/``inf`` allowed."""
    cell = cell.strip()
    if not cell:
        return math.nan
    if not cell.isascii() or "_" in cell:
        raise ValueError(cell)
    return float(cell)


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _parse_csv_lines(
    src: SourceText,
    rows: list[tuple[int, str]],
    header: list[str],
    wanted: list[str],
    maybe_empty: list[str],
    kind: str,
    loose: Sequence[str] = (),
) -> NDArray[np.float64]:
    """The table line by line: the first bad line raises, else the values (N, len(wanted))."""
    out: list[list[float]] = []
    where = [header.index(c) for c in wanted]
    for number, text in rows:
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != len(header):
            raise InputError(
                f"expected {len(header)} comma-separated fields ({','.join(header)}){kind}, "
                f"got {len(fields)}",
                path=src.path,
                line=number,
            )
        row = []
        for c, i in zip(wanted, where):
            tok = fields[i]
            if c in maybe_empty and tok == "":
                row.append(float("nan"))
            elif c in loose and tok.isascii() and "_" not in tok and _is_float(tok):
                row.append(float(tok))
            else:
                row.append(parse_float(tok, source=src, line=number, what=f"column '{c}'"))
        out.append(row)
    return np.asarray(out, dtype=np.float64).reshape(-1, len(wanted))


def format_csv_table(
    header: Sequence[str],
    columns: Sequence[ArrayLike],
    fmt: str | Sequence[str] = NUMBER_FORMAT,
) -> str:
    """A header CSV table as text; NaN cells are left empty.

    Parameters
    ----------
    header : sequence of str
        Column names.
    columns : sequence of array_like, each shape (N,)
    fmt : str or sequence of str
        ``%`` formats, one for all or one per column. :data:`NUMBER_FORMAT` (the default)
        writes every double so that :func:`read_csv_table` reads it back bit for bit; ``%d``
        for ids.
    """
    fmts = [fmt] * len(header) if isinstance(fmt, str) else list(fmt)
    if len(fmts) != len(header) or len(columns) != len(header):
        raise ValueError("one column and one format per header name expected")
    head = ",".join(header) + "\n"
    cols = [np.asarray(c) for c in columns]
    n = cols[0].shape[0] if cols else 0
    if n == 0:
        return head
    flat = np.empty((n, len(cols)), dtype=object)
    for k, (c, f) in enumerate(zip(cols, fmts)):
        flat[:, k] = c.astype(np.int64 if f == "%d" else np.float64).tolist()
    body = ((",".join(fmts) + "\n") * n) % tuple(flat.ravel().tolist())
    if "nan" in body:
        body = _NAN_CELL.sub("", body)
    return head + body


_NAN_CELL = re.compile(r"(?<![^,\n])nan(?=[,\n])")


def write_csv_table(
    path: PathLike,
    header: Sequence[str],
    columns: Sequence[ArrayLike],
    fmt: str | Sequence[str] = NUMBER_FORMAT,
) -> None:
    """Write :func:`format_csv_table` to ``path`` atomically."""
    write_text_atomic(path, format_csv_table(header, columns, fmt))


Records = dict[str, tuple[NDArray[np.float64], NDArray[np.int64]]]


def _keyword_records_fast(
    src: SourceText, fields: Mapping[str, int], *, skipped: Counter[str] | None = None
) -> Records | None:
    """:func:`read_keyword_records` for a well-formed file, one ``float`` per token without
    per-token checks (several times faster: benchmarks/README.md); ``None`` at the first
    thing :func:`parse_float` or the record checks would reject, so the caller can report
    it. With ``skipped`` (a counter), records of other kinds are counted there instead of
    being rejected."""
    tokens: dict[str, list[str]] = {k: [] for k in fields}
    lines: dict[str, list[int]] = {k: [] for k in fields}
    others: Counter[str] = Counter()
    for number, text in src.data_lines():
        f = text.split()
        kind = f[0]
        n = fields.get(kind)
        if n is None and skipped is not None:
            others[kind] += 1
            continue
        if n != len(f):
            return None
        tokens[kind] += f[1:]
        lines[kind].append(number)
    out = {}
    for kind, n in fields.items():
        joined = "".join(tokens[kind])
        if not joined.isascii() or "_" in joined:
            return None
        try:
            values = np.array(list(map(float, tokens[kind])), dtype=np.float64)
        except ValueError:
            return None
        if not np.isfinite(values).all():
            return None
        out[kind] = (values.reshape(-1, n - 1), np.asarray(lines[kind], dtype=np.int64))
    if skipped is not None:
        skipped.update(others)
    return out


def read_keyword_records(
    path: PathLike,
    fields: Mapping[str, int],
    *,
    names: Mapping[str, Sequence[str]] | None = None,
    skipped: Counter[str] | None = None,
    source: SourceText | None = None,
) -> Records:
    """Read a file of keyword records (``KIND v1 v2 …``, e.g. g2o or iSAM text).

    Parameters
    ----------
    path : str or PathLike
    fields : mapping of record name → number of fields (the keyword included)
        Every record must be one of these (unless ``skipped`` is given), with exactly that
        many numeric fields.
    names : mapping of record name → field names (the keyword not included), optional
        For messages: ``VERTEX_SE2 x: expected a number`` and ``VERTEX_SE2: expected 5
        fields (VERTEX_SE2 id x y theta)`` instead of ``VERTEX_SE2 field 3``.
    skipped : Counter, optional
        Records of other kinds are skipped and counted here by name (not checked); without
        it they are an error.
    source : SourceText, optional
        Already-read text of ``path``.

    Returns
    -------
    dict of record name → (values (K, n − 1), line numbers (K,))
        One entry per name in ``fields`` (empty arrays when absent).
    """
    src = read_source(path) if source is None else source
    fast = _keyword_records_fast(src, fields, skipped=skipped)
    if fast is not None:
        return fast
    # something is wrong: parse token by token to name the first bad record (in file order)
    rows: dict[str, list[list[float]]] = {k: [] for k in fields}
    lines: dict[str, list[int]] = {k: [] for k in fields}
    others: Counter[str] = Counter()
    for number, text in src.data_lines():
        f = text.split()
        kind = f[0]
        if kind not in fields:
            if skipped is not None:
                others[kind] += 1
                continue
            raise InputError(
                f"unknown record {quote_token(kind)}; expected one of {', '.join(fields)}",
                path=src.path,
                line=number,
            )
        what = list(names[kind]) if names and kind in names else None
        if len(f) != fields[kind]:
            layout = f" ({kind} {' '.join(what)})" if what else ""
            raise InputError(
                f"{kind}: expected {fields[kind]} fields{layout}, got {len(f)}",
                path=src.path,
                line=number,
            )
        rows[kind].append(
            [
                parse_float(
                    t,
                    source=src,
                    line=number,
                    what=f"{kind} {what[k]}" if what else f"{kind} field {k + 2}",
                )
                for k, t in enumerate(f[1:])
            ]
        )
        lines[kind].append(number)
    if skipped is not None:
        skipped.update(others)
    return {
        k: (
            np.asarray(rows[k], dtype=np.float64).reshape(-1, n - 1),
            np.asarray(lines[k], dtype=np.int64),
        )
        for k, n in fields.items()
    }


# ------------------------------------------------------------------ JSON documents


class _RepeatedKey(Exception):
    """Raised inside :func:`json.loads` by :func:`_unique_pairs` (caught by :func:`loads_json`)."""


def _unique_pairs(pairs: list[tuple[str, object]]) -> dict[str, object]:
    out = dict(pairs)
    if len(out) != len(pairs):
        raise _RepeatedKey
    return out


# a JSON string, or one of the structural characters that matter for finding keys
_JSON_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|[{}\[\]]')


def _repeated_key(text: str) -> tuple[str, int, int]:
    """The first key (in document order) given twice in one object of valid JSON ``text``:
    ``(key, its first line, its second line)``."""
    stack: list[dict[str, int] | None] = []
    for m in _JSON_TOKEN.finditer(text):
        token = m.group()
        if token == "{":
            stack.append({})
        elif token == "[":
            stack.append(None)
        elif token in "}]":
            stack.pop()
        else:
            keys = stack[-1] if stack else None
            rest = text[m.end() :].lstrip()
            if keys is None or not rest.startswith(":"):
                continue  # a value, not a key
            key = json.loads(token)
            line = text.count("\n", 0, m.start()) + 1
            if key in keys:
                return key, keys[key], line
            keys[key] = line
    raise AssertionError("no repeated key found in a document json refused for one")


def loads_json(text: str, *, path: str) -> object:
    """``json.loads(text)``, refusing a key given twice in one object.

    :func:`json.loads` keeps the last value of a repeated key without a word, so an edited
    file could silently lose the value its reader meant; every JSON document slamrel reads
    as input goes through here. Raises :class:`InputError` naming ``path``, the key and the
    line of its second occurrence; :class:`json.JSONDecodeError` and :class:`RecursionError`
    pass through for the caller to word.
    """
    try:
        return json.loads(text, object_pairs_hook=_unique_pairs)
    except _RepeatedKey:
        key, first, line = _repeated_key(text)
        raise InputError(
            f"key {key!r} is given twice in one object (first on line {first}); expected "
            "each key once (JSON keeps only the last value, silently)",
            path=path,
            line=line,
        ) from None
