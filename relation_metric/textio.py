"""Strict reading of whitespace-separated text tables, and atomic writing.

Readers in slamrel share three rules:

* a bad line raises :class:`~relation_metric.errors.InputError` with the file, the 1-based
  line number and what was expected;
* the only tolerated defect is a **final line cut off mid-record with no newline** (a log
  whose writer was stopped): it is skipped with a :class:`TruncatedLineWarning`;
* ``#`` starts a comment line; blank lines are ignored.

Numeric tables take a fast path (numpy's C parser over the whole file); only when it fails,
or finds a non-finite value, the file is re-read line by line to say exactly where and why.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.fastparse import read_decimal_table
from relation_metric.outputs import (
    atomic_write,
    check_output_file,
    write_bytes_atomic,
    write_text_atomic,
)

__all__ = [
    "TruncatedLineWarning",
    "SourceText",
    "read_source",
    "read_numeric_table",
    "atomic_write",
    "check_not_input",
    "RowLines",
    "parse_float",
    "write_text_atomic",
    "write_bytes_atomic",
]

PathLike = str | os.PathLike[str]


class TruncatedLineWarning(UserWarning):
    """A final line without newline that does not parse was skipped."""


@dataclass(frozen=True)
class SourceText:
    """The lines of a text file, ready for parsing.

    Attributes
    ----------
    path : str
        The file name used in messages.
    lines : list of str
        All lines without their line ends (the possibly truncated last one included).
    ends_with_newline : bool
        False when the last line has no newline (it may be cut off).
    """

    path: str
    lines: list[str]
    ends_with_newline: bool

    def data_lines(self, comment: str = "#") -> Iterator[tuple[int, str]]:
        """Yield ``(line_number, stripped_text)`` for the non-blank, non-comment lines."""
        for number, raw in enumerate(self.lines, start=1):
            text = raw.strip()
            if text and not text.startswith(comment):
                yield number, text

    def is_last_line(self, number: int) -> bool:
        """True when ``number`` is the final line and it has no newline (may be cut off)."""
        return (not self.ends_with_newline) and number == len(self.lines)

    def warn_truncated(self, number: int, expected: str) -> None:
        """Issue the warning for a skipped, cut-off final line."""
        warnings.warn(
            f"{self.path}:{number}: the last line is cut off (no newline, {expected}); skipped",
            TruncatedLineWarning,
            stacklevel=3,
        )


def read_source(path: PathLike) -> SourceText:
    """Read a text file, with a clear :class:`InputError` for missing or binary files."""
    name = os.fspath(path)
    try:
        raw = Path(name).read_bytes()
    except FileNotFoundError:
        raise InputError("no such file", path=name) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a text file", path=name) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=name) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise InputError("not UTF-8 text", path=name, line=line) from None
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise InputError("contains a NUL byte; expected a text file", path=name, line=line)
    ends = text.endswith("\n") or text == ""
    lines = text.splitlines()
    return SourceText(path=name, lines=lines, ends_with_newline=ends)


def parse_float(token: str, *, source: SourceText, line: int, what: str) -> float:
    """Parse one finite float or raise :class:`InputError` naming ``what``."""
    try:
        value = float(token)
    except ValueError:
        raise InputError(
            f"{what}: expected a number, got {token!r}", path=source.path, line=line
        ) from None
    if not math.isfinite(value):
        raise InputError(
            f"{what}: expected a finite number, got {token!r}", path=source.path, line=line
        )
    return value


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
        Lines starting with this (after leading blanks) are comments.
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
    skip_last = False
    if not src.ends_with_newline and lines:
        last_fields = lines[-1].split()
        if last_fields and not lines[-1].lstrip().startswith(comment):
            if len(last_fields) != ncols or not _all_floats(last_fields):
                src.warn_truncated(len(lines), f"expected {ncols} fields: {layout}")
                skip_last = True
    body = lines[:-1] if skip_last else lines
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
        # Slow path: find the first bad line and say what is wrong with it.
        _diagnose(src, body_len=len(body), ncols=ncols, layout=layout, kind=kind, comment=comment)
        raise AssertionError("unreachable: the fast path failed but no line is bad")
    numbers = RowLines(body, comment)
    if values.size == 0:
        values = np.empty((0, ncols))
    if values.shape[0] < min_rows:
        raise InputError(
            f"no data{kind}: expected at least {min_rows} line(s) of {ncols} numbers ({layout})",
            path=src.path,
        )
    return values, numbers


def _all_floats(fields: Sequence[str]) -> bool:
    try:
        return all(math.isfinite(float(f)) for f in fields)
    except ValueError:
        return False


class RowLines:
    """Maps a data-row index to its 1-based line in the file, computed on first use.

    ``lines`` is the list of the file's lines, or a callable that produces it (so that a
    fast reader need not split the file unless a message needs a line number).
    """

    def __init__(self, lines: Sequence[str] | Callable[[], Sequence[str]], comment: str) -> None:
        self._lines = lines
        self._comment = comment
        self._numbers: NDArray[np.int64] | None = None

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

    :func:`relation_metric.fastparse.read_decimal_table` (vectorised numpy, plain decimals
    only, bit for bit ``float()``). Only a clean file takes this path: every data line with
    ``ncols`` finite plain decimals. Anything else (a cut-off last line, a bad token, NaN,
    exponents, a missing file) returns ``None``; ``np.loadtxt`` then reads it, or the
    line-by-line reader says what is wrong.
    """
    plain = read_decimal_table(path, ncols, comment=comment)
    if plain is None:
        return None
    values, text = plain
    text_lines = lambda: bytes(text).decode("ascii").splitlines()  # noqa: E731
    return values, RowLines(text_lines, comment)


