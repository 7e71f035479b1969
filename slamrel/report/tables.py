"""Comparison tables over results (algorithms × datasets), with paired significance tests.

Kümmerle et al. (2009, Sec. VI "Numerical Evaluation") tabulate the translational and
rotational relation errors, absolute and squared, mean ± std, per dataset and algorithm.
Their table cannot say whether two algorithms differ beyond chance. Here every pair of
algorithms on a dataset is compared on the *same relations*, one test per relation set
(the ``set`` column of the per-relation CSV; without it all relations are one set "all")
and part (translation, rotation): the mean paired difference of the abs errors A − B, its
confidence interval and a two-sided p-value from a circular block bootstrap over the
relations in time order (:func:`relation_metric.significance.paired_difference`: relations
that share a stretch of the run are dependent, and the blocks keep that dependence), the
p-values Holm-adjusted over all tests of the table
(:func:`relation_metric.significance.holm_adjust`).

Inputs are the per-relation CSV files of ``slamrel evaluate --per-relation`` (or of
``slamrel run``); relations are paired by their relation set and ``(t1, t2)`` as written
there.
"""

from __future__ import annotations

import itertools
import re
import warnings
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.evaluate import error_summaries
from relation_metric.significance import (
    DEFAULT_RESAMPLES,
    MIN_BLOCKS,
    OVERLAP_FACTOR,
    PairedDifference,
    holm_adjust,
    paired_difference,
)
from relation_metric.stats import ErrorStats, Summary
from slamrel.formats.results import read_per_relation_csv
from slamrel.formats.text import PathLike

__all__ = [
    "ALL_RELATIONS",
    "ResultErrors",
    "read_per_relation",
    "PairTest",
    "Comparison",
    "compare_results",
]

ALL_RELATIONS = "all"
"""The relation set of a per-relation CSV without a ``set`` column."""

_SEP = "\x1f"  # between set name and "t1 t2" in a pairing key (no name holds it)


