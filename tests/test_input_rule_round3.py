"""Issue 39, what was left: every error names its file (and line), ids exact, plain numbers.

Each test feeds the CLI (or, for another helper's module, the function the CLI calls) an
input whose error used to name no file, print ``np.float64(...)``, read the wrong id, or
speak bad grammar, and checks the one clear message now given.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relation_metric.errors import InputError
from slamrel.cli import main

_SQRT_INFO = "1 0 0 1 0 1"  # iSAM's upper-triangular square-root information (identity)


def _err(argv: list[str], capsys: pytest.CaptureFixture[str], code: int = 3) -> str:
    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    return err


def _plain(path: Path, rows: str) -> str:
    path.write_text(rows)
    return str(path)


def test_a_one_pose_reference_is_named(tmp_path, capsys):
    """ "needs at least 2 poses" used to name no file (evaluate and relations generate)."""
    one = _plain(tmp_path / "one.txt", "0 0 0 0\n")
    two = _plain(tmp_path / "two.txt", "0 0 0 0\n1 1 0 0\n")
    for argv in (
        ["evaluate", one, two, "-q"],
        ["evaluate", "--strategy", "loops", one, two, "-q"],
        ["relations", "generate", one, "-o", str(tmp_path / "x.relations"), "-q"],
    ):
        err = _err(argv, capsys)
        assert f"{one}: a reference trajectory needs at least 2 poses, has 1" in err, err
    assert not (tmp_path / "x.relations").exists()


def test_sync_with_one_matched_pose_names_both_files(tmp_path, capsys):
    ref = _plain(tmp_path / "ref.txt", "0 0 0 0\n1 1 0 0\n2 2 0 0\n")
    est = _plain(tmp_path / "est.txt", "0 0 0 0\n1.5 1 0 0\n2.5 2 0 0\n")
    err = _err(["evaluate", "--sync", ref, est, "-q"], capsys)
    assert f"{ref}: --sync pairs only 1 pose(s) with {est}" in err
    assert "--max-time-diff 0.1 s; relations need at least 2" in err


def test_isam_fractional_id_is_refused_at_its_line(tmp_path, capsys):
    f = _plain(
        tmp_path / "g.txt",
        f"ODOMETRY 0 1 1 0 0 {_SQRT_INFO}\nODOMETRY 1 2.5 1 0 0 {_SQRT_INFO}\n",
    )
    err = _err(["solve", f, "-o", str(tmp_path / "out"), "-q"], capsys)
    assert f"{f}:2:" in err and "'ODOMETRY id 2': expected an integer id, got 2.5" in err


def test_isam_ids_beyond_2_53_are_exact(tmp_path, capsys):
    """2**60 + 1 and 2**60 + 2 are read as written (they used to be refused as float ids);
    a LANDMARK seen from the missing pose 2**60 — one double with 2**60 + 1 — is refused at
    its line instead of landing on pose 2**60 + 1."""
    big = 2**60
    odo = (
        f"ODOMETRY 0 {big + 1} 1 0 0 {_SQRT_INFO}\n"
        f"ODOMETRY {big + 1} {big + 2} 1 0 0 {_SQRT_INFO}\n"
    )
    good = _plain(tmp_path / "good.txt", odo)
    out = tmp_path / "out"
    assert main(["solve", good, "-o", str(out), "-q"]) == 0
    vertices = [ln.split()[1] for ln in (out / "solved.g2o").read_text().splitlines()[:3]]
    assert vertices == ["0", str(big + 1), str(big + 2)]
    bad = _plain(tmp_path / "bad.txt", odo + f"LANDMARK {big} 5 1 0 1 0 1\n")
    err = _err(["solve", bad, "-o", str(tmp_path / "out2"), "-q"], capsys)
    assert f"{bad}:3: LANDMARK seen from unknown pose {big}" in err


def test_resumable_folder_message_grammar(tmp_path):
    from slamrel.outputs import resumable_directory

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    with pytest.raises(InputError, match="is not an evaluate-batch folder slamrel wrote"):
        resumable_directory(foreign, kind="evaluate-batch")
    with pytest.raises(InputError, match="is not a pose-only-study folder slamrel wrote"):
        resumable_directory(foreign, kind="pose-only-study")


def test_align_at_times_without_scans_are_plain_numbers():
    """``relations align --at``: the times of the first relation without a scan used to be
    shown as ``np.float64(101.0)``."""
    from slamrel.scans.proposals import pairs_at_times

    t = np.array([0.0, 0.2, 0.4])
    with pytest.raises(InputError) as err:
        pairs_at_times(t, np.array([0.0, 101.0]), np.array([0.2, 0.25]), tolerance=0.02)
    assert "relation 2 (101.0 0.25), is 101 s from the nearest scan" in str(err.value)
    assert "np." not in str(err.value)


# ------------------------------------- map-compare and review when no pair is found


def _far_maps(tmp_path: Path) -> tuple[str, str]:
    """Two valid maps the automatic association cannot pair (no shared id, no shape in
    common within the cut-off): a person can still pair them by hand."""
    est = _plain(tmp_path / "est.csv", "id,x,y\n1,0,0\n2,10,0\n3,0,10\n4,10,10\n")
    ref = _plain(tmp_path / "ref.csv", "id,x,y\n11,100,100\n12,150,100\n13,100,150\n14,160,160\n")
    return est, ref


def test_map_compare_without_any_pair_still_writes_its_outputs(tmp_path, capsys):
    """It used to exit 3 ("found no consistent pair") and write no page to pair by hand."""
    import json

    est, ref = _far_maps(tmp_path)
    page, out = tmp_path / "r.html", tmp_path / "mc.json"
    argv = ["map-compare", est, ref, "--review", str(page), "--json", str(out)]
    err = _err([*argv, "--per-edge", str(tmp_path / "e.csv")], capsys, code=0)
    assert "found no consistent pair of landmarks: 0 pairs" in err
    assert "on the page of --review (or slamrel review)" in err
    a = json.loads(out.read_text())["association"]
    assert (a["matched"], a["missed"], a["spurious"]) == (0, 4, 4)
    assert a["missed_ids"] == [11, 12, 13, 14] and a["spurious_ids"] == [1, 2, 3, 4]
    assert "0 pairs" in a["cautions"][0]
    assert page.stat().st_size > 1000
    assert (tmp_path / "e.csv").read_text().count("\n") == 1  # the header, no edge
    # the pairs the user asked for by id stay the user's: none is still an error
    _err(["map-compare", est, ref, "--associate", "id"], capsys)


@pytest.mark.parametrize("mode", ["auto", "id-or-auto"])
def test_review_without_any_pair_writes_the_page(tmp_path, capsys, mode):
    est, ref = _far_maps(tmp_path)
    page = tmp_path / "r.html"
    assert main(["review", est, ref, "-o", str(page), "--associate", mode]) == 0
    out, err = capsys.readouterr()
    assert "0 proposed pairs" in out and "4 missed, 4 spurious" in out
    assert "0 pairs" in err and "pair the landmarks by hand on this page" in err
    assert page.stat().st_size > 1000


# ------------------------------ information beyond what a solve can sum (no bug warning)

_G2O = (
    "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
    "EDGE_SE2 0 1 1 0 0 {i} 0 0 {i} 0 {i}\n"
    "EDGE_SE2 1 2 1 0.1 0 1 0 0 1 0 1\n"
    "EDGE_SE2 0 2 2.5 0 0 {i} 0 0 {i} 0 {i}\n"  # a loop that disagrees by 0.5 m
)


def test_g2o_information_beyond_1e200_is_refused_at_its_line(tmp_path, capsys):
    """Information 1e300 on a loop that disagrees: the solve overflowed (slamrel's own
    "floating-point problem … bug" warning, then "singular"). Refused at the edge's line;
    1e200 (a standard deviation of 1e-100) still solves, without a warning."""
    f = _plain(tmp_path / "g.g2o", _G2O.format(i="1e300"))
    err = _err(["solve", f, "-o", str(tmp_path / "out"), "-q"], capsys)
    assert f"{f}:4: EDGE_SE2 information matrix: an entry of 1e+300 is beyond 1e+200" in err
    assert "floating-point problem" not in err
    ok = _plain(tmp_path / "ok.g2o", _G2O.format(i="1e200"))
    assert main(["solve", ok, "-o", str(tmp_path / "ok"), "-q"]) == 0
    assert capsys.readouterr().err == ""


def test_toro_and_isam_information_beyond_1e200_are_refused(tmp_path, capsys):
    toro = _plain(
        tmp_path / "t.graph",
        "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1e300 0 1e300 1e300 0 0\n",
    )
    err = _err(["solve", toro, "-o", str(tmp_path / "o1"), "-q"], capsys)
    assert f"{toro}:3: EDGE2 information matrix: an entry of 1e+300 is beyond 1e+200" in err
    isam = _plain(
        tmp_path / "i.txt",
        f"ODOMETRY 0 1 1 0 0 1e150 0 0 1 0 1\nODOMETRY 1 2 1 0 0 {_SQRT_INFO}\n",
    )
    err = _err(["solve", isam, "-o", str(tmp_path / "o2"), "-q"], capsys)
    assert f"{isam}:1: ODOMETRY: square-root information entry 1e+150 is beyond 1e+100" in err
    tiny = _plain(
        tmp_path / "c.txt",
        "ODOMETRY 0 1 1 0 0 1e-250 0 0 1e-250 0 1e-250\nODOMETRY 1 2 1 0 0 1 0 0 1 0 1\n",
    )
    err = _err(["solve", tiny, "--noise", "covariance", "-o", str(tmp_path / "o3")], capsys)
    assert f"{tiny}:1: ODOMETRY information (inverse covariance): an entry of 1e+250" in err


# ------------------------------------------------ MRCLAM: odd-but-valid and repeated rows


def test_mrclam_nonpositive_ranges_are_left_out_counted_and_named(tmp_path):
    """A range of 0 or below (the dataset holds −0.035 m) used to refuse the whole run with
    an error naming only the folder. Left out, counted, the first named by file and line."""
    from slamrel.importers.mrclam import read_mrclam_robot
    from tests.test_importers_mrclam import make_dataset

    rows = ["10.1 63 1.5 0.1\n", "10.2 63 -0.035 0.1\n", "10.3 81 0 0.2\n", "10.7 81 3 0.5\n"]
    d = make_dataset(tmp_path, measurement_rows=rows)
    with pytest.warns(UserWarning) as caught:
        r = read_mrclam_robot(d, 1)
    said = " ".join(str(w.message) for w in caught)
    assert "Robot1_Measurement.dat: 2 measurement(s) with a range of 0 or below left out" in said
    assert "(the first at line 4: range -0.035)" in said
    assert r.nonpositive_ranges == 2
    np.testing.assert_allclose(r.measurements[:, :2], [[10.1, 1.5], [10.7, 3.0]])


def test_mrclam_landmark_surveyed_twice_is_refused_at_its_line(tmp_path, capsys):
    from tests.test_importers_mrclam import HEAD, make_dataset

    d = make_dataset(tmp_path)
    lm = d / "Landmark_Groundtruth.dat"
    lm.write_text(HEAD + "6 1.0 2.0 0.01 0.01\n7 3.0 4.0 0.01 0.01\n6 5.0 6.0 0.01 0.01\n")
    err = _err(["import", "mrclam", str(d), "--robot", "1", "-o", str(tmp_path / "b")], capsys)
    assert f"{lm}:5: landmark subject 6 is given twice (first at line 3)" in err
    assert not (tmp_path / "b").exists()


def test_slam_known_association_names_the_measurement_without_an_id(tmp_path, capsys):
    """It used to say only the bundle folder ("needs a landmark id for every measurement")."""
    from tests.test_readers_fuzz import BUNDLE

    b = tmp_path / "log"
    b.mkdir()
    for name, text in BUNDLE.items():
        (b / name).write_text(text)  # measurements.csv line 3 has an empty landmark field
    err = _err(["slam", str(b), "-o", str(tmp_path / "out")], capsys)
    assert f"{b / 'measurements.csv'}:3: measurement without a landmark id" in err
    assert "--association nn associates them by nearest neighbour" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("topic", ["/pose", "/odom"])
def test_a_nan_pose_in_a_bag_names_the_bag_topic_and_message(tmp_path, capsys, topic):
    """It used to say "pose 5 is not finite" with no file (the bag reader built the
    trajectory without saying where its rows came from)."""
    pytest.importorskip("rosbags")
    from tests.test_bags import _truth, _write

    truth = _truth(np.random.default_rng(0))
    truth["xyz"][5, 0] = np.nan
    bag = _write(tmp_path / "nan.bag", "ros1", truth)
    err = _err(["evaluate", f"{bag}:{topic}", f"{bag}:/posecov", "-q"], capsys)
    assert f"{bag}: topic '{topic}', message 6 of " in err
    assert "x = nan; expected finite numbers (1 such message(s))" in err


def test_a_full_disk_at_the_lock_file_is_one_error_and_leaves_no_lock(
    tmp_path, capsys, monkeypatch
):
    """ENOSPC while writing the pid into the output's lock file: it used to escape as a raw
    OSError and leave an empty ``.NAME.slamrel-lock`` behind."""
    import errno
    import os

    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "pwrite", full)
    out = tmp_path / "sim"
    err = _err(["simulate", "simple1", "-o", str(out), "-q"], capsys)
    assert f"{out}: cannot write its lock file: no space left on the device" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_nees_with_a_covariance_too_small_to_invert_usefully_is_refused(tmp_path, capsys):
    """Variance 1e-300: the NEES overflowed (slamrel's own "floating-point problem … bug"
    warnings, then a mean of 3e295, exit 0). Refused at its line; 1e-150 is still scored."""
    truth = _plain(tmp_path / "truth.txt", "0 0 0 0\n1 1 0 0\n2 2 0 0\n")
    rows = "1 1 0.01 0 0.01 0 0 0.01 0 0.01\n2 2 0 0.01 0.01 0 0 0.01 0 0.01\n"
    tiny = _plain(tmp_path / "c.txt", "0 0.01 0 0 1e-300 0 0 1e-300 0 1e-300\n" + rows)
    err = _err(["nees", truth, tiny], capsys)
    assert f"{tiny}:1: information (inverse covariance; a variance below about 1e-200)" in err
    assert "floating-point problem" not in err
    ok = _plain(tmp_path / "ok.txt", "0 0.01 0 0 1e-150 0 0 1e-150 0 1e-150\n" + rows)
    assert main(["nees", truth, ok, "-q"]) == 0
    assert "floating-point problem" not in capsys.readouterr().err


@pytest.mark.parametrize(
    ("options", "knob"),
    [
        (["--strategy", "distance", "--distance", "5"], "(a smaller --distance)"),
        (["--strategy", "time", "--seconds", "5"], "(fewer --seconds)"),
        (["--step", "3"], "(a smaller --step)"),
    ],
)
def test_no_relation_selected_names_the_option_that_would_select_some(
    tmp_path, capsys, options, knob
):
    """The hint used to list options the command does not have (--delta)."""
    two = _plain(tmp_path / "two.txt", "0 0 0 0\n1 1 0 0\n")
    err = _err(["evaluate", *options, two, two, "-q"], capsys)
    assert f"{two}: no relation was selected" in err and knob in err
    assert "--delta" not in err


def test_a_disconnected_graph_names_the_file_ids(tmp_path, capsys):
    """It said "pose #1 (0-based, in file order)": an index in id order, not the file's
    order nor its id. The file ids now: vertex 30 is cut off from vertex 10 (the gauge)."""
    f = _plain(
        tmp_path / "g.g2o",
        "VERTEX_SE2 30 2 0 0\nVERTEX_SE2 10 0 0 0\nVERTEX_SE2 20 1 0 0\n"
        "EDGE_SE2 10 20 1 0 0 1 0 0 1 0 1\n",
    )
    err = _err(["solve", f, "-o", str(tmp_path / "out"), "-q"], capsys)
    assert "2 disconnected parts (sizes 2, 1)" in err
    assert "e.g. pose 30, share no factor with pose 10, which holds the gauge" in err


# ------------------------------- a bundle's controls and initial_pose beyond float64's reach


def _bundle(tmp_path: Path, **files: str) -> Path:
    from tests.test_readers_fuzz import BUNDLE

    b = tmp_path / "b"
    b.mkdir()
    for name, text in {**BUNDLE, **files}.items():
        (b / name).write_text(text)
    return b


@pytest.mark.parametrize(
    ("rows", "said"),
    [
        ("0,1e300,0\n1,1,0.1\n", "controls.csv:2: v = 1e+300: beyond 1e+30 m/s"),
        ("0,1,0\n1,1,-1e300\n", "controls.csv:3: omega = -1e+300: beyond 1e+30 rad/s"),
        ("0,1,0\n1e300,1,0.1\n2e300,0,0\n", "controls.csv:2: v = 1: the controls' path up to"),
        ("0,1,0\n1,3e29,0\n", "controls.csv:3: v = 3e+29: the controls' path up to this row"),
    ],
)
def test_controls_beyond_float64s_reach_are_refused_at_their_line(tmp_path, capsys, rows, said):
    """v = 1e300 used to run, with slamrel's own "floating-point problem … bug" warnings (an
    omega of 1e300: exit 0 with them). The speed, yaw rate, and the path and turn of the held
    rows (Σ |v| Δt: 3e29 m/s held for 8 s) are bounded like positions (1e30)."""
    end = "" if "e300,0,0" in rows else "9,0,0\n"
    b = _bundle(tmp_path, **{"controls.csv": "t,v,omega\n" + rows + end})
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt"), "-q"], capsys)
    assert f"{b / said}" in err, err
    assert "floating-point problem" not in err
    assert not (tmp_path / "x.txt").exists()


def test_controls_inside_the_bound_give_no_bug_warning(tmp_path, capsys):
    """v = 1e29 m/s held for 1 s (path 1e29 m < 1e30): read. The filter then places the robot
    1e29 m away, where its metre-scale covariance and the map are lost in rounding: one
    error naming the bundle (exit 3), and none of slamrel's own "floating-point problem"
    warnings."""
    b = _bundle(tmp_path, **{"controls.csv": "t,v,omega\n0,1e29,0\n1,1,0.1\n2,1,0.1\n3,0,0\n"})
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt"), "--method", "filter"], capsys)
    assert f"error: {b}: " in err and "floating-point problem" not in err
    # the smoother: a recovered position beyond 1e30 m is a divergence, not "pose 1: position
    # (4e+28, 3.5e+54) is beyond 1e+30 m; expected coordinates in metres" about no file; which
    # of the two the rounding reaches first depends on the numpy build (numpy 2.4: the
    # smoother's factorisation fails before the divergence check): either names the bundle
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt")], capsys)
    assert f"error: {b}: " in err and "pose 1: position" not in err
    assert "diverged at t=" in err or "the smoother could not factor" in err


@pytest.mark.parametrize("model", ["velocity", "odometry"])
def test_a_log_spanning_no_time_names_its_file(tmp_path, capsys, model):
    """It used to name the bundle folder only ("the controls/odometry span no time")."""
    files = {"controls.csv": "t,v,omega\n1,1,0\n1,1,0.1\n"}
    name = "controls.csv"
    if model == "odometry":
        manifest = json.loads(_bundle_json())
        manifest["motion_model"] = {
            "type": "odometry",
            "sigma_x": 0.1,
            "sigma_y": 0.1,
            "sigma_theta": 0.01,
        }
        files = {"bundle.json": json.dumps(manifest), "odometry.csv": "t,x,y,theta\n1,0,0,0\n"
                 "1,1,0,0\n"}  # fmt: skip
        name = "odometry.csv"
    b = _bundle(tmp_path, **files)
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt"), "-q"], capsys)
    line = ":3" if model == "velocity" else ""
    assert f"{b / name}{line}: all 2 {'control' if line else 'odometry'} rows have t = 1.0" in err
    assert "span" in err


def _bundle_json() -> str:
    from tests.test_readers_fuzz import BUNDLE_JSON

    return BUNDLE_JSON


@pytest.mark.parametrize(("pose", "said"), [([1e31, 0, 0], "x = 1e+31"), ([0, 0, -2e30], "θ")])
def test_initial_pose_beyond_1e30_is_refused_at_its_line(tmp_path, capsys, pose, said):
    """1e31 used to be accepted (the filter then named no line, the smoother "diverged")."""
    manifest = json.loads(_bundle_json())
    manifest["initial_pose"] = pose
    b = _bundle(tmp_path, **{"bundle.json": json.dumps(manifest, indent=2)})
    line = 1 + json.dumps(manifest, indent=2).splitlines().index('  "initial_pose": [')
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt"), "-q"], capsys)
    assert f"{b / 'bundle.json'}:{line}: initial_pose: {said}" in err, err
    assert "is beyond 1e+30" in err


@pytest.mark.parametrize("method", ["smoother", "batch"])
def test_noise_beyond_float64s_precision_is_an_error_not_a_crash(tmp_path, capsys, method):
    """sigma_v = sigma_omega = 1e10 (allowed: below 1e30) swamps the initial covariance: the
    smoother's prior covariances are singular in float64. It used to be "internal error
    (LinAlgError: Singular matrix)", exit 1."""
    manifest = json.loads(_bundle_json())
    manifest["motion_model"] = {"type": "velocity", "sigma_v": 1e10, "sigma_omega": 1e10}
    b = _bundle(tmp_path, **{"bundle.json": json.dumps(manifest)})
    err = _err(["recover", str(b), "--method", method, "-o", str(tmp_path / "x.txt")], capsys)
    assert f"{b}: the {method} could not factor a covariance" in err
    assert "method filter" in err and not (tmp_path / "x.txt").exists()


