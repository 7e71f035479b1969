"""Held-out audit of issue 39's classes: other variants thrown at every reader and command.

Each case writes its input files into a fresh folder, runs ``python -m slamrel ARGV`` there
and judges the outcome:

- ``score``: exit 0 (and, where given, a value checked against a hand computation);
- ``error``: exit 3, the message names the file (and ``FILE:LINE`` when a line is given);
- ``option``: exit 2;
- ``either``: a score (exit 0) or an error naming the file (exit 3): odd input whose
  refusal and acceptance are both defensible, as long as nothing is silent or broken.

Always wrong: a traceback, "internal error", slamrel's own "floating-point problem … bug"
warning, a timeout, an exit code outside the expectation.

Usage: python audit.py [--only SUBSTRING] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(os.environ.get("SLAMREL_REPO", Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # tests/test_bags.py imports conftest

BAD = ("Traceback", "internal error", "floating-point problem", "bug in slamrel")


@dataclass
class Case:
    cls: str
    name: str
    files: dict[str, Any]
    argv: list[str]
    expect: str  # score | error | option | either
    where: str | None = None  # file (relative) the error must name; "F:L" with a line
    check: Callable[[Path, str, str], str | None] | None = None
    pre: list[list[str]] = field(default_factory=list)
    mutate: Callable[[Path], None] | None = None
    says: tuple[str, ...] = ()  # substrings stderr+stdout must hold


CASES: list[Case] = []


def case(*a: Any, **k: Any) -> None:
    CASES.append(Case(*a, **k))


# ------------------------------------------------------------------------------ inputs

PLAIN = "".join(f"{k} {k * 1.0} 0 0\n" for k in range(6))


def plain_shift(dx: float, k0: int = 3) -> str:
    """PLAIN with pose k0 moved by dx along x: consecutive relations k0-1→k0 and k0→k0+1
    get a translational error of |dx| each, the others 0."""
    return "".join(f"{k} {k * 1.0 + (dx if k == k0 else 0)} 0 0\n" for k in range(6))


def tum(rows: list[tuple[float, float]]) -> str:
    return "".join(f"{t} {x} 0 0 0 0 0 1\n" for t, x in rows)


TUM_REF = tum([(k, k) for k in range(10)])
TUM_EST = tum([(k, k + 1.0) for k in range(10)])  # 1 m off everywhere: APE (no align) = 1


def json_out(key: str, want: float, path: str = "o.json", tol: float = 1e-9):
    def check(d: Path, out: str, err: str) -> str | None:
        try:
            doc = json.loads((d / path).read_text())
        except Exception as exc:  # noqa: BLE001
            return f"no json: {exc}"
        v: Any = doc
        for part in key.split("."):
            v = v[part] if not isinstance(v, list) else v[int(part)]
        if not (isinstance(v, int | float) and math.isclose(v, want, rel_tol=tol, abs_tol=tol)):
            return f"{key} = {v!r}, expected {want!r}"
        return None

    return check


def ape_rmse(want: float):
    def check(d: Path, out: str, err: str) -> str | None:
        for line in out.splitlines():
            if line.strip().startswith("rmse"):
                got = float(line.split()[-1])
                return None if math.isclose(got, want, rel_tol=1e-6) else f"rmse {got}"
        return "no rmse printed"

    return check


# ---- graphs
G2O = (
    "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
    "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\n"
)
TORO = (
    "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX2 2 2 0 0\n"
    "EDGE2 0 1 1 0 0 1 0 1 1 0 0\nEDGE2 1 2 1 0 0 1 0 1 1 0 0\n"
)
SQ = "1 0 0 1 0 1"
ISAM = f"ODOMETRY 0 1 1 0 0 {SQ}\nODOMETRY 1 2 1 0 0 {SQ}\n"


def graph_cases() -> None:
    case("graph", "g2o valid solve", {"g.g2o": G2O}, ["solve", "g.g2o", "-o", "out", "-q"], "score")
    case(
        "graph",
        "toro valid solve",
        {"g.graph": TORO},
        ["solve", "g.graph", "-o", "out", "-q"],
        "score",
    )
    case(
        "graph", "isam valid solve", {"g.txt": ISAM}, ["solve", "g.txt", "-o", "out", "-q"], "score"
    )
    bad_ids = {"3.5": "error", "1e20": "error", "1e2": "either", "2.0": "either", "0x2": "error",
               "nan": "error", "inf": "error", "-1": "either", "+2": "either", "002": "either",
               "99999999999999999999999": "error", "": "error", "a": "error"}  # fmt: skip
    for vid, exp in bad_ids.items():
        g = G2O.replace("VERTEX_SE2 2 2 0 0", f"VERTEX_SE2 {vid} 2 0 0").replace(
            "EDGE_SE2 1 2", f"EDGE_SE2 1 {vid}"
        )
        case("graph", f"g2o vertex id {vid!r}", {"g.g2o": g},
             ["solve", "g.g2o", "-o", "out", "-q"], exp, where="g.g2o:3" if exp == "error" else "g.g2o")  # fmt: skip
        t = TORO.replace("VERTEX2 2 2 0 0", f"VERTEX2 {vid} 2 0 0").replace(
            "EDGE2 1 2", f"EDGE2 1 {vid}"
        )
        case("graph", f"toro vertex id {vid!r}", {"g.graph": t},
             ["solve", "g.graph", "-o", "out", "-q"], exp, where="g.graph:3" if exp == "error" else "g.graph")  # fmt: skip
        if vid:
            i = ISAM.replace("ODOMETRY 1 2", f"ODOMETRY 1 {vid}")
            case("graph", f"isam pose id {vid!r}", {"g.txt": i},
                 ["solve", "g.txt", "-o", "out", "-q"], exp, where="g.txt:2" if exp == "error" else "g.txt")  # fmt: skip
    # -0: the integer 0 written with a sign; together with 0 it repeats the id
    for name, text, f in (
        ("g2o", G2O + "VERTEX_SE2 -0 5 5 0\n", "g.g2o"),
        ("toro", TORO + "VERTEX2 -0 5 5 0\n", "g.graph"),
    ):
        case(
            "graph",
            f"{name} vertex -0 repeats 0",
            {f: text},
            ["solve", f, "-o", "out", "-q"],
            "error",
            where=f"{f}:6",
        )
    case("graph", "g2o duplicate vertex", {"g.g2o": G2O + "VERTEX_SE2 1 7 7 0\n"},
         ["solve", "g.g2o", "-o", "out", "-q"], "error", where="g.g2o:6")  # fmt: skip
    case("graph", "toro duplicate vertex", {"g.graph": TORO + "VERTEX2 1 7 7 0\n"},
         ["solve", "g.graph", "-o", "out", "-q"], "error", where="g.graph:6")  # fmt: skip
    case("graph", "g2o edge to missing id", {"g.g2o": G2O + "EDGE_SE2 2 9 1 0 0 1 0 0 1 0 1\n"},
         ["solve", "g.g2o", "-o", "out", "-q"], "error", where="g.g2o:6")  # fmt: skip
    case("graph", "toro edge to missing id", {"g.graph": TORO + "EDGE2 2 9 1 0 0 1 0 1 1 0 0\n"},
         ["solve", "g.graph", "-o", "out", "-q"], "error", where="g.graph:6")  # fmt: skip
    big = 2**60
    case("graph", "toro edge to missing id near 2^60",
         {"g.graph": TORO.replace("VERTEX2 2 2 0 0", f"VERTEX2 {big + 1} 2 0 0").replace("EDGE2 1 2", f"EDGE2 1 {big + 1}") + f"EDGE2 0 {big} 1 0 0 1 0 1 1 0 0\n"},
         ["solve", "g.graph", "-o", "out", "-q"], "error", where="g.graph:6")  # fmt: skip
    case("graph", "g2o edge to missing id near 2^60",
         {"g.g2o": G2O.replace("VERTEX_SE2 2 2 0 0", f"VERTEX_SE2 {big + 1} 2 0 0").replace("EDGE_SE2 1 2", f"EDGE_SE2 1 {big + 1}") + f"EDGE_SE2 0 {big} 1 0 0 1 0 0 1 0 1\n"},
         ["solve", "g.g2o", "-o", "out", "-q"], "error", where="g.g2o:6")  # fmt: skip
    case("graph", "g2o vertex x 1e20", {"g.g2o": G2O.replace("VERTEX_SE2 2 2 0 0", "VERTEX_SE2 2 1e20 0 0")},
         ["solve", "g.g2o", "-o", "out", "-q"], "either", where="g.g2o")  # fmt: skip
    case("graph", "g2o vertex x 1e31", {"g.g2o": G2O.replace("VERTEX_SE2 2 2 0 0", "VERTEX_SE2 2 1e31 0 0")},
         ["solve", "g.g2o", "-o", "out", "-q"], "error", where="g.g2o:3")  # fmt: skip
    case("graph", "toro vertex nan", {"g.graph": TORO.replace("VERTEX2 2 2 0 0", "VERTEX2 2 nan 0 0")},
         ["solve", "g.graph", "-o", "out", "-q"], "error", where="g.graph:3")  # fmt: skip
    case("graph", "g2o edge info 1e300", {"g.g2o": G2O.replace("1 0 0 1 0 1\nEDGE_SE2 1 2", "1e300 0 0 1e300 0 1e300\nEDGE_SE2 1 2")},
         ["solve", "g.g2o", "-o", "out", "-q"], "error", where="g.g2o:4")  # fmt: skip
    # the trajectory reader of g2o files (evaluate): same id rule
    case("graph", "evaluate g2o vertex 3.5",
         {"g.g2o": G2O.replace("VERTEX_SE2 2 2 0 0", "VERTEX_SE2 3.5 2 0 0"), "r.txt": PLAIN},
         ["evaluate", "r.txt", "g.g2o", "-q"], "error", where="g.g2o:3")  # fmt: skip
    case("graph", "evaluate toro vertex 1e20",
         {"g.graph": TORO.replace("VERTEX2 2 2 0 0", "VERTEX2 1e20 2 0 0"), "r.txt": PLAIN},
         ["evaluate", "r.txt", "g.graph", "-q"], "error", where="g.graph")  # fmt: skip


# ---- relations from-graph
def loop_graph() -> str:
    """A square of side 50 m driven twice (8 × 25 m steps a lap, 16 poses, ids 0..16),
    vertices exact, odometry edges and loop closures 8 apart that agree exactly."""
    import numpy as np

    pts = []
    for k in range(17):
        s = (k % 8) * 25.0
        side, off = divmod(s, 50.0)
        side = int(side)
        xy = [(off, 0.0), (50.0, off), (50.0 - off, 50.0), (0.0, 50.0 - off)][side]
        pts.append((xy[0], xy[1], side * np.pi / 2))
    lines = [f"VERTEX_SE2 {k} {x:.12g} {y:.12g} {th:.12g}" for k, (x, y, th) in enumerate(pts)]
    from relation_metric import se2

    p = np.array(pts)
    for a, b in [(k, k + 1) for k in range(16)] + [(k, k + 8) for k in range(9)]:
        d = se2.between(p[a], p[b])
        lines.append(f"EDGE_SE2 {a} {b} {d[0]:.12g} {d[1]:.12g} {d[2]:.12g} 1 0 0 1 0 1")
    return "\n".join(lines) + "\n"


def from_graph_cases() -> None:
    g = loop_graph()
    base = ["relations", "from-graph", "g.g2o", "-o", "o.relations", "-q"]

    def n_relations(want: int):
        def check(d: Path, out: str, err: str) -> str | None:
            rows = [
                ln
                for ln in (d / "o.relations").read_text().splitlines()
                if ln and not ln.startswith("#")
            ]
            return None if len(rows) == want else f"{len(rows)} relations, expected {want}"

        return check

    # loops k -> k+8 travel 200 m: all 9 kept with --min-travel 100
    case("from-graph", "valid square", {"g.g2o": g}, base, "score", check=n_relations(9))
    case(
        "from-graph",
        "min-travel 250 keeps none",
        {"g.g2o": g},
        [*base, "--min-travel", "250"],
        "either",
        where="g.g2o",
    )
    for opt in ("--min-travel", "--max-error-xy", "--max-error-theta"):
        for v in ("-1", "nan", "inf", "1e300", "0"):
            case("from-graph", f"{opt} {v}", {"g.g2o": g}, [*base, opt, v], "optionish")
    times = "".join(f"{100 + k}\n" for k in range(17))
    case(
        "from-graph",
        "times valid",
        {"g.g2o": g, "t.txt": times},
        [*base, "--times", "t.txt"],
        "score",
        check=n_relations(9),
    )
    case(
        "from-graph",
        "times nan",
        {"g.g2o": g, "t.txt": times.replace("105\n", "nan\n")},
        [*base, "--times", "t.txt"],
        "error",
        where="t.txt:6",
    )
    case(
        "from-graph",
        "times short",
        {"g.g2o": g, "t.txt": times.replace("116\n", "")},
        [*base, "--times", "t.txt"],
        "error",
        where="t.txt",
    )
    case(
        "from-graph",
        "times decreasing",
        {"g.g2o": g, "t.txt": times.replace("105\n", "99\n")},
        [*base, "--times", "t.txt"],
        "error",
        where="t.txt:6",
    )
    case(
        "from-graph",
        "times 1e300",
        {"g.g2o": g, "t.txt": times.replace("116\n", "1e300\n")},
        [*base, "--times", "t.txt"],
        "either",
        where="t.txt",
    )
    case(
        "from-graph",
        "graph id 3.5",
        {"g.g2o": g.replace("VERTEX_SE2 3 ", "VERTEX_SE2 3.5 ")},
        base,
        "error",
        where="g.g2o:4",
    )
    case("from-graph", "toro graph id 1e20", {"g.graph": TORO.replace("VERTEX2 2 2 0 0", "VERTEX2 1e20 2 0 0")},
         ["relations", "from-graph", "g.graph", "-o", "o.relations", "-q"], "error", where="g.graph:3")  # fmt: skip


# ---- CARMEN laser logs
def room_ranges(x: float, y: float, th: float, n: int = 181) -> list[float]:
    """Ranges of a 181-beam scan (−90°…+90°) in the room [−5, 15] × [−3, 4]."""
    out = []
    for i in range(n):
        a = th - math.pi / 2 + math.pi * i / (n - 1)
        c, s = math.cos(a), math.sin(a)
        best = 1e9
        for wall, lo, hi, vertical in (
            (15, -3, 4, True),
            (-5, -3, 4, True),
            (4, -5, 15, False),
            (-3, -5, 15, False),
        ):
            if vertical and abs(c) > 1e-12:
                t = (wall - x) / c
                if t > 0 and lo <= y + t * s <= hi:
                    best = min(best, t)
            if not vertical and abs(s) > 1e-12:
                t = (wall - y) / s
                if t > 0 and lo <= x + t * c <= hi:
                    best = min(best, t)
        # a pillar at (4, 1.5) for features
        out.append(min(best, 50.0))
    return out


def carmen(
    poses: list[tuple[float, float, float, float]], *, override: dict[int, str] | None = None
) -> str:
    lines = []
    for k, (t, x, y, th) in enumerate(poses):
        r = " ".join(f"{v:.3f}" for v in room_ranges(x, y, th))
        line = f"FLASER 181 {r} {x} {y} {th} {x} {y} {th} {t} host {t}"
        lines.append((override or {}).get(k, line))
    return "\n".join(lines) + "\n"


LOG_POSES = [(10.0 + 0.5 * k, 0.3 * k, 0.0, 0.0) for k in range(12)]


def laser_cases() -> None:
    base = ["relations", "align", "log.clf", "-o", "o.relations", "-q"]
    good = carmen(LOG_POSES)
    case("laser", "valid log", {"log.clf": good}, base, "score")

    def swap(a: int, b: int) -> str:
        p = list(LOG_POSES)
        p[a], p[b] = p[b], p[a]
        return carmen(p)

    case(
        "laser",
        "out of order by 0.5 s",
        {"log.clf": swap(4, 5)},
        base,
        "either",
        where="log.clf",
        says=("order",),
    )
    case(
        "laser",
        "out of order by 3 s",
        {"log.clf": swap(2, 8)},
        base,
        "either",
        where="log.clf",
        says=("order",),
    )
    r = " ".join(["1.0"] * 181)
    for name, line, exp in (
        ("pose x 1e20", f"FLASER 181 {r} 1e20 0 0 1e20 0 0 12 host 12", "error"),
        ("pose x 1e31", f"FLASER 181 {r} 1e31 0 0 1e31 0 0 12 host 12", "error"),
        ("pose theta 1e20", f"FLASER 181 {r} 1 0 1e20 1 0 1e20 12 host 12", "either"),
        ("pose nan", f"FLASER 181 {r} nan 0 0 nan 0 0 12 host 12", "either"),
        ("time nan", f"FLASER 181 {r} 1 0 0 1 0 0 nan host nan", "either"),
        ("time inf", f"FLASER 181 {r} 1 0 0 1 0 0 inf host inf", "either"),
        ("time 1e300", f"FLASER 181 {r} 1 0 0 1 0 0 1e300 host 1e300", "either"),
        ("empty ranges", "FLASER 0 1 0 0 1 0 0 12 host 12", "either"),
        ("range nan", f"FLASER 181 nan {' '.join(['1.0'] * 180)} 1 0 0 1 0 0 12 host 12", "either"),
        ("range -1", f"FLASER 181 -1 {' '.join(['1.0'] * 180)} 1 0 0 1 0 0 12 host 12", "either"),
        (
            "range 1e300",
            f"FLASER 181 1e300 {' '.join(['1.0'] * 180)} 1 0 0 1 0 0 12 host 12",
            "either",
        ),
        ("count -3", "FLASER -3 1 0 0 1 0 0 12 host 12", "error"),
        ("count 1e20", "FLASER 1e20 1 0 0 1 0 0 12 host 12", "error"),
        ("count 2.5", "FLASER 2.5 1 1 1 0 0 1 0 0 12 host 12", "error"),
        ("count too big", "FLASER 181 1 2 3", "error"),
    ):
        case("laser", name, {"log.clf": carmen(LOG_POSES, override={4: line})}, base, exp,
             where="log.clf:5" if exp == "error" else "log.clf")  # fmt: skip
    case("laser", "traj info of a 1e20 pose", {"log.clf": carmen(LOG_POSES, override={4: f"FLASER 181 {r} 1e20 0 0 1e20 0 0 12 host 12"})},
         ["traj", "info", "log.clf"], "either", where="log.clf")  # fmt: skip
    case("laser", "one pose 300 m off (estimate)", {"log.clf": good, "est.txt": "".join(f"{t} {x + (300 if k == 6 else 0)} {y} {th}\n" for k, (t, x, y, th) in enumerate(LOG_POSES))},
         [*base, "--estimate", "est.txt"], "either", where="est.txt")  # fmt: skip
    for opt in (
        "--search-xy",
        "--search-theta",
        "--ambiguity",
        "--drift-xy",
        "--drift-theta",
        "--max-correction",
        "--max-range",
        "--time-tolerance",
        "--distance",
        "--angle",
    ):
        for v in ("0", "-1", "nan", "inf", "1e300"):
            case(
                "laser-opts",
                f"global {opt} {v}",
                {"log.clf": good},
                [*base, "--aligner", "global", opt, v],
                "optionish",
            )


# ---- bags
def bag_cases() -> None:
    try:
        import numpy as np
        import rosbags  # noqa: F401
    except ImportError:
        return

    def build(storage: str, name: str, edit: Callable[[dict], None]):
        def make(d: Path) -> None:
            from tests.test_bags import _truth, _write

            truth = _truth(np.random.default_rng(0))
            edit(truth)
            _write(d / name, storage, truth)

        return make

    def setx(v: float, col: int = 0, k: int = 5):
        def edit(t: dict) -> None:
            t["xyz"][k, col] = v

        return edit

    def setq(v: list[float], k: int = 5):
        def edit(t: dict) -> None:
            t["q"][k] = v

        return edit

    for storage, name in (("ros1", "r.bag"), ("sqlite3", "r_db3"), ("mcap", "r_mcap")):
        for label, edit, exp in (
            ("valid", lambda t: None, "score"),
            ("x nan", setx(float("nan")), "error"),
            ("z inf", setx(float("inf"), 2), "error"),
            ("x 1e31", setx(1e31), "error"),
            ("quaternion zero", setq([0, 0, 0, 0]), "error"),
            ("quaternion nan", setq([float("nan"), 0, 0, 1]), "error"),
        ):
            case("bag", f"{storage} {label}", {}, ["evaluate", f"{name}:/pose", f"{name}:/posecov", "-q"], exp,
                 where=name, mutate=build(storage, name, edit))  # fmt: skip
        case("bag", f"{storage} undecodable", {}, ["evaluate", f"{name}:/pose", f"{name}:/posecov", "-q"], "error",
             where=name, mutate=corrupt(storage, name))  # fmt: skip
        case("bag", f"{storage} ape undecodable", {}, ["ape", "bag" if storage == "ros1" else "bag2", name, "/pose", "/posecov"], "error",
             where=name, mutate=corrupt(storage, name))  # fmt: skip


def corrupt(storage: str, name: str):
    """The bag of ``tests/test_bags.py``'s writer with /pose message 4 cut to 7 bytes (it
    cannot deserialize): the writer's ``write`` wrapped, nothing else copied."""

    def make(d: Path) -> None:
        import numpy as np

        import tests.test_bags as tb

        kept = (tb.Writer1, tb.Writer2)

        def cut(base: type) -> type:
            class Cut(base):  # type: ignore[misc, valid-type]
                def write(self, conn: Any, stamp: int, data: bytes) -> None:
                    if conn.topic == "/pose" and stamp == 4 * 10**9:
                        data = bytes(data[:7])
                    super().write(conn, stamp, data)

            return Cut

        tb.Writer1, tb.Writer2 = cut(kept[0]), cut(kept[1])
        try:
            tb._write(d / name, storage, tb._truth(np.random.default_rng(0)))
        finally:
            tb.Writer1, tb.Writer2 = kept

    return make


