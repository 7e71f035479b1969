"""Comparison tables over results (algorithms × datasets), with paired significance tests.

Kümmerle et al. (2009, Sec. VI "Numerical Evaluation") tabulate the translational and
rotational relation errors, absolute and squared, mean ± std, per dataset and algorithm.
Their table cannot say whether two algorithms differ beyond chance; here every pair of
algorithms on a dataset is compared on the *same relations* with the Wilcoxon signed-rank
test on the paired per-relation errors (two-sided), and the p-values are Holm-adjusted over
the pairs of that dataset.

Inputs are the per-relation CSV files of ``slamrel evaluate --per-relation``; relations are
paired by their ``(t1, t2)`` as written there.
"""

from __future__ import annotations

import io
import itertools
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import wilcoxon

from relation_metric.errors import InputError
from relation_metric.stats import Summary, summarize
from slamrel.formats.text import PathLike, read_csv_table

__all__ = [
    "ResultErrors",
    "read_per_relation",
    "PairTest",
    "Comparison",
    "compare_results",
    "holm",
]


@dataclass(frozen=True)
class ResultErrors:
    """Per-relation errors of one algorithm on one dataset.

    Attributes
    ----------
    dataset, algorithm : str
    keys : ndarray of str, shape (M,)
        ``"t1 t2"`` of each scored relation (pairing key).
    translation, rotation : ndarray, shape (M,)
        Metres; radians (degrees when ``rotation_unit == "deg"``).
    rotation_unit : str
    source : str, optional
        The file the errors were read from (for messages).
    """

    dataset: str
    algorithm: str
    keys: NDArray[np.str_]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    rotation_unit: str
    source: str | None = None

    @property
    def name(self) -> str:
        """``dataset:algorithm (file)`` for messages."""
        where = f" ({self.source})" if self.source else ""
        return f"{self.dataset}:{self.algorithm}{where}"

    def restricted(self, keys: NDArray[np.str_]) -> ResultErrors:
        """The same result on the relations ``keys`` only (all of them must be present)."""
        _, idx, _ = np.intersect1d(self.keys, keys, assume_unique=True, return_indices=True)
        idx = np.sort(idx)
        return replace(
            self,
            keys=self.keys[idx],
            translation=self.translation[idx],
            rotation=self.rotation[idx],
        )


