"""Issue 39: nothing misread — the input rule at the root of every reader.

Each test feeds the CLI an input that used to give a wrong number without a word, or an
internal error, and checks the fix: one clear refusal (exit 3, the file, the line where
there is one, and what was expected) or a warning that says what was skipped.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from slamrel.cli import main
from tests.test_readers_fuzz import BUNDLE


def _write(root: Path, files: dict[str, str]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (root / name).write_text(text)
    return root


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    for needle in needles:
        assert needle in err, err
    return err


# ---------------------------------------------------------------- 1. TORO ids and values

_EDGE = "1 0 0 1 0 1 1 0 0"  # dx dy dθ and TORO's information entries (the identity)


def _toro(tmp_path: Path, text: str) -> list[str]:
    p = tmp_path / "g.graph"
    p.write_text(text)
    return ["solve", str(p), "-o", str(tmp_path / "out"), "-q"]


def test_toro_fractional_id_is_refused_not_truncated(tmp_path, capsys):
    """``VERTEX2 3.5`` used to become vertex 3 (the edge ``1 3`` then found it): exit 0."""
    argv = _toro(
        tmp_path,
        f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX2 3.5 2 0 0\n"
        f"EDGE2 0 1 {_EDGE}\nEDGE2 1 3 {_EDGE}\n",
    )
    _refused(argv, capsys, "g.graph:3:", "'VERTEX2 id'", "expected an integer id", "3.5")
    assert not (tmp_path / "out").exists()


def test_toro_ids_beyond_2_53_are_exact(tmp_path, capsys):
    """2**60 and 2**60 + 1 are one double: an edge to the missing 2**60 used to land on
    vertex 2**60 + 1 (exit 0). Read exactly, the edge's end is unknown, at its line."""
    big = 2**60
    argv = _toro(tmp_path, f"VERTEX2 0 0 0 0\nVERTEX2 {big + 1} 1 0 0\nEDGE2 0 {big} {_EDGE}\n")
    _refused(argv, capsys, "g.graph:3:", f"unknown vertex {big}")
    # the same ids, all present, solve: exact ids are kept, not refused
    argv = _toro(tmp_path, f"VERTEX2 0 0 0 0\nVERTEX2 {big + 1} 1 0 0\nEDGE2 0 {big + 1} {_EDGE}\n")
    assert main(argv) == 0
    solved = (tmp_path / "out" / "solved.g2o").read_text().split("\n")
    assert solved[1].split()[:2] == ["VERTEX_SE2", str(big + 1)]  # was written as 2**60


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("VERTEX2 0 0 0 0\nVERTEX2 1e19 1 0 0\n", ("g.graph:2:", "'VERTEX2 id'")),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX 1 2 0 0\nEDGE2 0 1 {_EDGE}\n",
            ("g.graph:3:", "vertex id 1 is defined twice (first on line 2)"),
        ),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1e31 0 0\nEDGE2 0 1 {_EDGE}\n",
            ("g.graph:2:", "pose: position"),
        ),
        (
            "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 -1 0 0\n",
            ("g.graph:3:", "EDGE2 information matrix"),
        ),
        (
            f"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1.5 {_EDGE}\n",
            ("g.graph:3:", "'EDGE2 vertex 2'"),
        ),
    ],
)
def test_toro_records_follow_the_g2o_rules(tmp_path, capsys, text, needles):
    """The g2o reader's checks, from the same functions: id range, repeated ids (across
    both spellings, at the second line), coordinates, information matrices, edge ends."""
    _refused(_toro(tmp_path, text), capsys, *needles)


# ---------------------------------------------------------------- 2. repeated CSV column names


def test_bundle_map_with_a_repeated_column_is_refused(tmp_path, capsys):
    """``x,landmark,x,y``: every landmark used to be placed at the first column's x."""
    rows = BUNDLE["map.csv"].splitlines()[1:]
    cells = [r.split(",") for r in rows]
    text = "x,landmark,X,y\n" + "".join(f"99,{c[0]},{c[1]},{c[2]}\n" for c in cells)
    b = _write(tmp_path / "b", dict(BUNDLE, **{"map.csv": text}))
    _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        "map.csv:1:",
        "names column 'x' twice (columns 1 and 3)",
    )
    assert not (tmp_path / "o.tum").exists()