# ---- bundles
def bundle_files(**over: Any) -> dict[str, Any]:
    from tests.test_readers_fuzz import BUNDLE, BUNDLE_JSON

    files = {f"b/{k}": v for k, v in BUNDLE.items()}
    if "manifest" in over:
        m = json.loads(BUNDLE_JSON)
        over.pop("manifest")(m)
        files["b/bundle.json"] = json.dumps(m, indent=2) + "\n"
    for k, v in over.items():
        files[f"b/{k}"] = v
    return {k: v for k, v in files.items() if v is not None}


def bundle_cases() -> None:
    rec = ["recover", "b", "-o", "x.txt", "-q"]
    case("bundle", "valid", bundle_files(), rec, "score")

    # step_covariance.csv
    def step_model(m: dict) -> None:
        m["motion_model"] = {"type": "velocity", "step_covariance": {"frame": "body"}}

    sc_head = "t,cxx,cxy,cxt,cyy,cyt,ctt\n"
    sc_ok = "".join(f"{t},0.01,0,0,0.01,0,0.001\n" for t in range(4))
    case(
        "bundle",
        "step_covariance valid",
        bundle_files(manifest=step_model, **{"step_covariance.csv": sc_head + sc_ok}),
        rec,
        "score",
    )
    case(
        "bundle",
        "step_covariance missing",
        bundle_files(manifest=step_model),
        rec,
        "error",
        where="b/step_covariance.csv",
    )
    for label, rows, line in (
        ("nan", sc_ok.replace("1,0.01", "1,nan"), 3),
        ("1e300", sc_ok.replace("1,0.01", "1,1e300"), 3),
        ("non-psd", sc_ok.replace("2,0.01,0,0,0.01", "2,0.01,5,0,0.01"), 4),
        ("other time", sc_ok.replace("2,0.01", "2.5,0.01"), 4),
        ("short", sc_ok.rsplit("3,", 1)[0], None),
        ("negative", sc_ok.replace("1,0.01", "1,-0.01"), 3),
    ):
        case("bundle", f"step_covariance {label}", bundle_files(manifest=step_model, **{"step_covariance.csv": sc_head + rows}), rec, "error",
             where="b/step_covariance.csv" + ("" if line is None else f":{line}"))  # fmt: skip


