"""The ``slamrel run`` page as a typed report: named sections and figures, and every number
shown equal to ``metrics.json`` (the file the tables are meant to mirror)."""

from __future__ import annotations

import base64
import html.parser
import json
from pathlib import Path
from typing import Any

import pytest

from slamrel.cli import main
from slamrel.runs.result import RunResult


class _Page(html.parser.HTMLParser):
    """Section headings, tables (caption → rows of cell texts) and embedded images."""

    def __init__(self) -> None:
        super().__init__()
        self.headings: list[str] = []
        self.tables: dict[str, list[list[str]]] = {}
        self.images: list[bytes] = []
        self._tag: str | None = None
        self._caption = ""
        self._row: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self._tag = tag
        if tag == "tr":
            self._row = []
        elif tag == "td" and self._row is not None:
            self._row.append("")
        elif tag == "img":
            src = dict(attrs)["src"] or ""
            self.images.append(base64.b64decode(src.split(",", 1)[1]))

    def handle_endtag(self, tag: str) -> None:
        if tag == "tr" and self._row:
            self.tables.setdefault(self._caption, []).append(self._row)
        if tag == "tr":
            self._row = None
        self._tag = None

    def handle_data(self, data: str) -> None:
        if self._tag == "h2":
            self.headings.append(data)
        elif self._tag == "caption":
            self._caption = data
        elif self._tag == "td" and self._row is not None:
            self._row[-1] += data


@pytest.fixture(scope="module")
def report(broken_run: Any) -> tuple[Path, _Page, dict[str, Any]]:
    """One run with a broken map (stretches), through the CLI (conftest's ``broken_run``)."""
    out = broken_run.folder
    page = _Page()
    page.feed((out / "report.html").read_text())
    return out, page, json.loads((out / "metrics.json").read_text())


def _num(cell: str) -> float:
    return float(cell.replace("−", "-").replace("∞", "inf"))


def _close(cell: str, value: float) -> bool:
    """A cell shows ``value`` to 3 significant digits (whole numbers from 1000 on)."""
    return _num(cell) == pytest.approx(value, rel=5e-3, abs=1e-12 if value == 0 else 0.5e-3)


def test_sections_in_order(report: tuple[Path, _Page, dict[str, Any]]) -> None:
    _, page, _ = report
    # h2 texts: the verdict's heading, the contents, then the four sections
    sections = page.headings[page.headings.index("Contents") + 1 :]
    assert sections == ["slamrel run: simple1/a/seed 0", "Consistency", "Map–log agreement", "Map"]


def test_figures_are_the_files_in_order(report: tuple[Path, _Page, dict[str, Any]]) -> None:
    out, page, _ = report
    files = sorted(out.glob("figure_*.png"), key=lambda p: int(p.stem.split("_")[1]))
    assert len(files) == 4  # trajectories, errors, NEES, map
    assert [p.read_bytes() for p in files] == page.images


def test_nees_nis_and_stretch_tables_equal_metrics(
    report: tuple[Path, _Page, dict[str, Any]],
) -> None:
    _, page, m = report
    nees = page.tables["NEES (3 dof) of the pose estimates"]
    placed = "recovered, in the map's frame"  # metrics.json nees_map_placement.recovered
    assert [row[0] for row in nees] == [*m["nees"], placed]
    for row in nees:
        n = m["nees_map_placement"]["recovered"] if row[0] == placed else m["nees"][row[0]]
        assert _close(row[1], n["mean"]) and _close(row[2], n["band"][0])
        assert _close(row[3], n["band"][1]) and _close(row[4], n["inside"])
    (nis_row,) = page.tables["NIS of the recovery's innovations (2 dof)"]
    nis = m["recovery"]["nis"]
    assert int(nis_row[0]) == nis["count"] and _close(nis_row[1], nis["mean"])
    assert _close(nis_row[2], nis["median"]) and _close(nis_row[4], nis["fraction_beyond_95"])
    stretches = m["divergence"]["stretches"]
    rows = page.tables["stretches where the map and the log disagree"]
    assert len(rows) == min(len(stretches), 50) >= 1
    t0 = m["time_base"]["t0"]  # the page's times are seconds since the run's start
    for row, s in zip(rows, stretches):
        a, b = row[0].removesuffix(" s").split("–")
        assert float(a) == pytest.approx(s["t0"] - t0, abs=0.051)
        assert float(b) == pytest.approx(s["t1"] - t0, abs=0.051)
        assert _close(row[1], s["duration"])
        assert [int(row[k]) for k in (2, 3, 6)] == [
            s["measurements"],
            s["outlying"],
            s["reentries"],
        ]
    assert len({row[0] for row in rows}) == len(rows)  # no two intervals print alike