@pytest.mark.parametrize(
    ("name", "text", "argv"),
    [
        # trajectory CSV (the header after a comment line: the refusal names its line)
        ("t.csv", "# made by hand\nt,x,y,theta,t\n0,0,0,0,5\n1,1,0,0,6\n2,2,0,0,7\n",
         ["evaluate", "{f}", "{f}", "-q"]),
        # landmark map
        ("m.csv", "landmark,x,y,y\n1,0,0,9\n2,1,0,9\n3,0,1,9\n", ["map-compare", "{f}", "{f}"]),
    ],
)  # fmt: skip
def test_every_csv_reader_refuses_a_repeated_column(tmp_path, capsys, name, text, argv):
    f = tmp_path / name
    f.write_text(text)
    line = 2 if text.startswith("#") else 1
    repeated = "t" if name == "t.csv" else "y"
    _refused([a.format(f=f) for a in argv], capsys, f"{name}:{line}:", f"column {repeated!r} twice")


# ---------------------------------------------------------------- 3. repeated JSON keys


def test_bundle_json_with_a_repeated_key_is_refused(tmp_path, capsys):
    """The second ``sigma_v`` used to win silently; which one the writer meant is unknown."""
    text = BUNDLE["bundle.json"].replace('"sigma_v": 0.1,', '"sigma_v": 0.1,\n    "sigma_v": 5.0,')
    assert text != BUNDLE["bundle.json"]
    b = _write(tmp_path / "b", dict(BUNDLE, **{"bundle.json": text}))
    line = text.splitlines().index('    "sigma_v": 5.0,') + 1
    _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        f"bundle.json:{line}:",
        "key 'sigma_v' is given twice in one object (first on line",
    )
    # the same key in two different objects is not a repeat
    assert main(["recover", str(_write(tmp_path / "c", BUNDLE)), "-o", str(tmp_path / "o.tum"),
                 "-q"]) == 0  # fmt: skip


def test_study_record_with_a_repeated_key_is_damaged(tmp_path):
    """A stored study result is slamrel's input on resume: a repeated key makes it damaged
    (recomputed, or named when only loaded), never half-trusted."""
    from relation_metric.errors import InputError
    from slamrel.studies.sweep import Task, load_results

    t = Task("x", "math:hypot", {})
    (tmp_path / f"{t.key}.json").write_text(f'{{"key": "{t.key}", "result": {{"a": 1,\n "a": 2}}}}')
    with pytest.raises(InputError, match="damaged study result: key 'a' is given twice"):
        load_results(tmp_path, [t])


# ---------------------------------------------------------------- 4. an estimate beside the log


def _carmen(times: list[float]) -> str:
    """FLASER scans of a robot moving 0.1 m a scan along x in a round room (every range
    1 m): laser pose = odometry pose, one line a scan."""
    ranges = " ".join(["1.00"] * 181)
    return "".join(
        f"FLASER 181 {ranges} {0.1 * k} 0 0 {0.1 * k} 0 0 {t} host {t}\n"
        for k, t in enumerate(times)
    )


def _tum(times: list[float]) -> str:
    return "".join(f"{t} {0.1 * k} 0 0 0 0 0 1\n" for k, t in enumerate(times))