def _mount_cases() -> None:
    rec = ["recover", "b", "-o", "x.txt", "-q"]
    # sensor_model.mount
    for label, mount, exp in (
        ("valid", [0.1, 0, 0], "score"), ("two", [0.1, 0], "error"), ("string", ["a", 0, 0], "error"),
        ("1e31", [1e31, 0, 0], "error"), ("1e300", [1e300, 0, 0], "error"), ("nan", "NaN", "error"),
        ("theta 1e20", [0, 0, 1e20], "either"), ("bool", [True, 0, 0], "error"),
    ):  # fmt: skip

        def m_mount(m: dict, mount=mount) -> None:
            m["sensor_model"]["mount"] = mount

        files = bundle_files(manifest=m_mount)
        if mount == "NaN":
            files["b/bundle.json"] = files["b/bundle.json"].replace('"NaN"', "NaN")
        case("bundle", f"mount {label}", files, rec, exp, where="b/bundle.json")


def _statement_cases() -> None:
    rec = ["recover", "b", "-o", "x.txt", "-q"]

    # time: steps
    def steps(m: dict) -> None:
        m["time"] = "steps"

    case(
        "bundle",
        "time steps valid",
        bundle_files(
            manifest=steps,
            **{
                "measurements.csv": "t,range,bearing,landmark\n1,1.5,0.1,1\n2,2.0,-0.3,\n2,3.0,0.5,2\n"
            },
        ),
        rec,
        "score",
    )
    case(
        "bundle",
        "time steps fractional",
        bundle_files(manifest=steps),
        rec,
        "error",
        where="b/measurements.csv:2",
    )
    case(
        "bundle",
        "time steps 1e300",
        bundle_files(
            manifest=steps,
            **{
                "controls.csv": "t,v,omega\n0,1,0\n1,1,0.1\n1e300,0,0\n",
                "measurements.csv": "t,range,bearing,landmark\n1,1.5,0.1,1\n",
            },
        ),
        rec,
        "error",
        where="b/controls.csv",
    )
    for v in ('"Steps"', "1", "null", '["steps"]'):

        def tv(m: dict, v=v) -> None:
            m["time"] = json.loads(v)

        case("bundle", f"time {v}", bundle_files(manifest=tv), rec, "error", where="b/bundle.json")
    # processed column
    for label, col, exp, where in (
        ("valid", ["1", "0", "1"], "score", None), ("2", ["1", "2", "1"], "error", "b/measurements.csv:3"),
        ("yes", ["1", "yes", "1"], "error", "b/measurements.csv:3"), ("empty", ["1", "", "1"], "error", "b/measurements.csv:3"),
        ("nan", ["1", "nan", "1"], "error", "b/measurements.csv:3"), ("0.5", ["1", "0.5", "1"], "error", "b/measurements.csv:3"),
    ):  # fmt: skip
        rows = ["0.5,1.5,0.1,1", "1.5,2.0,-0.3,", "2.5,3.0,0.5,2"]
        text = "t,range,bearing,landmark,processed\n" + "".join(
            f"{r},{c}\n" for r, c in zip(rows, col)
        )
        case(
            "bundle",
            f"processed {label}",
            bundle_files(**{"measurements.csv": text}),
            rec,
            exp,
            where=where,
        )