def _key_paths(node: object, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """The path of every key of every dict in a JSON tree (list items add no step)."""
    out: list[tuple[str, ...]] = []
    if isinstance(node, dict):
        for k, v in node.items():
            out += [(*path, k), *_key_paths(v, (*path, k))]
    elif isinstance(node, list):
        for v in node:
            out += _key_paths(v, path)
    return out


def test_each_nees_and_divergence_key_is_written_once(
    report: tuple[Path, _Page, dict[str, Any]],
) -> None:
    _, _, m = report
    paths = _key_paths(m)
    for key in (
        "nees", "nees_frame", "nees_truth_frame", "nees_map_placement", "divergence",
        "nees_stretches",
    ):  # fmt: skip
        assert [p for p in paths if p[-1] == key] == [
            ("divergence", key) if key == "nees_stretches" else (key,)
        ], key
    # no other key of the file is named after the NEES
    assert {p for p in paths if "nees" in p[-1]} == {
        ("nees",), ("nees_frame",), ("nees_truth_frame",), ("nees_map_placement",),
        ("nees_map_placement", "placement", "rigid_nees"),  # the placement's own, 3 dof
        ("divergence", "nees_stretches"),
        ("divergence", "nees_stretches", "nees_max"),  # the blow-ups (this run has some)
    }  # fmt: skip


@pytest.mark.slow
def test_one_nees_per_estimate_the_one_the_page_shows(
    report: tuple[Path, _Page, dict[str, Any]], tmp_path: Path
) -> None:
    """metrics.json's NEES of each estimate is the page's, and the recovered one is the NEES
    of the trajectory and covariances ``slamrel recover`` writes for the same bundle, computed
    here pose by pose against groundtruth.csv with the prior (the first pose) left out."""
    import numpy as np

    out, page, m = report
    rows = page.tables["NEES (3 dof) of the pose estimates"]
    placed = "recovered, in the map's frame"  # the verdict's, nees_map_placement
    assert sorted(m["nees"]) == sorted(row[0] for row in rows if row[0] != placed)
    assert sorted(m["nees"]) == ["online", "recovered"]
    for row in rows:
        if row[0] == placed:
            assert _close(row[1], m["nees_map_placement"]["recovered"]["mean"])
            continue
        assert _close(row[1], m["nees"][row[0]]["mean"])
        assert _close(row[5], m["nees_truth_frame"][row[0]]["mean"])
    traj, cov, rep = tmp_path / "t.txt", tmp_path / "c.npy", tmp_path / "r.json"
    argv = ["recover", str(out / "bundle"), "-o", str(traj), "--covariances", str(cov)]
    assert main([*argv, "--report", str(rep), "-q"]) == 0
    est, covs = np.loadtxt(traj), np.load(cov)
    truth = np.loadtxt(out / "bundle" / "groundtruth.csv", delimiter=",", skiprows=1)
    values = []
    for k in range(1, est.shape[0]):  # 0: the prior
        j = int(np.argmin(np.abs(truth[:, 0] - est[k, 0])))
        if abs(truth[j, 0] - est[k, 0]) > 1e-6:  # no ground truth at this pose
            continue
        e = truth[j, 1:4] - est[k, 1:4]
        e[2] = np.arctan2(np.sin(e[2]), np.cos(e[2]))
        values.append(e @ np.linalg.solve(covs[k], e))
    assert m["nees_frame"]["anchoring"] is None  # the truth frame: nothing to place
    assert m["nees"]["recovered"]["mean"] == pytest.approx(np.mean(values), rel=1e-9)
    assert json.loads(rep.read_text())["nees"] == m["nees"]["recovered"]


def test_map_tables_equal_metrics(report: tuple[Path, _Page, dict[str, Any]]) -> None:
    _, page, m = report
    mp = m["map"]
    edge, corner = page.tables["landmark-map relation errors"]
    for row, part in ((edge, "translation"), (corner, "rotation")):
        s = mp[part]["abs"]
        assert all(_close(c, s[k]) for c, k in zip(row[1:4], ("mean", "std", "max")))
        assert int(row[4]) == s["count"]
    (assoc,) = page.tables["association and set distances"]
    a = mp["association"]
    counts = [a["matched"], a["missed"], a["unobserved"], a["spurious"]]
    assert [int(c) for c in assoc[:4]] == counts
    assert _close(assoc[4], mp["ospa"]["value"]) and _close(assoc[5], mp["gospa"]["value"])
    assert _close(assoc[6], mp["ospa"]["c"]) and _close(assoc[7], mp["ospa"]["p"])


@pytest.fixture(scope="module")
def rescored(report: tuple[Path, _Page, dict[str, Any]]) -> tuple[Any, Any]:
    """The report's bundle read back and scored again by ``run_pipeline``, with the readers
    made to fail while it runs: (the RunInput, the RunResult)."""
    import slamrel.pipeline as pipeline

    out, _, _ = report
    inp = pipeline.read_run_input(out / "bundle")  # the report's bundle: map + ground truth

    def no_io(*a: object, **k: object) -> None:
        raise AssertionError("run_pipeline read a file")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "read_bundle", no_io)
        mp.setattr(pipeline, "read_online", no_io)
        return inp, pipeline.run_pipeline(inp)