def test_align_refuses_an_estimate_beside_the_log(tmp_path, capsys):
    """Times 100 … 101 s against scans at 10 … 11 s: every guess used to be the log's own
    motion from the estimate's end pose ("guesses from EST", exit 0). Refused as the bag path
    refuses it; an overlapping estimate still gives the guesses."""
    scan_times = [10.0 + 0.2 * k for k in range(6)]
    log, est = tmp_path / "log.clf", tmp_path / "est.tum"
    log.write_text(_carmen(scan_times))
    est.write_text(_tum([t + 90.0 for t in scan_times]))
    out = tmp_path / "out.relations"
    argv = ["relations", "align", str(log), "--estimate", str(est), "-o", str(out)]
    _refused(argv, capsys, f"{est}:", "no scan lies within the estimate's time span",
             "100.000 … 101.000 s", "10.000 … 11.000 s")  # fmt: skip
    assert not out.exists()
    est.write_text(_tum(scan_times))
    assert main(argv) == 0
    assert f"guesses from {est}; 0 scan pose(s) odometry-corrected" in capsys.readouterr().out


# ---------------------------------------------------------------- 5. skipped and reordered, said


def test_skipped_3d_pose_vertices_are_warned(tmp_path, capsys):
    """Only VERTEX_SE2 poses make a g2o trajectory; a skipped VERTEX_SE3 used to be counted
    only in --json."""
    g2o = tmp_path / "t.g2o"
    g2o.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\nVERTEX_SE2 2 2 0 0\n"
        "VERTEX_SE3:QUAT 4 1 0 0 0 0 0 1\nVERTEX_SE2 3 3 0 0\nEDGE_SE2 0 2 1 0 0 1 0 0 1 0 1\n"
    )
    ref = tmp_path / "r.tum"
    ref.write_text("0 0 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n3 3 0 0 0 0 0 1\n")
    assert main(["evaluate", str(ref), str(g2o), "-q"]) == 0
    err = capsys.readouterr().err
    assert (
        f"warning: {g2o}: skipped 2 VERTEX_SE3:QUAT record(s) (3-D poses, first at line 2); "
        "the g2o trajectory format reads VERTEX_SE2 poses only"
    ) in err
    # the records a g2o trajectory always skips (edges, landmarks) stay silent
    g2o.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_XY 7 1 1\nVERTEX_SE2 2 2 0 0\nVERTEX_SE2 3 3 0 0\n")
    assert main(["evaluate", str(ref), str(g2o), "-q"]) == 0
    assert "skipped" not in capsys.readouterr().err