@dataclass(frozen=True)
class ResultErrors:
    """Per-relation errors of one algorithm on one dataset.

    Attributes
    ----------
    dataset, algorithm : str
    keys : ndarray of str, shape (M,)
        ``"t1 t2"`` of each scored relation (pairing key, with the relation set).
    translation, rotation : ndarray, shape (M,)
        Metres; radians (degrees when ``rotation_unit == "deg"``).
    rotation_unit : str
    source : str, optional
        The file the errors were read from (for messages).
    t1, t2 : ndarray, shape (M,), optional
        The relation times; when not given they are read from ``keys``.
    relation_set : ndarray of str, shape (M,), optional
        The relation set of each relation (``consecutive``, ``loops``, ...); when not given
        every relation is in the one set :data:`ALL_RELATIONS`.
    """

    dataset: str
    algorithm: str
    keys: NDArray[np.str_]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    rotation_unit: str
    source: str | None = None
    t1: NDArray[np.float64] | None = None
    t2: NDArray[np.float64] | None = None
    relation_set: NDArray[np.str_] | None = None

    def __post_init__(self) -> None:
        keys = np.asarray(self.keys, dtype=np.str_).reshape(-1)
        m = keys.size
        where = f" ({self.source})" if self.source else ""
        if (self.t1 is None or self.t2 is None) and m == 0:
            t1 = t2 = np.empty(0)
        elif self.t1 is None or self.t2 is None:
            parts = np.char.partition(keys, " ")
            try:
                t1, t2 = parts[:, 0].astype(np.float64), parts[:, 2].astype(np.float64)
            except ValueError:
                raise InputError(
                    f'{self.dataset}:{self.algorithm}{where}: relation keys must be "t1 t2" '
                    f"(two numbers) when t1 and t2 are not given, got {str(keys[0])!r} ..."
                ) from None
        else:
            t1 = np.asarray(self.t1, dtype=np.float64)
            t2 = np.asarray(self.t2, dtype=np.float64)
        if self.relation_set is None:
            sets = np.full(m, ALL_RELATIONS)
        else:
            sets = np.asarray(self.relation_set, dtype=np.str_)
        for name, value in (("translation", self.translation), ("rotation", self.rotation)):
            object.__setattr__(self, name, np.asarray(value, dtype=np.float64))
        for name, arr in (
            ("translation", self.translation), ("rotation", self.rotation),
            ("t1", t1), ("t2", t2), ("relation_set", sets),
        ):  # fmt: skip
            if arr.shape != (m,):
                raise InputError(
                    f"{self.dataset}:{self.algorithm}{where}: {name} has shape {arr.shape}, "
                    f"expected ({m},) as the keys"
                )
        if not (np.isfinite(t1).all() and np.isfinite(t2).all()):
            raise InputError(
                f"{self.dataset}:{self.algorithm}{where}: relation times must be finite"
            )
        object.__setattr__(self, "keys", keys)
        object.__setattr__(self, "t1", t1)
        object.__setattr__(self, "t2", t2)
        object.__setattr__(self, "relation_set", sets)

    @property
    def name(self) -> str:
        """``dataset:algorithm (file)`` for messages."""
        where = f" ({self.source})" if self.source else ""
        return f"{self.dataset}:{self.algorithm}{where}"

    @property
    def sets(self) -> NDArray[np.str_]:
        """The relation set of each relation (set when built: never ``None``)."""
        assert self.relation_set is not None
        return self.relation_set

    @property
    def times(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(t1, t2)`` of each relation (set when built: never ``None``)."""
        assert self.t1 is not None and self.t2 is not None
        return self.t1, self.t2

    @cached_property
    def pair_keys(self) -> NDArray[np.str_]:
        """Relation set and ``"t1 t2"``: what pairs a relation across results."""
        return np.char.add(np.char.add(self.sets, _SEP), self.keys)

    @cached_property
    def key_order(self) -> NDArray[np.intp]:
        """The permutation that sorts :attr:`pair_keys` (results with one relation set
        line up in this order)."""
        return np.argsort(self.pair_keys, kind="stable")

    def restricted(self, pair_keys: NDArray[np.str_]) -> ResultErrors:
        """The same result on the relations ``pair_keys`` only (all must be present)."""
        _, idx, _ = np.intersect1d(
            self.pair_keys, pair_keys, assume_unique=True, return_indices=True
        )
        idx = np.sort(idx)
        t1, t2 = self.times
        return replace(
            self,
            keys=self.keys[idx],
            translation=self.translation[idx],
            rotation=self.rotation[idx],
            t1=t1[idx],
            t2=t2[idx],
            relation_set=self.sets[idx],
        )


def read_per_relation(path: PathLike, *, dataset: str, algorithm: str) -> ResultErrors:
    """A per-relation CSV of ``slamrel evaluate`` as compared (only valid relations are kept).

    The file is read by the format's one reader,
    :func:`slamrel.formats.results.read_per_relation_csv`. Relations are keyed by their
    times ``t1 t2`` (as numbers, so that ``1.50`` and ``1.5`` pair) and, when the file has a
    ``set`` column, their relation set (without it every relation is in the set
    :data:`ALL_RELATIONS`); a relation twice in one set cannot be paired and is refused.
    """
    table = read_per_relation_csv(path)
    keep, lines = table.valid, table.lines
    trans, rot = table.translation[keep], table.rotation[keep]
    t1, t2 = table.t1[keep], table.t2[keep]
    k = np.char.add(np.char.add(t1.astype(str), " "), t2.astype(str))
    sets = None if table.relation_set is None else table.relation_set[keep]
    paired = k if sets is None else np.char.add(np.char.add(sets, _SEP), k)
    uniq, counts = np.unique(paired, return_counts=True)
    if (counts > 1).any():
        dup = int(np.flatnonzero(paired == uniq[counts > 1][0])[1])
        within = "" if sets is None else f" in relation set {str(sets[dup])!r}"
        raise InputError(
            f"a relation (t1, t2) appears twice{within}; cannot pair relations",
            path=path,
            line=int(lines[keep][dup]),
        )
    return ResultErrors(
        dataset, algorithm, k, trans, rot, table.rotation_unit,
        t1=t1, t2=t2, relation_set=sets,
    )  # fmt: skip


@dataclass(frozen=True)
class PairTest:
    """Two algorithms compared on one relation set and part (translation or rotation).

    Attributes
    ----------
    dataset, relation_set, a, b, part : str
    unit : str
        Of the errors and differences: ``m`` for translation, ``rad`` or ``deg``.
    difference : PairedDifference
        Means, mean difference A − B, confidence interval, bootstrap p-value and block
        length (:func:`relation_metric.significance.paired_difference`).
    p_holm : float
        Holm-adjusted over all tests of the table (NaN without a test).
    significant : bool
        ``p_holm < alpha``.
    """

    dataset: str
    relation_set: str
    a: str
    b: str
    part: str
    unit: str
    difference: PairedDifference
    p_holm: float
    significant: bool

    @property
    def n(self) -> int:
        """Relations compared."""
        return self.difference.n

    @property
    def mean_difference(self) -> float:
        """Mean A − B of the abs errors (negative: A has the smaller errors)."""
        return self.difference.mean_difference

    @property
    def p_value(self) -> float:
        """The unadjusted bootstrap p-value (NaN without a test)."""
        return self.difference.p_value

    @property
    def better(self) -> str | None:
        """The algorithm with the smaller mean error when the difference is significant."""
        if not self.significant:
            return None
        return self.a if self.mean_difference < 0 else self.b


@dataclass(frozen=True)
class ResultStats:
    """The statistics of one result's common relations: translation [m] and rotation (in
    the comparison's unit), each of ``|e|`` and ``e²``."""

    translation: ErrorStats
    rotation: ErrorStats

    def part(self, part: str, kind: str) -> Summary:
        """``part`` ("translation" or "rotation"), ``kind`` ("abs" or "sqr"): for tables
        that walk the columns."""
        stats: ErrorStats = getattr(self, part)
        return stats.abs if kind == "abs" else stats.sqr


@dataclass(frozen=True)
class Comparison:
    """Statistics per (dataset, algorithm) and pairwise tests per dataset and relation set."""

    stats: dict[tuple[str, str], ResultStats]
    tests: list[PairTest]
    alpha: float
    rotation_unit: str
    left_out: dict[tuple[str, str], int] = field(default_factory=dict)
    resamples: int = DEFAULT_RESAMPLES

    def rows(self) -> list[list[Any]]:
        """Table rows: dataset, algorithm, then mean and std of trans/rot abs/sqr, N."""
        out = []
        for (ds, alg), st in self.stats.items():
            row: list[Any] = [ds, alg]
            for part in ("translation", "rotation"):
                for kind in ("abs", "sqr"):
                    row += [st.part(part, kind).mean, st.part(part, kind).std]
            row.append(st.translation.abs.count)
            out.append(row)
        return out

    def columns(self) -> list[str]:
        u = self.rotation_unit
        return [
            "dataset", "algorithm",
            "trans abs mean [m]", "trans abs std [m]", "trans sqr mean [m²]", "trans sqr std [m²]",
            f"rot abs mean [{u}]", f"rot abs std [{u}]",
            f"rot sqr mean [{u}²]", f"rot sqr std [{u}²]",
            "relations",
        ]  # fmt: skip

    @property
    def confidence(self) -> float:
        """Level of the intervals: ``1 − alpha``."""
        return 1.0 - self.alpha

    def test_description(self) -> str:
        """What the tests are, in words (the paragraph above the tests table)."""
        tested = sum(t.difference.tested for t in self.tests)
        level = f"{100 * self.confidence:g} %"
        return (
            "Paired differences A − B of the abs errors, one test per relation set and part, "
            "over the relations both scored (negative: A has the smaller errors; % of B's "
            f"mean). The {level} confidence interval of the mean difference and its two-sided "
            "p-value come from a circular block bootstrap over the relations in time order "
            f"(B = {self.resamples} resamples; p below 1/B is shown as < 1/B, never 0), which "
            "keeps the dependence of relations that share a stretch of the run. Block length "
            f"L: the largest of {OVERLAP_FACTOR} × (1 + the mean number of later relations a "
            "relation overlaps in time), the Politis–White length from the differences' "
            f"autocorrelation and ⌈n^(1/3)⌉; with fewer than {MIN_BLOCKS} blocks there is no "
            f"test. p (Holm): adjusted over the {tested} tests of this table; significant: "
            f"p (Holm) < α = {self.alpha:g}."
        )

    def markdown(self) -> str:
        """The table and the tests as GitHub Markdown."""
        lines = [_md_row(self.columns()), "|" + "---|" * len(self.columns())]
        for row in self.rows():
            lines.append(_md_row(_fmt(v) for v in row))
        dropped = {k: n for k, n in self.left_out.items() if n}
        if dropped:
            lines += [
                "",
                "Relations not scored by every algorithm of a dataset are left out of its "
                "statistics and tests: "
                + ", ".join(f"{_md(ds)}:{_md(alg)} {n}" for (ds, alg), n in dropped.items())
                + ".",
            ]
        if not self.tests:
            return "\n".join(lines) + "\n"
        level = f"{100 * self.confidence:g} % CI"
        head = [
            "dataset", "relations", "part", "A", "B", "n", "mean A", "mean B", "A − B", level,
            "A − B [% of B]", "p", "p (Holm)", "better", "test",
        ]  # fmt: skip
        lines += ["", self.test_description(), ""]
        lines += [_md_row(head), "|" + "---|" * len(head)]
        for t in self.tests:
            lines.append(_md_row(self._test_cells(t)))
        return "\n".join(lines) + "\n"

    def _test_cells(self, t: PairTest) -> list[str]:
        d, u = t.difference, t.unit
        dash = "—"
        ci = f"[{d.ci_low:+.3g}, {d.ci_high:+.3g}] {u}" if d.tested else dash
        rel = d.relative_difference
        if t.significant:
            better = f"{t.better} by {abs(d.mean_difference):.3g} {u}"
        elif d.tested:
            better = "neither (not significant)"
        else:
            better = f"{dash} (no test)"
        test = f"block bootstrap, L = {d.block.length}" if d.tested else f"none: {d.reason}"
        return [
            t.dataset, t.relation_set, t.part, t.a, t.b, str(t.n),
            f"{d.mean_a:.4g} {u}", f"{d.mean_b:.4g} {u}", f"{d.mean_difference:+.3g} {u}", ci,
            f"{rel:+.1f} %" if np.isfinite(rel) else "n/a",
            self._p_text(d.p_value, d.p_at_floor), self._p_text(t.p_holm, d.p_at_floor),
            better, test,
        ]  # fmt: skip

    def _p_text(self, p: float, at_floor: bool) -> str:
        """A p-value as shown: ``< x`` at the bootstrap's resolution (x = p (B + 1) / B)."""
        if not np.isfinite(p):
            return "—"
        if at_floor:
            return f"< {min(1.0, p * (self.resamples + 1) / self.resamples):.2g}"
        return f"{p:.2g}"

    def csv(self) -> str:
        """The statistics table as CSV."""
        return _csv_text([self.columns(), *([_fmt(v) for v in row] for row in self.rows())])

    def tests_csv(self) -> str:
        """The tests as CSV, one row per test (numbers to 6 digits; empty without a test)."""
        rows: list[list[Any]] = [[
            "dataset", "relation_set", "part", "unit", "a", "b", "n", "mean_a", "mean_b",
            "mean_difference", "ci_low", "ci_high", "confidence", "relative_difference_percent",
            "p_value", "p_below_1_over_B", "p_holm", "significant", "better", "block_length",
            "blocks", "resamples", "no_test_reason",
        ]]  # fmt: skip
        for t in self.tests:
            d = t.difference
            rows.append([
                t.dataset, t.relation_set, t.part, t.unit, t.a, t.b, t.n,
                _num(d.mean_a), _num(d.mean_b), _num(d.mean_difference), _num(d.ci_low),
                _num(d.ci_high), _num(d.confidence), _num(d.relative_difference),
                _num(d.p_value), int(d.p_at_floor), _num(t.p_holm), int(t.significant),
                t.better or "", d.block.length, _num(d.block.blocks), d.resamples, d.reason,
            ])  # fmt: skip
        return _csv_text(rows)

    def latex(self) -> str:
        """The table as a LaTeX tabular: mean ± std per part, like the paper's table."""
        u = self.rotation_unit
        head = (
            "\\begin{tabular}{llrrrr}\n\\hline\n"
            "dataset & algorithm & trans. abs [m] & trans. sqr [m$^2$] & "
            f"rot. abs [{u}] & rot. sqr [{u}$^2$] \\\\\n\\hline\n"
        )
        body = []
        for (ds, alg), st in self.stats.items():
            cells = [
                f"${st.part(p, k).mean:.4g} \\pm {st.part(p, k).std:.4g}$"
                for p in ("translation", "rotation")
                for k in ("abs", "sqr")
            ]
            body.append(f"{_tex(ds)} & {_tex(alg)} & " + " & ".join(cells) + " \\\\")
        return head + "\n".join(body) + "\n\\hline\n\\end{tabular}\n"


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if not np.isfinite(v) else f"{v:.6g}"
    return str(v)


def _num(v: float) -> str:
    """A number of ``tests.csv``: 6 significant digits, empty when NaN."""
    return f"{v:.6g}" if np.isfinite(v) else ""


def _csv_field(v: Any) -> str:
    """One CSV field (RFC 4180): quoted when it holds a separator, a quote or a line end, or
    when it starts with ``#`` or white space (slamrel's CSV readers take a line starting with
    ``#`` for a comment and strip cells); quotes doubled."""
    s = str(v)
    if any(c in s for c in ',"\r\n') or s[:1] in ("#", " ", "\t") or s[-1:] in (" ", "\t"):
        return '"' + s.replace('"', '""') + '"'
    return s


csv_field = _csv_field  # public: the batch table quotes its names by the same rule


def _csv_text(rows: Sequence[Sequence[Any]]) -> str:
    """Rows as CSV text that :func:`csv.reader` reads back field for field."""
    return "".join(",".join(_csv_field(v) for v in row) + "\n" for row in rows)


# GitHub Markdown: a backslash escapes any ASCII punctuation; these would end a table cell
# (|), start math ($), emphasis (* _) or code (`), or escape what follows (\); a < that
# could open an HTML tag is written as &lt;
_MD_SPECIAL = re.compile(r"([\\|$*_`])")
_MD_TAG = re.compile(r"<(?=[A-Za-z/!?])")


def _md(s: str) -> str:
    """Text for a Markdown table cell: specials escaped, line ends as ``<br>``."""
    text = _MD_TAG.sub("&lt;", _MD_SPECIAL.sub(r"\\\1", s))
    return "<br>".join(text.splitlines()) if ("\n" in text or "\r" in text) else text


markdown_cell = _md  # public: the batch table escapes its names by the same rule


def _md_row(cells: Iterable[str]) -> str:
    return "| " + " | ".join(_md(c) for c in cells) + " |"


_TEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "\n": " ",
    "\r": " ",
}