def _json_cases() -> None:
    rec = ["recover", "b", "-o", "x.txt", "-q"]
    # map_source, initialisation
    for key, vals in (
        ("map_source", ['"LOG"', "1", "true", '"log"']),
        ("initialisation", ['"x"', "0", '"initialises_only"']),
    ):
        for v in vals:

            def mv(m: dict, key=key, v=v) -> None:
                m[key] = json.loads(v)

            ok = v in ('"log"', '"initialises_only"')
            case(
                "bundle",
                f"{key} {v}",
                bundle_files(manifest=mv),
                rec,
                "score" if ok else "error",
                where=None if ok else "b/bundle.json",
            )
    # JSON: repeated keys, NaN literal, huge ints, Infinity
    from tests.test_readers_fuzz import BUNDLE_JSON

    js = json.dumps(json.loads(BUNDLE_JSON))  # one line: the replacements below hit
    assert '"initial_pose": [0, 0, 0]' in js and "[1e-06, 0, 0]" in js and '"sigma_v": 0.1' in js
    for label, text, exp in (
        ("repeated key", js.replace('"initial_pose": [0, 0, 0]', '"initial_pose": [0, 0, 0],\n  "initial_pose": [1, 0, 0]'), "error"),
        ("repeated nested key", js.replace('"sigma_v": 0.1', '"sigma_v": 0.1, "sigma_v": 0.2'), "error"),
        ("NaN literal", js.replace('"sigma_v": 0.1', '"sigma_v": NaN'), "error"),
        ("Infinity literal", js.replace('"sigma_v": 0.1', '"sigma_v": Infinity'), "error"),
        ("-Infinity pose", js.replace('"initial_pose": [0, 0, 0]', '"initial_pose": [-Infinity, 0, 0]'), "error"),
        ("huge int", js.replace('"initial_pose": [0, 0, 0]', '"initial_pose": [' + "9" * 400 + ', 0, 0]'), "error"),
        ("huge int sigma", js.replace('"sigma_v": 0.1', '"sigma_v": ' + "9" * 5000), "error"),
        ("1e400", js.replace('"sigma_v": 0.1', '"sigma_v": 1e400'), "error"),
        ("BOM", "\ufeff" + js, "either"),
        ("deep nesting", js.replace('"description"', '"x_deep": ' + "[" * 100000 + "]" * 100000 + ', "description"') if '"description"' in js else js[:-1] + ', "x_deep": ' + "[" * 100000 + "]" * 100000 + "}", "either"),
        ("initial_pose 1e31", js.replace('"initial_pose": [0, 0, 0]', '"initial_pose": [0, 1e31, 0]'), "error"),
        ("initial_cov 1e300", js.replace("[1e-06, 0, 0]", "[1e300, 0, 0]"), "error"),
    ):  # fmt: skip
        case(
            "json",
            f"bundle.json {label}",
            bundle_files(**{"bundle.json": text}),
            rec,
            exp,
            where="b/bundle.json",
        )


