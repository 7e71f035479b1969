"""Vectorised, exact parsing of whitespace-separated decimal tables from raw bytes.

:func:`parse_decimal_table` reads a table such as a Freiburg ``.relations`` file
(``t1 t2 x y z roll pitch yaw`` per line) with a handful of whole-array numpy operations
instead of a per-line parser. It accepts only a strict subset of what ``np.loadtxt`` accepts
and returns ``None`` for anything else, so that the caller can fall back to the exact,
diagnosing reader (:func:`slamrel.formats.text.read_numeric_table`).

Accepted
    Tokens ``-?D*(.D*)?`` with at least one digit (``12``, ``-0.5``, ``.5``, ``5.``) are read
    vectorised when they have at most 24 integer and 22 fraction digits and an integer
    mantissa (the digits without the point) below 9·10**18 — every ``%.17g`` (``repr``) and
    ``%.18g`` output without exponent. Other number tokens, :data:`ODD_TOKEN`
    (``[-+]?(D+.?D*|.D+)([eE][-+]?D+)?``: exponents, a ``+`` sign, more digits), are
    handed to ``float()`` one by one, as long as they are few (see :data:`ODD_SHARE`);
    fields separated by runs of blanks and tabs; lines ended by ``\\n`` or ``\\r\\n``; blank
    lines; comments from the comment character to the end of its line (whole comment
    lines, and trailing comments as ``np.loadtxt`` strips them); a missing final newline
    when the last line is a complete row.

Refused (``None``)
    ``nan``/``inf`` and values that overflow to infinity, hexadecimal, any other character
    outside a comment, non-ASCII bytes, NUL bytes, a lone ``\\r``, rows with another number
    of fields, an empty table, a final line without newline that holds a comment, and a
    table whose odd tokens are too many (numpy's parser is then faster).

Exactness
    A token with mantissa ``m < 2**53`` and ``f ≤ 22`` fraction digits is the real number
    ``m / 10**f``. Both ``m`` and ``10**f`` are exact doubles, and IEEE-754 division is
    correctly rounded, so ``float(m) / 10.0**f`` is the double nearest to the decimal — bit
    for bit what ``float(token)`` (``strtod``) returns (Clinger's fast path). For
    ``2**53 ≤ m < 2**63`` the same quotient is within 1.5 units in the last place; its
    remainder ``m − q·10**f``, computed in double-double arithmetic (Dekker's exact product),
    decides between it and its two neighbours, and the rare token that lies within
    ``2**-21`` units of a midpoint (a tie such as ``9007199254740993``) or next to a power
    of two goes to ``float()`` (:func:`_round_big`). The sign is applied afterwards
    (``-0.0`` included). An odd token's value is ``float(token)`` itself.

Method
    The bytes are scanned once for separators (``b <= 32``), points and control characters;
    token starts and ends come from the separator mask's edges. Each token's integer and
    fraction digits are read right-aligned as little-endian 64-bit words (an unaligned strided
    view of the buffer), the bytes before the digits are replaced by ``'0'``, and eight ASCII
    digits are combined into their value with three multiply-shift steps (the SWAR method;
    the multiplications wrap modulo 2**64 by design). Digits are validated per word (a word
    that is not all digits marks its token odd). A second word (and a third) is read only
    for the tokens with more than eight (sixteen) integer or fraction digits; tokens of at
    most eight characters are read as one word, the point squeezed out by a shift.
    The file is processed in blocks of whole lines (2 MiB) so that the intermediate arrays
    stay in the CPU cache, and column by column inside a block (a column usually has one
    layout, so its tokens need not be split into short and long ones).

Speed
    A 10^6-line, 91 MB ``.relations`` file is read faster than by ``np.loadtxt`` and about
    as fast as by pandas' C reader (timings in benchmarks/README.md). The table is allocated
    column by column (an F-ordered ``(N, ncols)`` array): each column is written and later
    read contiguously. The blocks of a file are parsed by up to :data:`MAX_WORKERS`
    threads of one pool per process (numpy releases the GIL inside its loops); each block
    writes its rows from the first row its lines could start at, and the gaps left by
    blank and comment lines are closed afterwards. This module needs numpy only, and its
    exactness follows from the argument above. See ``benchmarks/bench_relation_metric.py``.
"""