def test_slam_far_from_the_origin_gives_no_bug_warning(tmp_path, capsys):
    """initial_pose (1e30, -1e30): a 1.5 m range is lost in rounding, so a new landmark lands
    on the robot's very position and the next nearest-neighbour search divided 0 by 0
    (slamrel's own "floating-point problem … bug" warning). Such a landmark has no range or
    bearing: no measurement is associated with it."""
    manifest = json.loads(_bundle_json())
    manifest["initial_pose"] = [1e30, -1e30, 0]
    b = _bundle(tmp_path, **{"bundle.json": json.dumps(manifest)})
    out = tmp_path / "s"
    assert main(["slam", str(b), "-o", str(out), "--association", "nn"]) == 0
    got = capsys.readouterr()
    assert "floating-point problem" not in got.err, got.err
    assert "EKF-SLAM: 3 landmarks" in got.out


@pytest.mark.parametrize("aligner", ["global", "icp"])
def test_align_with_no_pair_selected_writes_an_empty_set(tmp_path, capsys, aligner):
    """--distance inf (or 1e300) selects no pair: the global aligner's chain indexed an empty
    list ("internal error (IndexError …)"); both aligners now say 0 relations, exit 0."""
    from tests.test_input_rule import _carmen

    log = tmp_path / "log.clf"
    log.write_text(_carmen([10.0 + 0.2 * k for k in range(8)]))
    out = tmp_path / "o.relations"
    argv = ["relations", "align", str(log), "-o", str(out), "--aligner", aligner]
    assert main([*argv, "--distance", "inf", "--angle", "inf"]) == 0
    said = capsys.readouterr()
    assert "0 relations from 8 FLASER scans" in said.out and "internal error" not in said.err
    assert [ln for ln in out.read_text().splitlines() if not ln.startswith("#")] == []