def _controls_cases() -> None:
    rec = ["recover", "b", "-o", "x.txt", "-q"]
    # controls extremes (the brief's three)
    for label, rows, exp, where in (
        ("v 1e300", "0,1e300,0\n1,1,0.1\n2,0,0\n", "error", "b/controls.csv:2"),
        ("omega 1e300", "0,1,1e300\n1,1,0.1\n2,0,0\n", "error", "b/controls.csv:2"),
        ("v -1e300", "0,1,0\n1,-1e300,0.1\n2,0,0\n", "error", "b/controls.csv:3"),
        ("omega 1e200 last row", "0,1,0\n1,1,0.1\n3,0,1e200\n", "error", "b/controls.csv:4"),
        ("dt 1e300", "0,1,0\n1,1,0.1\n1e300,0,0\n", "error", "b/controls.csv:3"),
        ("v 1e15", "0,1e15,0\n1,1,0.1\n3,0,0\n", "either", "b"),
        ("omega 1e15", "0,1,1e15\n1,1,0.1\n3,0,0\n", "either", "b"),
        ("no time", "1,1,0\n1,1,0.1\n", "error", "b/controls.csv"),
        ("no time 3 rows", "1,1,0\n1,1,0.1\n1,0,0\n", "error", "b/controls.csv"),
        ("nan", "0,nan,0\n1,1,0.1\n3,0,0\n", "error", "b/controls.csv:2"),
    ):  # fmt: skip
        case(
            "bundle",
            f"controls {label}",
            bundle_files(**{"controls.csv": "t,v,omega\n" + rows}),
            rec,
            exp,
            where=where,
        )
        if exp == "error":
            case(
                "bundle",
                f"slam: controls {label}",
                bundle_files(**{"controls.csv": "t,v,omega\n" + rows}),
                ["slam", "b", "-o", "s", "--association", "nn"],
                exp,
                where=where,
            )

    def odo(m: dict) -> None:
        m["motion_model"] = {
            "type": "odometry",
            "sigma_x": 0.1,
            "sigma_y": 0.1,
            "sigma_theta": 0.01,
        }

    case(
        "bundle",
        "odometry no time",
        bundle_files(manifest=odo, **{"odometry.csv": "t,x,y,theta\n1,0,0,0\n1,1,0,0\n"}),
        rec,
        "error",
        where="b/odometry.csv",
    )
    case(
        "bundle",
        "odometry 1e31",
        bundle_files(
            manifest=odo, **{"odometry.csv": "t,x,y,theta\n0,0,0,0\n1,1e31,0,0\n3,2,0,0\n"}
        ),
        rec,
        "error",
        where="b/odometry.csv:3",
    )
    case(
        "bundle",
        "odometry valid",
        bundle_files(
            manifest=odo,
            **{"odometry.csv": "t,x,y,theta\n0,0,0,0\n1,1,0,0\n2,2,0.1,0.1\n3,3,0.3,0.2\n"},
        ),
        rec,
        "score",
    )
    for label, sig in (("sigma_v 1e10", 1e10), ("sigma_v 1e-300", 1e-300), ("sigma_v 1e30", 1e30)):

        def sv(m: dict, sig=sig) -> None:
            m["motion_model"]["sigma_v"] = sig

        for method in ("filter", "smoother", "batch"):
            case(
                "bundle",
                f"{label} {method}",
                bundle_files(manifest=sv),
                [*rec, "--method", method],
                "either",
                where="b",
            )


# ---- CSV
def csv_cases() -> None:
    ref = "t,x,y,theta\n" + "".join(f"{k},{k}.0,0,0\n" for k in range(6))
    # the estimate: pose 3 moved 0.1 m along x -> mean of 5 consecutive errors = 0.2 / 5 = 0.04
    est_rows = [f"{k},{k + (0.1 if k == 3 else 0)},0,0" for k in range(6)]
    ev = ["evaluate", "r.csv", "e.csv", "--json", "o.json", "-q"]
    chk = json_out("translation.abs.mean", 0.04)
    case(
        "csv",
        "traj csv valid",
        {"r.csv": ref, "e.csv": "t,x,y,theta\n" + "\n".join(est_rows) + "\n"},
        ev,
        "score",
        check=chk,
    )
    case(
        "csv",
        "traj csv BOM",
        {"r.csv": ref, "e.csv": "\ufefft,x,y,theta\n" + "\n".join(est_rows) + "\n"},
        ev,
        "score",
        check=chk,
    )
    case(
        "csv",
        "traj csv CRLF",
        {
            "r.csv": ref,
            "e.csv": ("t,x,y,theta\n" + "\n".join(est_rows) + "\n").replace("\n", "\r\n"),
        },
        ev,
        "score",
        check=chk,
    )
    case(
        "csv",
        "traj csv trailing comma",
        {"r.csv": ref, "e.csv": "t,x,y,theta,\n" + "\n".join(r + "," for r in est_rows) + "\n"},
        ev,
        "either",
        where="e.csv",
        check=None,
    )