def test_result_holds_the_map_once_and_reads_nothing(
    report: tuple[Path, _Page, dict[str, Any]], rescored: tuple[Any, Any]
) -> None:
    """``run_pipeline`` on a RunInput does no I/O; the map JSON is derived from the comparison."""
    from slamrel.report.run_page import RunSections

    _, _, m = report
    inp, result = rescored
    assert inp.bundle.groundtruth is not None and inp.online is None
    assert result.map == result.map_comparison.as_dict()  # type: ignore[union-attr]
    assert "map" not in {f.name for f in RunResult.__dataclass_fields__.values()}
    # the same bundle scored again: the same map numbers as the first report
    assert result.metrics()["map"] == m["map"]
    assert set(RunSections._fields) == {"summary", "consistency", "agreement", "map"}
    # typed access: the recovered scores by attribute, the same numbers metrics.json holds
    rec = result.recovered
    assert rec is not None and rec is result.evaluations["recovered"]
    assert result.main_estimate == "recovered" and result.online is None
    assert rec.sets == tuple(m["trajectory"]["by_relation_set"]) and list(rec)[0] == "all"
    assert rec.all.translation.abs.mean == m["trajectory"]["translation"]["abs"]["mean"]
    loops = m["trajectory"]["by_relation_set"]["loops"]
    assert rec["loops"].rotation.sqr.mean == loops["rotation"]["sqr"]["mean"]


def test_verdict_reads_the_numbers_metrics_holds(rescored: tuple[Any, Any]) -> None:
    """The verdict judges the typed results; each is the number ``metrics.json`` writes."""
    from slamrel.report.verdict import RunFacts

    _, result = rescored
    m = json.loads(json.dumps(result.metrics()))
    f = RunFacts.of(result)
    assert f.main == m["trajectory_source"] == "recovered"
    for name, err in f.translation_errors.items():
        key = "trajectory" if name == f.main else name
        assert err == m[key]["translation"]["abs"]["mean"]
    # the evidence counts the relations scored, and the unassociated ones beside them
    assert f.relations == m["trajectory"]["translation"]["abs"]["count"]
    assert f.relations + f.unassociated == m["trajectory"]["relations"]
    assert f.unassociated == m["trajectory"]["unassociated"]
    # the recovered consistency is judged in the map's frame when it is defined
    placed = m.get("nees_map_placement")
    judged = m["nees"]["recovered"] if placed is None else placed["recovered"]
    assert f.nees is not None and f.nees.as_dict() == judged
    assert f.counts is not None and f.counts.as_dict() == m["recovery"]["measurements"]
    assert f.poses == m["recovery"]["poses"]
    mp, ms = m["map"], f.map
    assert ms is not None
    assert ms.edge.as_dict() == mp["translation"]["abs"]
    assert ms.corner.as_dict() == mp["rotation"]["abs"]
    a = mp["association"]
    assert (ms.matched, ms.missed, ms.spurious) == (a["matched"], a["missed"], a["spurious"])
    assert (ms.ospa, ms.gospa) == (mp["ospa"]["value"], mp["gospa"]["value"])
    assert (ms.cutoff, ms.order) == (mp["ospa"]["c"], mp["ospa"]["p"])