def test_a_json_integer_beyond_pythons_digit_limit_is_refused_at_its_line(tmp_path, capsys):
    """A 5,000-digit integer in bundle.json: Python refuses to convert it ("internal error
    (ValueError: Exceeds the limit (4300 digits) …)"). Refused at its line."""
    text = _bundle_json().replace('"sigma_v": 0.1', '"sigma_v": ' + "9" * 5000)
    b = _bundle(tmp_path, **{"bundle.json": text})
    line = 1 + next(k for k, ln in enumerate(text.splitlines()) if "9999" in ln)
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt")], capsys)
    assert f"{b / 'bundle.json'}:{line}: a number of more than 4300 digits" in err


def test_a_step_covariance_beyond_1e60_is_refused_at_its_line(tmp_path, capsys):
    """An entry of 1e300 in step_covariance.csv used to run into "filter diverged" naming
    only the folder; 1e60 (the largest variance a model accepts) is the bound."""
    manifest = json.loads(_bundle_json())
    manifest["motion_model"] = {"type": "velocity", "step_covariance": {"frame": "body"}}
    rows = "".join(f"{t},0.01,0,0,0.01,0,0.001\n" for t in range(4)).replace("1,0.01", "1,1e300")
    b = _bundle(
        tmp_path,
        **{
            "bundle.json": json.dumps(manifest),
            "step_covariance.csv": "t,cxx,cxy,cxt,cyy,cyt,ctt\n" + rows,
        },
    )
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt")], capsys)
    assert f"{b / 'step_covariance.csv'}:3: step covariance: an entry of 1e+300 is beyond" in err