def _csv_odd_cases() -> None:
    ref = "t,x,y,theta\n" + "".join(f"{k},{k}.0,0,0\n" for k in range(6))
    est_rows = [f"{k},{k + (0.1 if k == 3 else 0)},0,0" for k in range(6)]
    ev = ["evaluate", "r.csv", "e.csv", "--json", "o.json", "-q"]
    case(
        "csv",
        "traj csv quoted header",
        {"r.csv": ref, "e.csv": '"t","x","y","theta"\n' + "\n".join(est_rows) + "\n"},
        ev,
        "either",
        where="e.csv",
    )
    case(
        "csv",
        "traj csv repeated column",
        {"r.csv": ref, "e.csv": "t,x,x,theta\n" + "\n".join(est_rows) + "\n"},
        ev,
        "error",
        where="e.csv:1",
    )
    case(
        "csv",
        "traj csv repeated t",
        {"r.csv": ref, "e.csv": "t,t,x,y,theta\n" + "\n".join(f"0,{r}" for r in est_rows) + "\n"},
        ev,
        "error",
        where="e.csv:1",
    )
    case(
        "csv",
        "traj csv column case",
        {"r.csv": ref, "e.csv": "t,X,y,theta\n" + "\n".join(est_rows) + "\n"},
        ev,
        "either",
        where="e.csv",
    )
    case(
        "csv",
        "traj csv header only",
        {"r.csv": ref, "e.csv": "t,x,y,theta\n"},
        ev,
        "error",
        where="e.csv",
    )
    case(
        "csv",
        "traj csv nan cell",
        {
            "r.csv": ref,
            "e.csv": "t,x,y,theta\n" + "\n".join(est_rows).replace("3,3.1,", "3,nan,") + "\n",
        },
        ev,
        "either",
        where="e.csv",
    )
    case(
        "csv",
        "traj csv 1e20 cell",
        {
            "r.csv": ref,
            "e.csv": "t,x,y,theta\n" + "\n".join(est_rows).replace("3,3.1,", "3,1e20,") + "\n",
        },
        ev,
        "either",
        where="e.csv",
    )


def _map_csv_cases() -> None:
    # landmark maps
    est = "id,x,y\n1,0,0\n2,10,0\n3,0,10\n4,10,10\n"
    refm = "id,x,y\n1,0,0\n2,10,0\n3,0,10\n4,10,10.5\n"
    mc = ["map-compare", "e.csv", "r.csv", "--associate", "id", "--json", "o.json"]
    case("csv", "map valid", {"e.csv": est, "r.csv": refm}, mc, "score")
    for label, text, exp, where in (
        ("repeated x", "id,x,y,x\n1,0,0,5\n2,10,0,5\n3,0,10,5\n4,10,10,5\n", "error", "e.csv:1"),
        ("repeated id", "id,x,id,y\n1,0,9,0\n2,10,9,0\n3,0,9,10\n4,10,9,10\n", "error", "e.csv:1"),
        ("BOM", "\ufeff" + est, "score", None),
        ("CRLF", est.replace("\n", "\r\n"), "score", None),
        ("trailing comma", est.replace("\n", ",\n"), "either", "e.csv"),
        ("quoted header", '"id","x","y"\n' + est.split("\n", 1)[1], "either", "e.csv"),
        ("id 3.5", est.replace("3,0,10", "3.5,0,10"), "error", "e.csv:4"),
        ("id 1e20", est.replace("3,0,10", "1e20,0,10"), "error", "e.csv:4"),
        ("id -0 and 0", est.replace("3,0,10", "-0,0,10").replace("4,10,10", "0,10,10"), "error", "e.csv:5"),
        ("duplicate id", est.replace("3,0,10", "2,0,10"), "error", "e.csv:4"),
        ("x 1e31", est.replace("3,0,10", "3,1e31,10"), "error", "e.csv:4"),
        ("x nan", est.replace("3,0,10", "3,nan,10"), "error", "e.csv:4"),
        ("huge id", est.replace("3,0,10", "99999999999999999999,0,10"), "error", "e.csv:4"),
    ):  # fmt: skip
        case("csv", f"map {label}", {"e.csv": text, "r.csv": refm}, mc, exp, where=where)


def _bundle_csv_cases() -> None:
    # bundle CSVs
    rec = ["recover", "b", "-o", "x.txt", "-q"]
    for label, text, exp, where in (
        ("repeated column", "t,range,bearing,range,landmark\n0.5,1.5,0.1,9,1\n", "error", "b/measurements.csv:1"),
        ("BOM", "\ufefft,range,bearing,landmark\n0.5,1.5,0.1,1\n1.5,2.0,-0.3,\n2.5,3.0,0.5,2\n", "score", None),
        ("CRLF", "t,range,bearing,landmark\r\n0.5,1.5,0.1,1\r\n1.5,2.0,-0.3,\r\n2.5,3.0,0.5,2\r\n", "score", None),
        ("trailing comma", "t,range,bearing,landmark,\n0.5,1.5,0.1,1,\n", "either", "b/measurements.csv"),
        ("quoted header", '"t","range","bearing","landmark"\n0.5,1.5,0.1,1\n', "either", "b/measurements.csv"),
        ("landmark 1.5", "t,range,bearing,landmark\n0.5,1.5,0.1,1.5\n", "error", "b/measurements.csv:2"),
        ("landmark 1e20", "t,range,bearing,landmark\n0.5,1.5,0.1,1e20\n", "error", "b/measurements.csv:2"),
    ):  # fmt: skip
        case(
            "csv",
            f"measurements {label}",
            bundle_files(**{"measurements.csv": text}),
            rec,
            exp,
            where=where,
        )
    case(
        "csv",
        "controls repeated column",
        bundle_files(**{"controls.csv": "t,v,omega,v\n0,1,0,5\n1,1,0.1,5\n3,0,0,5\n"}),
        rec,
        "error",
        where="b/controls.csv:1",
    )
    case(
        "csv",
        "map.csv repeated x",
        bundle_files(**{"map.csv": "landmark,x,y,x\n1,1.5,0.2,9\n2,3,1,9\n3,5,5,9\n"}),
        rec,
        "error",
        where="b/map.csv:1",
    )