def test_align_warns_of_scans_out_of_time_order(tmp_path, capsys):
    """Scans 4 and 6 step back in time (10.3 after 10.4, 10.6 after 10.8): the warning
    counts 2 and names line 4; the scans stay in file order, as before."""
    log = tmp_path / "log.clf"
    log.write_text(_carmen([10.0, 10.2, 10.4, 10.3, 10.8, 10.6, 11.0]))
    out = tmp_path / "out.relations"
    assert main(["relations", "align", str(log), "-o", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    assert (
        f"{log}: 2 FLASER scans out of time order (largest step back 0.200000 s, first at "
        "line 4); kept in file order"
    ) in err
    log.write_text(_carmen([10.0, 10.2, 10.3, 10.4, 10.6, 10.8, 11.0]))
    out.unlink()
    assert main(["relations", "align", str(log), "-o", str(out), "-q"]) == 0
    assert "out of time order" not in capsys.readouterr().err


# ---------------------------------------------------------------- 6. crashes on valid input


@pytest.mark.parametrize(("storage", "name"), [("ros1", "run.bag"), ("sqlite3", "run_db3"),
                                               ("mcap", "run_mcap")])  # fmt: skip
def test_bag_message_that_does_not_deserialize_is_named(tmp_path, capsys, rng, storage, name):
    """Message 3 of /pose is cut off (half its bytes): an "internal error" before; now the
    bag, the topic and the message's index on it, exit 3 (ROS 1, db3, MCAP alike)."""
    pytest.importorskip("rosbags")
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    from tests.test_bags import TYPES, _messages, _truth

    ros1 = storage == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    bag = tmp_path / name
    writer = Writer1(bag) if ros1 else Writer2(bag, version=9, storage_plugin=plugin)
    with writer as w:
        c = w.add_connection("/pose", TYPES["pose"], typestore=ts)
        for i, m in enumerate(_messages(ts, _truth(rng), "pose")):
            raw = (ts.serialize_ros1 if ros1 else ts.serialize_cdr)(m, TYPES["pose"])
            w.write(c, 10**9 * (i + 1), raw[: len(raw) // 2] if i == 2 else raw)
    ref = tmp_path / "ref.tum"
    ref.write_text("".join(f"{1_500_000_000 + k} {k} 0 0 0 0 0 1\n" for k in range(6)))
    _refused(
        ["evaluate", str(ref), f"{bag}:/pose", "-q"],
        capsys,
        str(bag),
        "topic '/pose', message 3: does not deserialize as geometry_msgs/PoseStamped",
    )


def test_compare_draws_names_with_dollars_literally(tmp_path, capsys):
    """Dataset and algorithm names are the user's words, not mathtext: ``a$\\frac$`` used to
    end in an internal error while drawing errors.png."""
    from slamrel.plots.relation_errors import literal_text

    ref, est = tmp_path / "ref.tum", tmp_path / "est.tum"
    ref.write_text("".join(f"{k} {k} 0 0 0 0 0 1\n" for k in range(12)))
    est.write_text("".join(f"{k} {k + 0.01 * (k % 3)} 0 0 0 0 0 1\n" for k in range(12)))
    per = {}
    for name, traj in (("est", est), ("ref", ref)):
        per[name] = tmp_path / f"{name}.csv"
        argv = ["evaluate", str(ref), str(traj), "--strategy", "consecutive",
                "--per-relation", str(per[name]), "-q"]  # fmt: skip
        assert main(argv) == 0
    out = tmp_path / "cmp"
    argv = ["compare", f"a$\\frac$:b$x$={per['est']}", f"a$\\frac$:$c={per['ref']}",
            "-o", str(out), "-q"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    assert (out / "errors.png").stat().st_size > 0
    assert "| a\\$\\\\frac\\$ | b\\$x\\$ |" in (out / "table.md").read_text()
    # what matplotlib is given: each $ escaped, so no pair opens mathtext
    assert literal_text("a$\\frac$") == "a\\$\\frac\\$"
    from matplotlib.text import Text

    shown = Text(text=literal_text("a$\\frac$"))._preprocess_math(literal_text("a$\\frac$"))
    assert shown == ("a$\\frac$", False)  # drawn as the name itself, not as math


@pytest.mark.parametrize("key", ["sigma_range", "sigma_bearing"])
def test_sensor_sigma_whose_variance_is_not_a_double_is_refused(tmp_path, capsys, key):
    """σ = 1e-300 squares to 1e-600, which float64 holds only as 0: the smoother and batch
    inverted that zero (LinAlgError, "internal error"). Refused where it is read, for every
    method alike (the filter ran the σ = 0 model a bundle may not state); 1e-150 is read."""
    import json

    meta = json.loads(BUNDLE["bundle.json"])
    meta["sensor_model"][key] = 1e-300
    text = json.dumps(meta, indent=2) + "\n"
    b = _write(tmp_path / "b", dict(BUNDLE, **{"bundle.json": text}))
    line = next(n for n, t in enumerate(text.splitlines(), 1) if f'"{key}"' in t)
    for method in ("smoother", "batch", "filter"):
        out = tmp_path / f"{method}.tum"
        _refused(["recover", str(b), "-o", str(out), "--method", method], capsys,
                 f"bundle.json:{line}:", f"sensor_model.{key}: 1e-300 is below 1e-150",
                 "expected a standard deviation of at least 1e-150")  # fmt: skip
        assert not out.exists()
    meta["sensor_model"][key] = 1e-150
    b = _write(tmp_path / "c", dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)}))
    assert main(["recover", str(b), "-o", str(tmp_path / "f.tum"), "--method", "filter",
                 "-q"]) == 0  # fmt: skip


def test_align_refuses_a_pose_that_no_correlative_search_can_reach(tmp_path, capsys):
    """A scan pose at 1e20 m: the correlative search's table from the reference to the guess
    had a negative size (an internal error). The scans cannot overlap anywhere in the window
    and the table would be ~7e23 cells: refused, naming the scan's line. A pose only 10 m
    off (no overlap either, a small table) still runs, as before."""
    log = tmp_path / "log.clf"
    text = _carmen([10.0 + 0.2 * k for k in range(6)]).splitlines(keepends=True)
    far = text[3].replace(" 0.30000000000000004 0 0 0.30000000000000004 ", " 1e20 0 0 1e20 ")
    assert far != text[3]
    log.write_text("".join(text[:3] + [far] + text[4:]))
    out = tmp_path / "out.relations"
    _refused(["relations", "align", str(log), "-o", str(out), "--aligner", "icp"], capsys,
             f"{log}:4:", "the guess puts the scan of line 4 1e+20 m from the scan of line 1",
             "no placement it tries lets them overlap")  # fmt: skip
    assert not out.exists()
    # the global aligner (default): its chain links line 3 to line 4, refused the same way
    _refused(["relations", "align", str(log), "-o", str(out)], capsys, f"{log}:4:",
             "the guess puts the scan of line 4 1e+20 m from the scan of line 3",
             "no placement it tries lets them overlap")  # fmt: skip
    assert not out.exists()
    log.write_text("".join(text[:3] + [far.replace("1e20", "10")] + text[4:]))
    assert main(["relations", "align", str(log), "-o", str(out), "-q"]) == 0


def test_align_refuses_a_correlative_window_that_would_not_fit_in_memory(tmp_path, capsys):
    """``--search-xy 200`` on scans whose returns reach 1 m: the lookup table spans
    2 · (1 + 200 + 4 · 0.05 + 8 · 0.03) + 8 · 0.05 ≈ 403 m a side at 3 cm, ≈ 13,400² ≈ 1.8e8
    cells (1.3 GiB), beyond 2^27 ≈ 1.34e8: one clear error (exit 3) before any table is
    built, not a process that swaps or dies. The default window (±1.5 m) runs."""
    log = tmp_path / "log.clf"
    log.write_text(_carmen([10.0 + 0.2 * k for k in range(6)]))
    out = tmp_path / "out.relations"
    argv = ["relations", "align", str(log), "-o", str(out), "--aligner", "icp"]
    argv += ["--global-search", "always"]
    err = _refused([*argv, "--search-xy", "200"], capsys, f"{log}:",
                   "±200 m at 0.03 m cells", "would not fit in memory",
                   "limit 134217728 cells", "expected a smaller --search-xy")  # fmt: skip
    assert err.count("error") == 1
    assert not out.exists()
    assert main([*argv, "-q"]) == 0


@pytest.mark.parametrize("command", [["evaluate"], ["relations", "align"]])
def test_skip_invalid_poses_says_it_is_for_carmen_logs_only(tmp_path, capsys, command):
    """``--skip-invalid-poses`` reaches only the CARMEN reader (``skip_invalid`` of
    ``load_trajectory``); the help says so, and a TUM estimate with a NaN is still refused
    with it (exit 3), as the help promises."""
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--skip-invalid-poses" in help_text
    start = help_text.rindex("--skip-invalid-poses")
    assert "CARMEN logs only" in help_text[start : start + 400]
    est = tmp_path / "est.tum"
    est.write_text("10.0 0 0 0 0 0 0 1\n10.2 nan 0 0 0 0 0 1\n10.4 0.2 0 0 0 0 0 1\n")
    if command == ["evaluate"]:
        ref = tmp_path / "ref.tum"
        ref.write_text(_tum([10.0, 10.2, 10.4]))
        argv = ["evaluate", str(ref), str(est)]
    else:
        log = tmp_path / "log.clf"
        log.write_text(_carmen([10.0, 10.2, 10.4]))
        argv = ["relations", "align", str(log), "--estimate", str(est)]
        argv += ["-o", str(tmp_path / "out.relations")]
    _refused([*argv, "--skip-invalid-poses"], capsys, f"{est}:2:", "expected a finite number")