@pytest.mark.parametrize("option", ["--time-tolerance", "--loop-min-travel"])
@pytest.mark.parametrize("value", ["-1", "nan"])
def test_align_refuses_a_negative_or_nan_tolerance(tmp_path, capsys, option, value):
    """--time-tolerance and --loop-min-travel of -1 or nan were accepted (exit 0, the value
    unused without --at / --loops, or a loop rule that compares nothing): exit 2 now."""
    from tests.test_input_rule import _carmen

    log = tmp_path / "log.clf"
    log.write_text(_carmen([10.0 + 0.2 * k for k in range(4)]))
    out = tmp_path / "o.relations"
    argv = ["relations", "align", str(log), "-o", str(out), "--loops", option, value]
    assert main(argv) == 2
    assert f"{option} must be 0 or more" in capsys.readouterr().err
    assert not out.exists()


def test_a_json_integer_beyond_float64_is_refused_not_a_crash(tmp_path, capsys):
    """A 400-digit integer in initial_pose: math.isfinite raised OverflowError ("internal
    error (OverflowError: int too large to convert to float)"). Refused as not finite."""
    manifest = json.loads(_bundle_json())
    manifest["initial_pose"] = [10**400 - 1, 0, 0]
    b = _bundle(tmp_path, **{"bundle.json": json.dumps(manifest, indent=2)})
    err = _err(["recover", str(b), "-o", str(tmp_path / "x.txt")], capsys)
    assert f"{b / 'bundle.json'}:" in err
    assert "initial_pose: expected a finite number, got 9999999999" in err