def _manifest_cases() -> None:
    # batch manifest
    runs = {"r/ref.txt": PLAIN, "r/est.txt": plain_shift(0.1)}
    for label, text, exp, where in (
        ("valid", "name,reference,estimate\nrun1,r/ref.txt,r/est.txt\n", "score", None),
        ("repeated column", "name,reference,estimate,name\nrun1,r/ref.txt,r/est.txt,x\n", "error", "m.csv:1"),
        ("BOM", "\ufeffname,reference,estimate\nrun1,r/ref.txt,r/est.txt\n", "score", None),
        ("CRLF", "name,reference,estimate\r\nrun1,r/ref.txt,r/est.txt\r\n", "score", None),
        ("trailing comma", "name,reference,estimate,\nrun1,r/ref.txt,r/est.txt,\n", "either", "m.csv"),
        ("duplicate name", "name,reference,estimate\nrun1,r/ref.txt,r/est.txt\nrun1,r/ref.txt,r/est.txt\n", "error", "m.csv:3"),
        ("name with comma", 'name,reference,estimate\n"a,b",r/ref.txt,r/est.txt\n', "either", "m.csv"),
        ("name with newline", 'name,reference,estimate\n"a\nb",r/ref.txt,r/est.txt\n', "either", "m.csv"),
        ("name ..", "name,reference,estimate\n..,r/ref.txt,r/est.txt\n", "either", "m.csv"),
        ("name with slash", "name,reference,estimate\na/b,r/ref.txt,r/est.txt\n", "either", "m.csv"),
    ):  # fmt: skip
        case("csv", f"batch manifest {label}", {**runs, "m.csv": text}, ["batch", "m.csv", "-o", "out", "--workers", "0", "-q"], exp, where=where,
             check=None if exp != "score" else table_mean(0.04))  # fmt: skip