def read_per_relation(path: PathLike, *, dataset: str, algorithm: str) -> ResultErrors:
    """Read a per-relation CSV of ``slamrel evaluate`` (only valid relations are kept).

    Relations are keyed by their times ``t1 t2`` (as numbers, so that ``1.50`` and ``1.5``
    pair); the errors of invalid relations may be empty.
    """
    rot_names = ("rot_error_rad", "rot_error_deg")
    table = read_csv_table(
        path,
        required=("t1", "t2", "trans_error", rot_names, "valid"),
        empty_ok=("trans_error", *rot_names),
        describe="the per-relation CSV of slamrel evaluate",
    )
    c, lines = table
    rot_col = next(n for n in rot_names if n in c)
    valid = c["valid"]
    bad = np.flatnonzero((valid != 0) & (valid != 1))
    if bad.size:
        raise InputError(
            f"column 'valid': expected 0 or 1, got {float(valid[bad[0]]):g}",
            path=path,
            line=int(lines[bad[0]]),
        )
    keep = valid == 1
    trans, rot = c["trans_error"][keep], c[rot_col][keep]
    empty = np.flatnonzero(np.isnan(trans) | np.isnan(rot))
    if empty.size:
        raise InputError(
            "a valid relation without an error value; expected numbers in trans_error and "
            f"{rot_col}",
            path=path,
            line=int(lines[keep][empty[0]]),
        )
    t1, t2 = c["t1"][keep], c["t2"][keep]
    k = np.char.add(np.char.add(t1.astype(str), " "), t2.astype(str))
    uniq, first, counts = np.unique(k, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = int(np.flatnonzero(k == uniq[counts > 1][0])[1])
        raise InputError(
            "a relation (t1, t2) appears twice; cannot pair relations",
            path=path,
            line=int(lines[keep][dup]),
        )
    return ResultErrors(dataset, algorithm, k, trans, rot, rot_col.removeprefix("rot_error_"))


@dataclass(frozen=True)
class PairTest:
    """Wilcoxon signed-rank test of two algorithms on the relations both scored."""

    dataset: str
    a: str
    b: str
    part: str
    n: int
    median_difference: float
    p_value: float
    p_holm: float
    significant: bool


@dataclass(frozen=True)
class Comparison:
    """Statistics per (dataset, algorithm) and pairwise tests per dataset."""

    stats: dict[tuple[str, str], dict[str, dict[str, Summary]]]
    tests: list[PairTest]
    alpha: float
    rotation_unit: str
    left_out: dict[tuple[str, str], int] = field(default_factory=dict)

    def rows(self) -> list[list[Any]]:
        """Table rows: dataset, algorithm, then mean and std of trans/rot abs/sqr, N."""
        out = []
        for (ds, alg), st in self.stats.items():
            row: list[Any] = [ds, alg]
            for part in ("translation", "rotation"):
                for kind in ("abs", "sqr"):
                    row += [st[part][kind].mean, st[part][kind].std]
            row.append(st["translation"]["abs"].count)
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

    def markdown(self) -> str:
        """The table and the tests as GitHub Markdown."""
        lines = ["| " + " | ".join(self.columns()) + " |", "|" + "---|" * len(self.columns())]
        for row in self.rows():
            lines.append("| " + " | ".join(_fmt(v) for v in row) + " |")
        dropped = {k: n for k, n in self.left_out.items() if n}
        if dropped:
            lines += [
                "",
                "Relations not scored by every algorithm of a dataset are left out of its "
                "statistics and tests: "
                + ", ".join(f"{ds}:{alg} {n}" for (ds, alg), n in dropped.items())
                + ".",
            ]
        lines += ["", f"Paired Wilcoxon signed-rank tests (Holm-adjusted, α = {self.alpha}):", ""]
        lines += [
            "| dataset | A | B | part | n | median(A − B) | p | p (Holm) | significant |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for t in self.tests:
            lines.append(
                f"| {t.dataset} | {t.a} | {t.b} | {t.part} | {t.n} | {t.median_difference:.4g} | "
                f"{t.p_value:.3g} | {t.p_holm:.3g} | {'yes' if t.significant else 'no'} |"
            )
        return "\n".join(lines) + "\n"

    def csv(self) -> str:
        """The statistics table as CSV."""
        buf = io.StringIO()
        buf.write(",".join(c.replace(",", ";") for c in self.columns()) + "\n")
        for row in self.rows():
            buf.write(",".join(_fmt(v) for v in row) + "\n")
        return buf.getvalue()

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
                f"${st[p][k].mean:.4g} \\pm {st[p][k].std:.4g}$"
                for p in ("translation", "rotation")
                for k in ("abs", "sqr")
            ]
            body.append(f"{_tex(ds)} & {_tex(alg)} & " + " & ".join(cells) + " \\\\")
        return head + "\n".join(body) + "\n\\hline\n\\end{tabular}\n"


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if not np.isfinite(v) else f"{v:.6g}"
    return str(v)


def _tex(s: str) -> str:
    return (
        s.replace("\\", "\\textbackslash{}")
        .replace("_", "\\_")
        .replace("&", "\\&")
        .replace("%", "\\%")
    )


def holm(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Holm–Bonferroni adjusted p-values (step-down, monotone, capped at 1)."""
    p = np.asarray(p, dtype=np.float64)
    m = p.size
    if m == 0:
        return p
    order = np.argsort(p)
    adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out


def compare_results(results: list[ResultErrors], *, alpha: float = 0.05) -> Comparison:
    """Statistics per result and paired tests between the algorithms of each dataset.

    Within a dataset every algorithm is scored on the *same* relations: those that all of
    its results contain (matched by ``(t1, t2)``). Relations that some result lacks (e.g.
    left unassociated there) are left out of every statistic and test of that dataset,
    counted in :attr:`Comparison.left_out` and named in a warning, so that means side by
    side are over one set.

    Raises
    ------
    InputError
        No results; ``alpha`` outside (0, 1); a result with no relations or a non-finite
        error; a (dataset, algorithm) given twice; rotation units mixed; a dataset whose
        results share no relation.
    """
    if not results:
        raise InputError("nothing to compare: give at least one result")
    if not (0.0 < alpha < 1.0):
        raise InputError(f"alpha must be a probability in (0, 1), got {float(alpha):g}")
    units = {r.rotation_unit for r in results}
    if len(units) != 1:
        raise InputError(
            f"results mix rotation units {sorted(units)}; evaluate all with or without --degrees"
        )
    seen: set[tuple[str, str]] = set()
    for r in results:
        key = (r.dataset, r.algorithm)
        if key in seen:
            raise InputError(f"{r.dataset}/{r.algorithm} is given twice")
        seen.add(key)
        _check_errors(r)
    results, left_out = _common_relations(results)
    stats: dict[tuple[str, str], dict[str, dict[str, Summary]]] = {}
    for r in results:
        stats[(r.dataset, r.algorithm)] = {
            "translation": {"abs": summarize(r.translation), "sqr": summarize(r.translation**2)},
            "rotation": {"abs": summarize(r.rotation), "sqr": summarize(r.rotation**2)},
        }
    tests: list[PairTest] = []
    for ds in dict.fromkeys(r.dataset for r in results):
        group = [r for r in results if r.dataset == ds]
        raw: list[tuple[str, str, str, int, float, float]] = []
        for a, b in itertools.combinations(group, 2):
            common, ia, ib = np.intersect1d(a.keys, b.keys, return_indices=True)
            for part in ("translation", "rotation"):
                da = getattr(a, part)[ia] - getattr(b, part)[ib]
                if common.size < 2 or np.all(da == 0):
                    p = 1.0
                else:
                    p = float(wilcoxon(getattr(a, part)[ia], getattr(b, part)[ib]).pvalue)
                med = float(np.median(da)) if da.size else float("nan")
                raw.append((a.algorithm, b.algorithm, part, int(common.size), med, p))
        adj = holm(np.array([x[5] for x in raw]))
        for (a_name, b_name, part, n, med, p), ph in zip(raw, adj):
            tests.append(PairTest(ds, a_name, b_name, part, n, med, p, float(ph), bool(ph < alpha)))
    return Comparison(stats, tests, alpha, units.pop(), left_out)


def _check_errors(r: ResultErrors) -> None:
    if r.keys.size == 0:
        raise InputError(
            f"{r.dataset}:{r.algorithm}: no scored relations (all invalid or none); nothing to "
            "compare",
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
        common = group[0].keys
        for r in group[1:]:
            common = np.intersect1d(common, r.keys, assume_unique=True)
        if common.size == 0:
            raise InputError(
                f"dataset {ds}: the results share no relation (t1, t2) ("
                + ", ".join(r.name for r in group)
                + "); were they evaluated on the same relations?"
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