@pytest.mark.parametrize("value", ["0", "-5", "181", "nan"])
def test_align_refuses_a_loop_max_angle_out_of_range(tmp_path, capsys, value):
    """--loop-max-angle is a heading difference in (0, 180] degrees: else exit 2."""
    from tests.test_input_rule import _carmen

    log = tmp_path / "log.clf"
    log.write_text(_carmen([10.0 + 0.2 * k for k in range(4)]))
    out = tmp_path / "o.relations"
    argv = ["relations", "align", str(log), "-o", str(out), "--loops"]
    assert main([*argv, "--loop-max-angle", value]) == 2
    assert "--loop-max-angle must lie in (0, 180] degrees" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_loop_max_angle_drops_the_loop_pairs_seen_from_opposite_headings(tmp_path, capsys):
    """Out 4 m along x, a half turn on the spot, back along −x: every loop pair joins the two
    legs, seen from headings π apart. At 180° (the default) they are proposed; at 45° none
    is, and the pairs are exactly the consecutive ones (the run without --loops)."""
    from tests.test_proposals import report_rows

    poses = [(0.25 * k, 0.0, 0.0) for k in range(17)]
    poses += [(4.0, 0.0, 0.25 * k) for k in range(1, 13)] + [(4.0, 0.0, np.pi)]
    poses += [(4.0 - 0.25 * k, 0.0, np.pi) for k in range(1, 17)]
    rows = report_rows(tmp_path, poses)
    loops = ["--loops", "--loop-min-travel", "2"]
    consecutive = rows()
    assert rows(*loops, "--loop-max-angle", "45") == consecutive
    assert rows(*loops, "--loop-max-angle", "180") > consecutive