from __future__ import annotations

import math
import os
import re
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["parse_decimal_table", "read_decimal_table", "DecimalFile", "MAX_FRACTION", "UTF8_BOM"]

UTF8_BOM = b"\xef\xbb\xbf"
"""The UTF-8 byte order mark, ignored at the start of a file."""

MAX_FRACTION = 22
"""Most fraction digits a token may have on the vectorised path (``10**22`` is the largest
exact power of ten in float64); a longer one goes to ``float()``."""

MAX_WORKERS = 4
"""Most threads that parse the blocks of one file at once."""

MIN_ODD_ALLOWANCE = 256
ODD_SHARE = 16
"""A file with more odd tokens than ``max(MIN_ODD_ALLOWANCE, tokens // ODD_SHARE)`` is
refused (``None``): one by one they cost more than numpy's parser."""

_PRINTABLE = b"\t\r" + bytes(range(32, 128))
_PAD = 16  # blanks before the data so that 16-byte look-behinds stay inside the buffer
_BLOCK = 1 << 21  # bytes per block of whole lines: a block's arrays stay in the CPU cache

_U64 = np.uint64
_ZEROS = _U64(0x3030303030303030)  # eight ASCII '0'
_PLUS118 = _U64(0x7676767676767676)
_TOP_BITS = _U64(0x8080808080808080)
_MASK16 = _U64(0x00FF00FF00FF00FF)
_MASK32 = _U64(0x0000FFFF0000FFFF)
_MUL1 = _U64(10 * (1 << 8) + 1)
_MUL2 = _U64(100 * (1 << 16) + 1)
_MUL3 = _U64(10000 * (1 << 32) + 1)
_S8, _S16, _S32, _S64 = _U64(8), _U64(16), _U64(32), _U64(64)
_ALL = _U64(0xFFFFFFFFFFFFFFFF)
_E8 = _U64(10**8)
_E16 = _U64(10**16)
_TWO53 = _U64(1 << 53)
_MAX_PART = 24  # digits of an integer or fraction part read as three 8-byte words
_MAX_MANTISSA = 9e18  # below 2**63 ≈ 9.22e18 with room for the estimate's 1e-15 error
_MARGIN = 2.0**-21  # guard band around a rounding midpoint, in units (see _round_big)
_FRACTION_FIELD = _U64((1 << 52) - 1)
_SPLITTER = float(2**27 + 1)  # Veltkamp's constant for float64
_POW10_INT = np.array([10**k for k in range(20)], dtype=np.uint64)  # 10**19 < 2**64
_POW10_FLOAT = np.array([float(10**k) for k in range(MAX_FRACTION + 1)])  # exact to 10**22
_POW10_FLOAT_WIDE = np.array([float(10**k) for k in range(_MAX_PART + 1)])  # estimates only
_POW10_HI = _POW10_FLOAT * _SPLITTER - (_POW10_FLOAT * _SPLITTER - _POW10_FLOAT)
_POW10_LO = _POW10_FLOAT - _POW10_HI
ODD_TOKEN = re.compile(rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
"""Tokens the fast path hands to ``float()`` one by one (exponents, a ``+`` sign, many
digits): what the exact path reads with the same value; anything else refuses the file."""


def parse_decimal_table(
    raw: bytes, ncols: int, *, comment: str = "#"
) -> NDArray[np.float64] | None:
    """Parse a whitespace-separated table of plain decimals, or return ``None``.

    Parameters
    ----------
    raw : bytes
        The whole file.
    ncols : int
        Number of fields every data line must have.
    comment : str
        One ASCII character that starts a comment running to the end of its line.

    Returns
    -------
    ndarray, shape (N, ncols), or None
        The values, each equal to ``float(token)`` bit for bit; ``None`` when the text is
        outside the accepted subset (see the module docstring) or holds no row — the caller
        then takes the exact path, which accepts or diagnoses it.
    """
    buf = bytearray(_PAD + len(raw) + 1)
    buf[_PAD : _PAD + len(raw)] = raw
    return _parse_padded(buf, len(raw), ncols, comment)


class DecimalFile(NamedTuple):
    """What :func:`read_decimal_table` read.

    Attributes
    ----------
    values : ndarray, shape (N, ncols)
        The rows of the complete lines.
    text : memoryview
        The file's bytes (a leading byte order mark replaced by blanks), for line numbers.
    cut_off_line : int or None
        1-based number of the last line when it has no final newline and holds data: it
        was not parsed (the caller warns that it is cut off); ``None`` otherwise.
    """

    values: NDArray[np.float64]
    text: memoryview
    cut_off_line: int | None


def read_decimal_table(
    path: str | os.PathLike[str], ncols: int, *, comment: str = "#"
) -> DecimalFile | None:
    """:func:`parse_decimal_table` on a file, read straight into the parser's buffer.

    The file rules of :mod:`slamrel.formats.text` apply at the byte level: a leading
    UTF-8 byte order mark is ignored, and a last line without final newline is not parsed
    (it is cut off; a blank or comment one is just ignored) — see ``cut_off_line``.

    ``None`` when the file cannot be read (the exact path then says why) or is outside the
    accepted subset.
    """
    _prime_allocator()
    try:
        with open(path, "rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            buf = bytearray(_PAD + size + 1)
            view = memoryview(buf)
            if handle.readinto(view[_PAD : _PAD + size]) != size or handle.read(1):
                return None  # the file changed while being read
    except OSError:
        return None
    end = _PAD + size
    if buf.startswith(UTF8_BOM, _PAD, end):
        buf[_PAD : _PAD + len(UTF8_BOM)] = b"   "
    cut_off = None
    tail = b""
    start = end
    if size and buf[end - 1] != 10:
        start = max(buf.rfind(b"\n", _PAD, end) + 1, _PAD)
        tail = bytes(buf[start:end])
        if not tail.isascii() or tail.translate(None, _PRINTABLE):
            return None  # non-ASCII or control characters: the exact path checks them
        text = tail.strip()
        if text and not text.startswith(comment.encode("ascii", "replace")):
            cut_off = buf.count(b"\n", _PAD, end) + 1
        buf[start:end] = b" " * len(tail)  # not parsed: cut off, blank or a comment
    try:
        values = _parse_padded(buf, size, ncols, comment)
    finally:
        buf[start:end] = tail
    if values is None:
        return None
    return DecimalFile(values, view[_PAD:end], cut_off)


_primed = False


def _prime_allocator() -> None:
    """Free one untouched 8 MiB array, once per process, before the first parse.

    glibc serves blocks above its mmap threshold (128 KiB at start) with fresh mappings and
    trims the heap above twice that; it raises both to the size of the largest mapped block
    freed so far (up to 32 MiB). The parser's per-block temporaries (1–3 MiB) would
    otherwise be mapped, faulted in and unmapped again block after block on the first call
    in a process: page faults by the hundred thousand for a 91 MB file, most of the first
    call's system time (measured in benchmarks/README.md). The array's pages are never
    touched; elsewhere than glibc this costs nothing.
    """
    global _primed
    if not _primed:
        _primed = True
        scratch = np.empty(8 << 20, dtype=np.uint8)
        del scratch


def _parse_padded(
    buf: bytearray, size: int, ncols: int, comment: str
) -> NDArray[np.float64] | None:
    """Parse ``buf[_PAD:_PAD + size]``; ``buf`` has ``_PAD`` spare bytes before, one after.

    The spare bytes are overwritten; the content is left as it was.
    """
    if ncols < 1 or size == 0 or len(comment) != 1 or not comment.isascii():
        return None
    if comment in "0123456789.-" or ord(comment) <= 32:
        return None
    buf[:_PAD] = b" " * _PAD
    buf[-1] = 32
    if not buf.isascii():
        return None  # the exact path checks UTF-8 and reports non-numeric text
    cbyte = comment.encode()
    if buf[-2] != 10:
        last = buf[buf.rfind(b"\n") + 1 : -1]
        if cbyte in last or last.endswith(b"\r"):
            return None  # the exact path decides about a possibly cut-off last line
        buf[-1] = 10
    b = np.frombuffer(buf, dtype=np.uint8)
    words = np.ndarray(shape=(b.size - 7,), dtype="<u8", buffer=buf, offset=0, strides=(1,))
    has_comment = cbyte in buf
    # Blocks of whole lines, each small enough for the CPU cache.
    cuts = [_PAD]
    while cuts[-1] < b.size:
        cut = buf.find(b"\n", cuts[-1] + _BLOCK) + 1
        cuts.append(b.size if cut == 0 else cut)
    # At most one row per line: blocks write their rows straight into ``values``.
    spans = list(zip(cuts[:-1], cuts[1:]))
    # Each block writes from the first row its lines could start at; blank and comment
    # lines leave gaps, closed afterwards.
    lines = [buf.count(b"\n", lo, hi) for lo, hi in spans]
    firsts = np.cumsum([0] + lines[:-1]).tolist()
    values = np.empty((ncols, sum(lines)), dtype=np.float64).T  # contiguous columns

    def block(k: int) -> int | None:
        lo, hi = spans[k]
        marked = has_comment and buf.find(cbyte, lo, hi) >= 0
        return _parse_block(b, words, lo, hi, cbyte[0] if marked else None, values[firsts[k] :])

    if len(spans) > 1 and _workers() > 1:  # numpy releases the GIL inside its loops
        counts = list(_pool().map(block, range(len(spans))))
    else:
        counts = [block(k) for k in range(len(spans))]
    nrows = 0
    for first, rows in zip(firsts, counts):
        if rows is None:
            return None
        if first != nrows:
            values[nrows : nrows + rows] = values[first : first + rows]
        nrows += rows
    return values[:nrows] if nrows else None


_POOL: tuple[int, ThreadPoolExecutor] | None = None


def _pool() -> ThreadPoolExecutor:
    """The threads that parse blocks, started once per process (a forked child, whose
    copy of the pool has no threads, starts its own)."""
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(_workers(), thread_name_prefix="fastparse"))
    return _POOL[1]


def _workers() -> int:
    """Threads for the blocks of one file: the cores this process may use, at most
    :data:`MAX_WORKERS`."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_WORKERS))


def _parse_block(
    b: NDArray[np.uint8],
    words: NDArray[np.uint64],
    lo: int,
    hi: int,
    cbyte: int | None,
    out: NDArray[np.float64],
) -> int | None:
    """Parse the whole lines ``b[lo:hi]`` (``b[lo - 1]`` and ``b[hi - 1]`` are blanks).

    Writes the rows to the top of ``out`` (shape (≥ rows, ncols)) and returns their number.
    Positions are local to the block (``lo - 1`` is local 0); ``words`` is indexed globally.
    """
    base = lo - 1
    block = b[base:hi]
    control = np.flatnonzero(block < 32)
    kinds = block[control]
    newlines = control[kinds == 10]
    if kinds.size != newlines.size:
        others = kinds[kinds != 10]
        if np.any((others != 9) & (others != 13)):
            return None  # NUL or a control character other than tab, CR, LF
        cr = control[kinds == 13]
        if np.any(block[cr + 1] != 10):
            return None  # a lone CR ends a line for str.splitlines but not here
    saved = None
    if cbyte is not None:
        saved = _blank_comments(block, newlines, cbyte)
    try:
        return _parse_fields(block, words, base, newlines, out)
    finally:
        if saved is not None:
            block[saved[0]] = saved[1]


def _parse_fields(
    block: NDArray[np.uint8],
    words: NDArray[np.uint64],
    base: int,
    newlines: NDArray[np.intp],
    out: NDArray[np.float64],
) -> int | None:
    """Tokens of a comment-free block → rows at the top of ``out``; their number or ``None``."""
    ncols = out.shape[1]
    sep = block <= 32
    edges = np.flatnonzero(sep[1:] != sep[:-1])
    edges += 1
    starts = edges[0::2]
    ends = edges[1::2]
    ntok = starts.size
    if ntok % ncols or not _one_row_per_line(starts, newlines, ncols):
        return None
    dots = np.flatnonzero(block == 46)
    if dots.size == ntok and np.all(dots >= starts) and np.all(dots < ends):
        point = dots
        has_point = np.ones(ntok, dtype=bool)
    else:
        owner = np.searchsorted(ends, dots, side="right")
        if owner.size > 1 and np.any(owner[1:] == owner[:-1]):
            return None  # two points in one token
        point = ends.copy()
        point[owner] = dots
        has_point = np.zeros(ntok, dtype=bool)
        has_point[owner] = True
    nrows = ntok // ncols
    if nrows == 0:
        return 0
    out = out[:nrows]
    negative = block[starts] == 45
    width = ends - starts
    width -= negative  # characters without the sign
    frac_len = ends - point
    frac_len -= has_point
    if np.any(width - has_point < 1):
        return None  # no digit: "-", ".", "-."
    ends += base
    point += base
    # Column by column: a column's tokens usually share one layout (all short or all
    # long), which saves splitting them.
    shape = (nrows, ncols)
    e, pt, w, fl = (a.reshape(shape) for a in (ends, point, width, frac_len))
    hp, neg = has_point.reshape(shape), negative.reshape(shape)
    odd_rows: list[NDArray[np.intp]] = []
    odd_cols: list[int] = []
    for col in range(ncols):
        odd = _parse_chunk(
            words,
            e[:, col],
            pt[:, col],
            w[:, col],
            fl[:, col],
            hp[:, col],
            neg[:, col],
            out=out[:, col],
        )
        if odd is not None:
            odd_rows.append(np.flatnonzero(odd))
            odd_cols.append(col)
    if odd_rows:
        count = sum(r.size for r in odd_rows)
        if count > max(MIN_ODD_ALLOWANCE, ntok // ODD_SHARE):
            return None  # mostly odd tokens: numpy's parser reads them faster
        ends -= base
        for rows, col in zip(odd_rows, odd_cols):
            k = rows * ncols + col
            tokens = [block[a:z].tobytes() for a, z in zip(starts[k].tolist(), ends[k].tolist())]
            values = _odd_values(tokens)
            if values is None:
                return None
            out[rows, col] = values
    return nrows


def _blank_comments(
    block: NDArray[np.uint8], newlines: NDArray[np.intp], cbyte: int
) -> tuple[NDArray[np.intp], NDArray[np.uint8]] | None:
    """Overwrite every comment (comment byte to end of line) with blanks, in place.

    Returns the overwritten positions and their bytes, to restore them afterwards, or
    ``None`` when there is no comment.
    """
    marks = np.flatnonzero(block == cbyte)
    if marks.size == 0:
        return None
    line = np.searchsorted(newlines, marks)
    first = np.ones(marks.size, dtype=bool)
    first[1:] = line[1:] != line[:-1]
    begin = marks[first]
    length = newlines[line[first]] - begin
    offsets = np.cumsum(length) - length
    index = np.repeat(begin - offsets, length) + np.arange(int(length.sum()))
    saved = (index, block[index])
    block[index] = 32
    return saved


def _one_row_per_line(starts: NDArray[np.intp], newlines: NDArray[np.intp], ncols: int) -> bool:
    """True when every line holds either no token or exactly one row of ``ncols`` tokens.

    The tokens that follow a newline must be exactly those with index ``k * ncols``, k ≥ 1.
    """
    after = np.searchsorted(starts, newlines)
    after = after[(after > 0) & (after < starts.size)]
    if after.size:
        keep = np.ones(after.size, dtype=bool)
        keep[1:] = after[1:] != after[:-1]
        after = after[keep]
    expected = np.arange(ncols, starts.size, ncols)
    return after.size == expected.size and bool(np.all(after == expected))


def _parse_chunk(
    words: NDArray[np.uint64],
    ends: NDArray[np.intp],
    point: NDArray[np.intp],
    width: NDArray[np.intp],
    frac_len: NDArray[np.intp],
    has_point: NDArray[np.bool_],
    negative: NDArray[np.bool_],
    *,
    out: NDArray[np.float64],
) -> NDArray[np.bool_] | None:
    """Parse one chunk of tokens into ``out``; the mask of its odd tokens, or ``None``.

    ``width`` counts the characters without the sign, ``frac_len`` the fraction digits.
    An odd token (not plain digits, too many digits, an undecided rounding) is left for
    :func:`_odd_values`; its place in ``out`` holds no meaningful value.
    """
    short = width <= 8
    if short.all():
        mantissa, odd = _short_mantissa(words, ends, width, frac_len, has_point)
    elif not short.any():
        mantissa, odd = _long_mantissa(words, ends, point, width, frac_len)
    else:
        mantissa = np.empty(ends.size, dtype=np.uint64)
        odd = np.zeros(ends.size, dtype=bool)
        pick = np.flatnonzero(short)
        part, part_odd = _short_mantissa(
            words, ends[pick], width[pick], frac_len[pick], has_point[pick]
        )
        mantissa[pick] = part
        if part_odd is not None:
            odd[pick] = part_odd
        pick = np.flatnonzero(~short)
        part, part_odd = _long_mantissa(words, ends[pick], point[pick], width[pick], frac_len[pick])
        mantissa[pick] = part
        if part_odd is not None:
            odd[pick] |= part_odd
        if not odd.any():
            odd = None
    power = np.minimum(frac_len, MAX_FRACTION)  # an odd token's value is replaced anyway
    values = mantissa.astype(np.float64)
    values /= _POW10_FLOAT[power]  # exact for m < 2**53; q0 of the correction otherwise
    is_big = mantissa >= _TWO53
    if odd is not None:
        is_big &= ~odd
    if is_big.all():  # e.g. a column of %.17g numbers
        values, undecided = _round_big(mantissa, values, power)
        if undecided.any():
            odd = undecided
    elif is_big.any():
        big = np.flatnonzero(is_big)
        fixed, undecided = _round_big(mantissa[big], values[big], power[big])
        values[big] = fixed
        if undecided.any():
            odd = np.zeros(ends.size, dtype=bool) if odd is None else odd
            odd[big[undecided]] = True
    # The sign last: the magnitude is >= 0, so this also gives -0.0 for "-0".
    np.copysign(values, 0.5 - negative, out=values)
    out[...] = values
    return odd


def _round_big(
    mantissa: NDArray[np.uint64], q0: NDArray[np.float64], power: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The double nearest to ``mantissa / 10**power`` for ``2**53 <= mantissa < 2**63``.

    ``q0 = fl(fl(m) / p)`` (``p = 10**power``, exact) is within 1.5 units in the last place
    (``u``) of ``v = m / p``. The remainder ``r = m - q0·p`` is computed to about 2**-41
    (``m = fl(m) + m_lo`` exactly, ``q0·p = ph + pl`` exactly by Dekker's product with
    Veltkamp's split, ``fl(m) - ph`` exact by Sterbenz's lemma), while ``p·u ≥ 2**-53·m ≥ 1``;
    so ``d = r / (p·u) = (v - q0) / u`` is known to about 2**-40 and the nearest double is
    ``q0 + rint(d)·u``, unless ``d`` lies within 2**-21 of a midpoint (a tie or near-tie),
    beyond ±1.5, or below zero next to a power of two (where ``u`` halves): those are
    ``undecided`` and go to ``float()``.
    """
    m_hi = mantissa.astype(np.float64)
    m_lo = mantissa.view(np.int64) - m_hi.astype(np.int64)
    p = _POW10_FLOAT[power]
    ph = q0 * p
    c = q0 * _SPLITTER
    q_hi = c - (c - q0)
    q_lo = q0 - q_hi
    p_hi, p_lo = _POW10_HI[power], _POW10_LO[power]
    pl = q_hi * p_hi
    pl -= ph
    pl += q_hi * p_lo
    pl += q_lo * p_hi
    pl += q_lo * p_lo
    r = m_hi - ph
    r += m_lo - pl
    u = np.spacing(q0)
    r /= p * u  # d, in units of u
    k = np.rint(r)
    off = np.abs(r - k)
    undecided = off > 0.5 - _MARGIN
    undecided |= np.abs(k) > 1.0
    # q0 a power of two (mantissa field 0) or just above one (field 1): u differs below.
    undecided |= (r < 0.0) & ((q0.view(np.uint64) & _FRACTION_FIELD) <= _U64(1))
    k *= u
    k += q0
    return k, undecided


def _short_mantissa(
    words: NDArray[np.uint64],
    ends: NDArray[np.intp],
    width: NDArray[np.intp],
    frac_len: NDArray[np.intp],
    has_point: NDArray[np.bool_],
) -> tuple[NDArray[np.uint64], NDArray[np.bool_] | None]:
    """Digits of tokens of at most 8 characters (sign excluded) as one integer, and the
    mask of tokens that are not digits (``None`` when all are).

    The token is the top ``width`` bytes of the word ending at ``ends``; the point is
    removed by moving the integer digits up one byte, under the ``frac_len`` fraction bytes.
    """
    word = words[ends - 8]
    # Top ``frac_len`` bytes (all bytes when there is no point) stay; the rest move up.
    shift = (8 - frac_len).astype(np.uint64)
    shift *= _S8
    shift *= has_point
    keep = _ALL << shift  # shift by 64 gives 0
    moved = word << _S8
    moved &= ~keep
    word &= keep
    word |= moved
    return _eight_digits(word, width - has_point)


def _long_mantissa(
    words: NDArray[np.uint64],
    ends: NDArray[np.intp],
    point: NDArray[np.intp],
    width: NDArray[np.intp],
    frac_len: NDArray[np.intp],
) -> tuple[NDArray[np.uint64], NDArray[np.bool_] | None]:
    """Digits of longer tokens: integer and fraction parts read separately, then combined.

    Odd (``True`` in the mask): a part longer than 24 digits, more than 22 fraction digits,
    a non-digit, or a mantissa of 9·10**18 or more (beyond the 63 bits the rounding uses).
    """
    int_len = width - (ends - point)
    odd = (int_len > _MAX_PART) | (frac_len > MAX_FRACTION)
    int_len = np.minimum(int_len, _MAX_PART)
    f_len = np.minimum(frac_len, _MAX_PART)
    int_words, int_odd = _digit_words(words, point, int_len)
    frac_words, frac_odd = _digit_words(words, ends, f_len)
    for bad in (int_odd, frac_odd):
        if bad is not None:
            odd |= bad
    long = np.flatnonzero(int_len + f_len > 18)  # < 10**18 otherwise: no overflow
    if long.size:
        # Every part exactly, the sum to 1e-15: safely below 2**63 ≈ 9.22e18 or odd.
        w = [a[long].astype(np.float64) for a in (*int_words, *frac_words)]
        scale = _POW10_FLOAT_WIDE[np.minimum(frac_len[long], _MAX_PART)]
        estimate = (w[0] + w[1] * 1e8 + w[2] * 1e16) * scale
        estimate += w[3] + w[4] * 1e8 + w[5] * 1e16
        odd[long[~(estimate < _MAX_MANTISSA)]] = True
    mantissa = _combine(frac_words)
    mantissa += _combine(int_words) * _POW10_INT[np.minimum(frac_len, 19)]  # wraps if odd
    return mantissa, odd if odd.any() else None


def _combine(parts: tuple[NDArray[np.uint64], ...]) -> NDArray[np.uint64]:
    """``low + 10**8 mid + 10**16 high`` (wraps modulo 2**64 for odd tokens, by design)."""
    low, mid, high = parts
    value = high * _E16
    value += mid * _E8
    value += low
    return value


def _digit_words(
    words: NDArray[np.uint64], end: NDArray[np.intp], length: NDArray[np.intp]
) -> tuple[tuple[NDArray[np.uint64], ...], NDArray[np.bool_] | None]:
    """The ``length`` (0..24) ASCII digits that end at byte ``end`` of each token, as the
    values of their last, middle and first eight (low, mid, high), and the mask of
    tokens with a non-digit among them (``None`` when there is none)."""
    low, odd = _eight_digits(words[end - 8], np.minimum(length, 8))
    parts = [low]
    for k in (1, 2):
        part = np.zeros(end.size, dtype=np.uint64)
        more = length > 8 * k
        count = np.minimum(length - 8 * k, 8)
        if more.all():
            part, bad = _eight_digits(words[end - 8 * (k + 1)], count)
        elif more.any():
            pick = np.flatnonzero(more)
            part[pick], bad = _eight_digits(words[end[pick] - 8 * (k + 1)], count[pick])
            if bad is not None:
                bad = _scatter(bad, pick, end.size)
        else:
            bad = None
        parts.append(part)
        if bad is not None:
            odd = bad if odd is None else odd | bad
    return (parts[0], parts[1], parts[2]), odd


def _scatter(mask: NDArray[np.bool_], pick: NDArray[np.intp], size: int) -> NDArray[np.bool_]:
    full = np.zeros(size, dtype=bool)
    full[pick] = mask
    return full


def _eight_digits(
    word: NDArray[np.uint64], length: NDArray[np.intp]
) -> tuple[NDArray[np.uint64], NDArray[np.bool_] | None]:
    """Value of the last ``length`` (0..8) bytes of each little-endian word, as digits, and
    the mask of words where a kept byte is not a digit (``None`` when there is none).

    The earlier bytes are replaced by ``'0'``.
    """
    shift = (8 - length).astype(np.uint64)
    shift *= _S8
    word >>= shift
    word <<= shift
    word |= _ZEROS >> (_S64 - shift)  # '0' in the replaced bytes (shift by 64 gives 0)
    # Digit values: '0'..'9' become 0..9. A byte below '0' borrows and ends at 0xF1 or
    # above; one above '9' ends at 0x0A or above, which adding 0x76 takes to 0x80 (or,
    # after a borrow from below, the byte below shows it): every non-digit leaves some
    # byte of ``check`` with its top bit set, and none is set when all are digits.
    word -= _ZEROS
    check = word + _PLUS118
    check |= word
    check &= _TOP_BITS
    bad = check != _U64(0)
    word *= _MUL1
    word >>= _S8
    word &= _MASK16
    word *= _MUL2
    word >>= _S16
    word &= _MASK32
    word *= _MUL3
    word >>= _S32
    return word, bad if bad.any() else None


def _odd_values(tokens: list[bytes]) -> list[float] | None:
    """``float()`` of the odd tokens, or ``None`` when one is outside :data:`ODD_TOKEN` or
    not finite (the exact path then diagnoses it)."""
    values = []
    for token in tokens:
        if ODD_TOKEN.fullmatch(token) is None:
            return None
        value = float(token)
        if not math.isfinite(value):
            return None
        values.append(value)
    return values