def table_mean(want: float):
    def check(d: Path, out: str, err: str) -> str | None:
        import csv

        with open(d / "out" / "table.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        if not rows:
            return "empty table"
        keys = [k for k in rows[0] if "mean" in k and ("trans" in k or k.startswith("t"))]
        if not keys:
            return f"no translation mean column in {list(rows[0])}"
        got = float(rows[0][keys[0]])
        return None if math.isclose(got, want, rel_tol=1e-6) else f"{keys[0]} = {got}"

    return check


# ---- batch and study folders
def folder_cases() -> None:
    names = ["a,b", "a|b", 'a"b', "a$b", "a$\\frac$b", "a b", "ä", "-a"]
    for nm in names:
        files = {
            f"runs/{nm}/reference.txt": PLAIN,
            f"runs/{nm}/estimate.txt": plain_shift(0.1),
            "runs/z/reference.txt": PLAIN,
            "runs/z/estimate.txt": plain_shift(0.2),
        }
        case(
            "folders",
            f"batch folder name {nm!r}",
            files,
            ["batch", "runs", "-o", "out", "--workers", "0", "-q"],
            "score",
            check=table_names([nm, "z"]),
        )
    # edited NaN in stored results, then resume
    files = {"runs/r1/reference.txt": PLAIN, "runs/r1/estimate.txt": plain_shift(0.1)}

    def nan_results(d: Path) -> None:
        for p in sorted((d / "out").rglob("*.json")):
            text = p.read_text()
            import re

            new = re.sub(r'("trans_mean": )[-0-9.e+]+', r"\1NaN", text, count=1)
            if new != text:
                p.write_text(new)
                return
        raise RuntimeError("no stored mean to edit")

    case("folders", "batch resume with a stored NaN", files, ["batch", "runs", "-o", "out", "--workers", "0", "-q"], "score",
         pre=[["batch", "runs", "-o", "out", "--workers", "0", "-q"]], mutate=nan_results, check=table_mean(0.04))  # fmt: skip

    def drop_table(d: Path) -> None:
        (d / "out" / "table.csv").unlink()
        for p in (d / "out" / "per_relation").glob("*.csv"):
            p.unlink()

    case("folders", "batch resume with deleted outputs", files, ["batch", "runs", "-o", "out", "--workers", "0", "-q"], "score",
         pre=[["batch", "runs", "-o", "out", "--workers", "0", "-q"]], mutate=drop_table,
         check=lambda d, o, e: table_mean(0.04)(d, o, e) or (None if list((d / "out" / "per_relation").glob("*.csv")) else "per_relation not rewritten"))  # fmt: skip

    def garbage_results(d: Path) -> None:
        for p in sorted((d / "out").rglob("*.json")):
            p.write_text('{"key": 1, "key": 2}')
            return

    case("folders", "batch resume with a damaged store", files, ["batch", "runs", "-o", "out", "--workers", "0", "-q"], "either",
         where="out", pre=[["batch", "runs", "-o", "out", "--workers", "0", "-q"]], mutate=garbage_results)  # fmt: skip


def _compare_study_cases() -> None:
    # compare: names as mathtext
    per = "t1,t2,translation,rotation\n" + "".join(
        f"{k},{k + 1},{0.01 * (k % 3)},{0.001 * (k % 5)}\n" for k in range(30)
    )
    for nm in ("a$\\frac$", "a,b", "a|b", 'x"y', "$x^2$"):
        case("folders", f"compare name {nm!r}", {"a.csv": per, "b.csv": per.replace(",0.0", ",0.02")},
             ["compare", f"D:{nm}=a.csv", "D:B=b.csv", "-o", "cmp", "--resamples", "99", "-q"], "either", where="a.csv")  # fmt: skip

    # study: edit a stored case to NaN, resume
    def study_nan(d: Path) -> None:
        import re

        for p in sorted((d / "st").rglob("*.json")):
            text = p.read_text()
            new = re.sub(r'("rmse_xy": )[-0-9.e+]+', r"\1NaN", text, count=1)
            if new != text:
                p.write_text(new)
                return
        raise RuntimeError("no stored number to edit")

    st = [
        "study",
        "pose-only",
        "-o",
        "st",
        "--runs",
        "1",
        "--worlds",
        "simple1",
        "--noise",
        "a",
        "--methods",
        "m1",
        "--workers",
        "1",
        "-q",
    ]
    case(
        "folders",
        "study resume with a stored NaN",
        {},
        st,
        "either",
        where="st",
        pre=[st],
        mutate=study_nan,
        check=study_rmse,
    )


def study_rmse(d: Path, out: str, err: str) -> str | None:
    """The resumed study's table: rmse_xy of the one case as the first run wrote it (0.272,
    measured), not NaN."""
    import csv

    with open(d / "st" / "table.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    got = rows[0]["rmse_xy"]
    return None if got == "0.272" else f"rmse_xy {got!r}"


def table_names(names: list[str]):
    def check(d: Path, out: str, err: str) -> str | None:
        import csv

        with open(d / "out" / "table.csv", newline="") as f:
            rows = list(csv.reader(f))
        widths = {len(r) for r in rows}
        if len(widths) != 1:
            return f"table.csv rows of widths {widths}"
        got = sorted(r[1] for r in rows[1:] if r[0] == "run")
        if got != sorted(names):
            return f"names {got}"
        md = (d / "out" / "table.md").read_text().splitlines()
        cells = {len(ln.replace("\\|", "").split("|")) for ln in md if ln.startswith("|")}
        return None if len(cells) == 1 else f"table.md rows of {cells} cells"

    return check


# ---- ape / rpe options
def evo_cases() -> None:
    files = {"r.tum": TUM_REF, "e.tum": TUM_EST}
    case(
        "evo",
        "ape valid (1 m off)",
        files,
        ["ape", "tum", "r.tum", "e.tum"],
        "score",
        check=ape_rmse(1.0),
    )
    for opt, vals in (
        ("--t_max_diff", ("0", "-1", "nan", "inf", "1e300")),
        ("--t_offset", ("nan", "inf", "1e300", "-1e300")),
        ("--t_start", ("nan", "1e300", "-inf")),
        ("--t_end", ("nan", "-1e300")),
        ("--n_to_align", ("0", "-1", "1e300", "2.5")),
    ):
        for v in vals:
            case(
                "evo-opts",
                f"ape {opt} {v}",
                files,
                ["ape", "tum", "r.tum", "e.tum", opt, v, "-a"]
                if opt == "--n_to_align"
                else ["ape", "tum", "r.tum", "e.tum", opt, v],
                "optionish",
            )
    for opt, vals in (
        ("-d", ("0", "-1", "nan", "inf", "1e300", "2.5")),
        ("-t", ("-1", "nan", "inf")),
        ("--t_max_diff", ("nan", "-1")),
    ):
        for v in vals:
            for unit in ("f", "m"):
                case(
                    "evo-opts",
                    f"rpe {opt} {v} -u {unit}",
                    files,
                    ["rpe", "tum", "r.tum", "e.tum", opt, v, "-u", unit],
                    "optionish",
                )
    case(
        "evo",
        "rpe valid",
        files,
        ["rpe", "tum", "r.tum", "e.tum", "-d", "1", "-u", "f"],
        "score",
        check=ape_rmse(0.0) if False else None,
    )
    for label, est in (("tum nan", TUM_EST.replace("4 5.0", "4 nan")), ("tum 1e31", TUM_EST.replace("4 5.0", "4 1e31")),
                       ("tum quat zero", TUM_EST.replace("4 5.0 0 0 0 0 0 1", "4 5.0 0 0 0 0 0 0")),
                       ("tum id-like time 1e20", TUM_EST.replace("\n4 5.0", "\n1e20 5.0"))):  # fmt: skip
        case(
            "evo",
            f"ape {label}",
            {"r.tum": TUM_REF, "e.tum": est},
            ["ape", "tum", "r.tum", "e.tum"],
            "either",
            where="e.tum",
        )


def build() -> None:
    graph_cases()
    from_graph_cases()
    laser_cases()
    bag_cases()
    bundle_cases()
    _mount_cases()
    _statement_cases()
    _json_cases()
    _controls_cases()
    csv_cases()
    _csv_odd_cases()
    _map_csv_cases()
    _bundle_csv_cases()
    _manifest_cases()
    folder_cases()
    _compare_study_cases()
    evo_cases()


# ------------------------------------------------------------------------------ running


#: Options whose value may be negative (a time offset or bound; evo's --n_to_align -1: all
#: poses): only nan is never valid.
SIGNED = ("--t_offset", "--t_start", "--t_end", "--n_to_align")  # evo: -1 aligns all poses


def _never_valid(c: Case) -> bool:
    """An option value no command can use: nan, or -1 for an option that is a size, a
    tolerance or a threshold."""
    for k, word in enumerate(c.argv[:-1]):
        if word.startswith("-") and not word[1:2].isdigit():
            v = c.argv[k + 1]
            if v == "nan" or (v == "-1" and word not in SIGNED):
                return True
    return False


def judge(c: Case, rc: int, out: str, err: str, d: Path) -> str | None:
    text = out + err
    for bad in BAD:
        if bad in text:
            return f"'{bad}' in output: {text.strip()[:300]}"
    if c.expect == "optionish":  # an option value: exit 2, or a score/refusal that is sound
        if rc == 2:
            return None
        if _never_valid(c):
            return f"exit {rc} for {c.name}: expected 2 (an option value nothing can use)"
        if rc in (0, 3):
            return None if rc == 0 else (None if "error:" in err else "exit 3 without error line")
        return f"exit {rc}"
    ok = {"score": (0,), "error": (3,), "option": (2,), "either": (0, 3)}[c.expect]
    if rc not in ok:
        return f"exit {rc}, expected {ok}: {text.strip()[:300]}"
    if rc == 3 and c.where:
        if "/" in c.where or ":" in c.where or "." in c.where or c.where:
            want = str(d / c.where.split(":")[0])
            line = c.where.split(":")[1] if ":" in c.where else None
            rel = c.where.split(":")[0]
            if want not in err and rel not in err:
                return f"error names no {c.where}: {err.strip()[:300]}"
            if line is not None and f"{rel}:{line}" not in err:
                return f"error lacks line {c.where}: {err.strip()[:300]}"
    for s in c.says:
        if s not in text:
            return f"output lacks {s!r}: {text.strip()[:300]}"
    if rc == 0 and c.check is not None:
        try:
            return c.check(d, out, err)
        except Exception as exc:  # noqa: BLE001 - a missing output is a finding
            return f"check failed: {exc!r}"
    return None


def run_case(c: Case, root: Path) -> tuple[str | None, int, str]:
    d = Path(tempfile.mkdtemp(dir=root))
    for name, content in c.files.items():
        p = d / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            with open(p, "w", newline="") as f:
                f.write(content)
    env = dict(os.environ, PYTHONPATH=str(REPO), MPLBACKEND="Agg")
    try:
        for argv in c.pre:
            subprocess.run(
                [sys.executable, "-m", "slamrel", *argv],
                cwd=d,
                env=env,
                capture_output=True,
                timeout=300,
            )
        if c.mutate is not None:
            c.mutate(d)
        p = subprocess.run(
            [sys.executable, "-m", "slamrel", *c.argv],
            cwd=d,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
    except subprocess.TimeoutExpired:
        return "timeout", -1, ""
    except Exception as exc:  # noqa: BLE001 - the audit's own setup failed
        return f"setup failed: {exc!r}", -1, ""
    verdict = judge(c, p.returncode, p.stdout, p.stderr, d)
    shutil.rmtree(d, ignore_errors=True)
    return verdict, p.returncode, (p.stderr.strip().splitlines() or [""])[-1][:200]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", default="")
    ap.add_argument("--classes", default="", help="comma-separated classes to run")
    ap.add_argument("--json")
    a = ap.parse_args()
    build()
    root = Path(tempfile.mkdtemp(prefix="audit39-"))
    results = []
    t0 = time.time()
    for c in CASES:
        if a.only and a.only not in f"{c.cls} {c.name}":
            continue
        if a.classes and c.cls not in a.classes.split(","):
            continue
        verdict, rc, last = run_case(c, root)
        results.append(
            {
                "cls": c.cls,
                "name": c.name,
                "rc": rc,
                "ok": verdict is None,
                "why": verdict,
                "last": last,
            }
        )
        print(
            f"{'ok  ' if verdict is None else 'FAIL'} [{c.cls}] {c.name}: rc={rc}"
            + ("" if verdict is None else f" -- {verdict}"),
            flush=True,
        )
    n, good = len(results), sum(r["ok"] for r in results)
    by = {}
    for r in results:
        by.setdefault(r["cls"], [0, 0])
        by[r["cls"]][0] += 1
        by[r["cls"]][1] += r["ok"]
    print(
        f"\n{good}/{n} right ({time.time() - t0:.0f} s); by class: "
        + ", ".join(f"{k} {v[1]}/{v[0]}" for k, v in by.items())
    )
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