def _tex(s: str) -> str:
    """Text for a LaTeX table cell: every special character of LaTeX escaped (one pass, so a
    replacement is never escaped again); line ends become spaces."""
    return "".join(_TEX_SPECIAL.get(c, c) for c in s)


def _test_seed(seed: int, *names: str) -> np.random.SeedSequence:
    """The bootstrap seed of one test: from ``seed`` and the test's names (not its position,
    so adding a result to a table leaves the other tests' resamples as they were)."""
    return np.random.SeedSequence([seed, zlib.crc32("\x1f".join(names).encode("utf-8"))])


def compare_results(
    results: list[ResultErrors],
    *,
    alpha: float = 0.05,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
) -> Comparison:
    """Statistics per result and paired tests between the algorithms of each dataset.

    Within a dataset every algorithm is scored on the *same* relations: those that all of
    its results contain (matched by relation set and ``(t1, t2)``). Relations that some
    result lacks (e.g. left unassociated there) are left out of every statistic and test of
    that dataset, counted in :attr:`Comparison.left_out` and named in a warning, so that
    means side by side are over one set.

    Each pair of algorithms is tested per relation set and part with
    :func:`relation_metric.significance.paired_difference` (circular block bootstrap of the
    paired differences in time order, ``resamples`` resamples, intervals at ``1 − alpha``);
    the p-values of all tests of the table are Holm-adjusted together, and a test is
    significant when its adjusted p-value is below ``alpha``.

    Parameters
    ----------
    results : list of ResultErrors
    alpha : float
        Significance level, in (0, 1).
    resamples : int
        Bootstrap resamples B per test (≥ 99: p-values resolve 1/(B + 1)).
    seed : int
        Seed of the bootstrap (each test draws from its own stream, derived from the seed
        and the test's dataset, relation set, algorithms and part).

    Raises
    ------
    InputError
        No results; ``alpha`` outside (0, 1); ``resamples`` < 99 or ``seed`` < 0; a result
        with no relations, a non-finite error or a relation twice; a (dataset, algorithm)
        given twice; rotation units mixed; a dataset whose results share no relation.
    """
    if not results:
        raise InputError("nothing to compare: give at least one result")
    if not (0.0 < alpha < 1.0):
        raise InputError(f"alpha must be a probability in (0, 1), got {float(alpha):g}")
    if resamples < 99:
        raise InputError(f"resamples must be >= 99 (p-values resolve 1/(B+1)), got {resamples}")
    if seed < 0:
        raise InputError(f"seed must be >= 0, got {seed}")
    units = {r.rotation_unit for r in results}
    if len(units) != 1:
        raise InputError(
            f"results mix rotation units {sorted(units)}; evaluate all with or without --degrees"
        )
    unit = units.pop()
    seen: set[tuple[str, str]] = set()
    for r in results:
        key = (r.dataset, r.algorithm)
        if key in seen:
            raise InputError(f"{r.dataset}/{r.algorithm} is given twice")
        seen.add(key)
        _check_errors(r)
    results, left_out = _common_relations(results)
    stats: dict[tuple[str, str], ResultStats] = {}
    for r in results:
        stats[(r.dataset, r.algorithm)] = ResultStats(
            error_summaries(r.translation), error_summaries(r.rotation)
        )
    raw: list[tuple[str, str, str, str, str, PairedDifference]] = []
    for ds in dict.fromkeys(r.dataset for r in results):
        group = [r for r in results if r.dataset == ds]
        for a, b in itertools.combinations(group, 2):
            ia, ib = a.key_order, b.key_order  # one relation set (_common_relations)
            sets = a.sets[ia]
            t1, t2 = (t[ia] for t in a.times)
            for name in dict.fromkeys(a.sets.tolist()):  # in the order of the file
                sel = np.flatnonzero(sets == name)
                if sel.size == 0:
                    continue
                for part in ("translation", "rotation"):
                    diff = paired_difference(
                        t1[sel], t2[sel], getattr(a, part)[ia][sel], getattr(b, part)[ib][sel],
                        confidence=1.0 - alpha, resamples=resamples,
                        seed=_test_seed(seed, ds, name, a.algorithm, b.algorithm, part),
                    )  # fmt: skip
                    raw.append((ds, name, a.algorithm, b.algorithm, part, diff))
    tested = np.array([x[5].tested for x in raw], dtype=bool)
    p_holm = np.full(len(raw), np.nan)
    p_holm[tested] = holm_adjust(np.array([x[5].p_value for x in raw])[tested])
    tests = [
        PairTest(
            ds,
            name,
            a_name,
            b_name,
            part,
            "m" if part == "translation" else unit,
            diff,
            float(ph),
            bool(ph < alpha),
        )  # fmt: skip
        for (ds, name, a_name, b_name, part, diff), ph in zip(raw, p_holm)
    ]
    return Comparison(stats, tests, alpha, unit, left_out, resamples)