def _diagnose(
    src: SourceText, *, body_len: int, ncols: int, layout: str, kind: str, comment: str
) -> None:
    for number, text in src.data_lines(comment):
        if number > body_len:
            break
        fields = text.split()
        if len(fields) != ncols:
            raise InputError(
                f"expected {ncols} fields ({layout}){kind}, got {len(fields)}",
                path=src.path,
                line=number,
            )
        for name, token in zip(layout.split(), fields):
            parse_float(token, source=src, line=number, what=f"field '{name}'")


def check_not_input(output: PathLike, inputs: Sequence[PathLike | None]) -> None:
    """Refuse to write ``output`` over one of the ``inputs`` (see
    :func:`relation_metric.outputs.check_output_file`, which this calls)."""
    check_output_file(output, inputs=inputs)


def read_keyword_records(
    path: PathLike, fields: dict[str, int]
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.int64]]]:
    """Read a file of keyword records (``KIND v1 v2 …``, e.g. g2o or iSAM text).

    Parameters
    ----------
    path : str or PathLike
    fields : dict of record name → number of fields (the keyword included)
        Every record must be one of these, with exactly that many numeric fields.

    Returns
    -------
    dict of record name → (values (K, n − 1), line numbers (K,))
        One entry per name in ``fields`` (empty arrays when absent).
    """
    src = read_source(path)
    rows: dict[str, list[list[float]]] = {k: [] for k in fields}
    lines: dict[str, list[int]] = {k: [] for k in fields}
    for number, text in src.data_lines():
        f = text.split()
        kind = f[0]
        if kind not in fields:
            raise InputError(
                f"unknown record {kind!r}; expected one of {', '.join(fields)}",
                path=src.path,
                line=number,
            )
        if len(f) != fields[kind]:
            if src.is_last_line(number):
                src.warn_truncated(number, f"{kind} needs {fields[kind]} fields")
                break
            raise InputError(
                f"{kind}: expected {fields[kind]} fields, got {len(f)}", path=src.path, line=number
            )
        rows[kind].append(
            [
                parse_float(t, source=src, line=number, what=f"{kind} field {k + 2}")
                for k, t in enumerate(f[1:])
            ]
        )
        lines[kind].append(number)
    return {
        k: (
            np.asarray(rows[k], dtype=np.float64).reshape(-1, n - 1),
            np.asarray(lines[k], dtype=np.int64),
        )
        for k, n in fields.items()
    }