def _check_errors(r: ResultErrors) -> None:
    if r.keys.size == 0:
        raise InputError(
            f"{r.dataset}:{r.algorithm}: no scored relations (all invalid or none); nothing to "
            "compare",
            path=r.source,
        )
    uniq, counts = np.unique(r.pair_keys, return_counts=True)
    if (counts > 1).any():
        set_name, key = str(uniq[counts > 1][0]).split(_SEP)
        raise InputError(
            f"{r.dataset}:{r.algorithm}: relation (t1 t2) {key} appears twice in relation set "
            f"{set_name!r}; cannot pair relations",
            path=r.source,
        )
    for part in ("translation", "rotation"):
        v = getattr(r, part)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise InputError(
                f"{r.dataset}:{r.algorithm}: {part} error of relation (t1 t2) {r.keys[bad[0]]} is "
                f"{float(v[bad[0]])}; expected finite errors",
                path=r.source,
            )


def _common_relations(
    results: list[ResultErrors],
) -> tuple[list[ResultErrors], dict[tuple[str, str], int]]:
    """Each result restricted to the relations every result of its dataset has."""
    out: list[ResultErrors] = []
    left_out: dict[tuple[str, str], int] = {}
    for ds in dict.fromkeys(r.dataset for r in results):
        group = [r for r in results if r.dataset == ds]
        common = group[0].pair_keys
        for r in group[1:]:
            common = np.intersect1d(common, r.pair_keys, assume_unique=True)
        if common.size == 0:
            raise InputError(
                f"dataset {ds}: the results share no relation (t1, t2) ("
                + ", ".join(r.name for r in group)
                + "); were they evaluated on the same relations?"
                + _sets_differ(group)
            )
        for r in group:
            left_out[(r.dataset, r.algorithm)] = int(r.keys.size - common.size)
        if any(r.keys.size != common.size for r in group):
            warnings.warn(
                f"dataset {ds}: the results score different relation sets ("
                + ", ".join(f"{r.name}: {r.keys.size}" for r in group)
                + f"); statistics and tests use the {common.size} relations common to all",
                UserWarning,
                stacklevel=3,
            )
            group = [r.restricted(common) for r in group]
        out.extend(group)
    return out, left_out


def _sets_differ(group: list[ResultErrors]) -> str:
    """A hint when the results name different relation sets (a ``set`` column or not)."""
    names = [sorted(set(r.sets.tolist())) for r in group]
    if all(n == names[0] for n in names):
        return ""
    return (
        " Their relation sets differ ("
        + "; ".join(f"{r.algorithm}: {', '.join(n)}" for r, n in zip(group, names))
        + f"): a per-relation CSV without a 'set' column is the one set {ALL_RELATIONS!r}; "
        "write all of them the same way (slamrel evaluate names the set when it generates "
        "the relations with --strategy)"
    )
