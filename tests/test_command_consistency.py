"""Issue 25: the same file gets the same verdict from every command, and messages say what is
wrong (file, line, what was expected) without tracebacks or raw numpy warnings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main

# iSAM text in the format's own convention: square-root information (100 = 1/0.01)
ISAM_SQRT = (
    "ODOMETRY 0 1 1.0 0 0 100 0 0 100 0 500\n"
    "ODOMETRY 1 2 1.0 0 1.5707963 100 0 0 100 0 500\n"
    "LANDMARK 1 3 1.0 1.0 5 0 5\n"
    "LANDMARK 2 3 1.0 0.0 5 0 5\n"
)
# the same problem with covariances in the same places (as GTSAM's copy of Victoria Park)
ISAM_COV = (
    "ODOMETRY 0 1 1.0 0 0 0.0001 0 0 0.0001 0 4e-06\n"
    "ODOMETRY 1 2 1.0 0 1.5707963 0.0001 0 0 0.0001 0 4e-06\n"
    "LANDMARK 1 3 1.0 1.0 0.04 0 0.04\n"
    "LANDMARK 2 3 1.0 0.0 0.04 0 0.04\n"
)


def _verdicts(tmp_path: Path, src: Path, capsys: pytest.CaptureFixture[str], *extra: str):
    """Exit codes and stderr of `import isam` and `solve` on ``src``."""
    out = []
    n = len(list(tmp_path.glob("solved*")))
    for argv in (
        ["import", "isam", str(src), "-o", str(tmp_path / f"i{n}.g2o"), "-q", *extra],
        ["solve", str(src), "-o", str(tmp_path / f"solved{n or ''}"), "-q", *extra],
    ):
        rc = main(argv)
        out.append((rc, capsys.readouterr().err))
    return out


# ---------------------------------------------------------------- 1. one iSAM reader


@pytest.mark.parametrize(
    "prefix",
    [b"# an iSAM file\n", b"\xef\xbb\xbf", b"\xef\xbb\xbf# comment\n\n", b"\n  \n"],
    ids=["comment", "bom", "bom+comment", "blank"],
)
def test_import_isam_and_solve_read_the_same_isam_file(tmp_path, capsys, prefix):
    """`solve` used to sniff the first raw token: a comment or a BOM made it read the iSAM
    file as g2o and refuse what `import isam` reads."""
    src = tmp_path / "a.txt"
    src.write_bytes(prefix + ISAM_SQRT.encode())
    (imp_rc, imp_err), (solve_rc, solve_err) = _verdicts(tmp_path, src, capsys)
    assert imp_rc == 0 and solve_rc == 0, imp_err + solve_err
    assert "warning" not in imp_err + solve_err
    lms = np.genfromtxt(tmp_path / "solved" / "landmarks.csv", delimiter=",", names=True)
    assert int(lms["landmark"]) == 3


@pytest.mark.parametrize("kind", ["directory", "missing", "bad-line", "unreadable"])
def test_import_isam_and_solve_refuse_with_the_same_message(tmp_path, capsys, kind):
    src = tmp_path / "a.txt"
    if kind == "directory":
        src.mkdir()
        said = "is a directory, expected a text file"
    elif kind == "missing":
        said = "no such file"
    elif kind == "unreadable":
        src.write_text(ISAM_SQRT)
        src.chmod(0)
        if _can_read(src):
            pytest.skip("running as a user who reads files without permission (root)")
        said = "cannot read: permission denied"
    else:
        src.write_text("# head\n" + ISAM_SQRT.replace("1.0 0 0 100", "1.0 0 x 100", 1))
        said = "a.txt:2: ODOMETRY field 6: expected a number"
    (imp_rc, imp_err), (solve_rc, solve_err) = _verdicts(tmp_path, src, capsys)
    assert imp_rc == solve_rc == 3
    tail = lambda err: err.split(": error: ", 1)[1]  # noqa: E731
    assert tail(imp_err) == tail(solve_err)
    assert said in tail(imp_err).lower() if kind == "unreadable" else said in tail(imp_err)
    assert "Traceback" not in imp_err + solve_err


def _can_read(path: Path) -> bool:
    try:
        path.read_bytes()
    except PermissionError:
        return False
    return True


# ------------------------------------------------------- 2. the iSAM noise convention


def test_isam_default_is_the_formats_square_root_information(tmp_path, capsys):
    """iSAM's Loader reads the numbers as the upper-triangular R (RᵀR = Σ⁻¹): so does the
    default, and a file in that convention raises no warning."""
    from slamrel.formats.isam import read_isam

    src = tmp_path / "a.txt"
    src.write_text(ISAM_SQRT)
    d = read_isam(src)
    np.testing.assert_allclose(d.graph.pp_info[0], np.diag([1e4, 1e4, 2.5e5]))
    cov = tmp_path / "c.txt"
    cov.write_text(ISAM_COV)
    np.testing.assert_allclose(
        read_isam(cov, noise="covariance").graph.pp_info[0], d.graph.pp_info[0], rtol=1e-12
    )
    (imp_rc, imp_err), (solve_rc, solve_err) = _verdicts(tmp_path, src, capsys)
    assert imp_rc == solve_rc == 0 and imp_err == solve_err == ""


def test_isam_other_convention_is_warned_by_both_commands(tmp_path, capsys):
    src = tmp_path / "c.txt"
    src.write_text(ISAM_COV)
    for rc, err in _verdicts(tmp_path, src, capsys):
        assert rc == 0
        assert err.count("warning:") == 1, err  # the ODOMETRY lines say it; once
        assert "ODOMETRY noise read as sqrt-information" in err
        assert "look like a covariance (pass --noise covariance" in err
    for rc, err in _verdicts(tmp_path, src, capsys, "--noise", "covariance"):
        assert rc == 0 and err == ""
    # and the other way round: square-root information read as covariance
    sq = tmp_path / "s.txt"
    sq.write_text(ISAM_SQRT)
    for rc, err in _verdicts(tmp_path, sq, capsys, "--noise", "covariance"):
        assert rc == 0 and "look like a sqrt-information (pass --noise sqrt-information" in err


@pytest.mark.parametrize("command", [["import", "isam"], ["solve"]])
def test_isam_noise_convention_is_stated_in_the_help(capsys, command):
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "sqrt-information (default, iSAM's own definition)" in text
    assert "square-root information matrix R" in text


# ----------------------------------------- 3. what recover writes, evaluate reads back


@pytest.fixture(scope="module")
def sim_bundle(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim") / "sim"
    assert main(["simulate", "simple1", "--noise", "a", "--seed", "2", "-o", str(d), "-q"]) == 0
    return d


@pytest.mark.parametrize(
    "name,fmt", [("a.tum", None), ("a.csv", None), ("a.log", None), ("a.clf", None),
                 ("a.dat", "tum"), ("a.dat", "csv"), ("a.dat", "carmen"), ("a", None)]
)  # fmt: skip
def test_recover_output_reads_back_in_evaluate_with_the_same_numbers(
    tmp_path, sim_bundle, name, fmt
):
    """`recover -o traj.csv` wrote plain text into a .csv file, which evaluate reads as CSV
    and refused. Every format recover writes now reads back with the same poses and times."""
    from slamrel.formats.trajectories import read_trajectory

    ref = tmp_path / "ref.txt"
    assert main(["recover", str(sim_bundle), "-o", str(ref), "-q"]) == 0
    out = tmp_path / name
    argv = ["recover", str(sim_bundle), "-o", str(out), "-q"]
    assert main(argv + ([] if fmt is None else ["--format", fmt])) == 0
    want, got = read_trajectory(ref).trajectory, read_trajectory(out).trajectory
    np.testing.assert_array_equal(got.timestamps, want.timestamps)
    np.testing.assert_allclose(got.poses, want.poses, rtol=0, atol=1e-12)  # TUM: a quaternion
    assert main(["evaluate", str(sim_bundle), str(out), "--strategy", "consecutive", "-q"]) == 0


@pytest.mark.parametrize(
    "argv,said",
    [
        (["-o", "t.g2o"], "have no timestamps"),
        (["-o", "t.relations"], "holds relations between poses, not a trajectory"),
        (["-o", "t.csv", "--format", "plain"], "--format plain does not go with a .csv file"),
        (["-o", "t.tum", "--format", "csv"], "--format csv does not go with a .tum file"),
    ],
)
def test_recover_refuses_an_output_evaluate_would_misread(tmp_path, sim_bundle, capsys, argv, said):
    argv = [a if not a.startswith("t.") else str(tmp_path / a) for a in argv]
    assert main(["recover", str(sim_bundle), *argv, "-q"]) == 2  # an option mistake
    err = capsys.readouterr().err
    assert err.startswith("slamrel recover: error: argument -o/--output: ") and said in err
    assert list(tmp_path.iterdir()) == []  # before any work


# ----------------------------------------------- 4. compare's tables with odd names

ODD_DATASET = 'run #1, "a|b" $x$ & 50% c_d \\e'
ODD_ALGORITHMS = ("ekf|slam", "fast\nslam, #2 {x}~^")


def _per_relation(path: Path, seed: int, scale: float) -> str:
    rng = np.random.default_rng(seed)
    n = 80
    t = np.arange(n, dtype=float)
    err = scale * np.abs(rng.normal(1.0, 0.3, n))
    rows = ["t1,t2,i,j,trans_error,rot_error_rad,valid,via_odometry"]
    rows += [f"{a},{a + 1},{k},{k + 1},{e},{e / 10},1,0" for k, (a, e) in enumerate(zip(t, err))]
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def _md_cells(line: str) -> list[str]:
    """A Markdown table row split on its unescaped pipes, escapes undone."""
    import re

    inner = line.strip()[1:-1]
    cells = re.split(r"(?<!\\)((?:\\\\)*)\|", inner)
    # re.split keeps the even runs of backslashes before a real pipe: glue them back on
    out, k = [], 0
    while k < len(cells):
        cell = cells[k] + (cells[k + 1] if k + 1 < len(cells) else "")
        out.append(re.sub(r"\\(.)", r"\1", cell.strip()).replace("<br>", "\n"))
        k += 2
    return out


def test_compare_tables_survive_names_with_specials(tmp_path):
    import csv

    a = _per_relation(tmp_path / "a.csv", 1, 1.0)
    b = _per_relation(tmp_path / "b.csv", 2, 2.0)
    out = tmp_path / "cmp"
    argv = ["compare", f"{ODD_DATASET}:{ODD_ALGORITHMS[0]}={a}",
            f"{ODD_DATASET}:{ODD_ALGORITHMS[1]}={b}", "-o", str(out), "-q",
            "--resamples", "99"]  # fmt: skip
    assert main(argv) == 0
    # CSV: csv.reader gives the names back whole, every row as wide as the header
    with (out / "table.csv").open(newline="") as f:
        rows = list(csv.reader(f))
    assert len({len(r) for r in rows}) == 1 and len(rows) == 3
    assert [r[:2] for r in rows[1:]] == [[ODD_DATASET, alg] for alg in ODD_ALGORITHMS]
    with (out / "tests.csv").open(newline="") as f:
        tests = list(csv.DictReader(f))
    assert tests and all(t["dataset"] == ODD_DATASET for t in tests)
    assert {(t["a"], t["b"]) for t in tests} == {ODD_ALGORITHMS}
    # Markdown: split on the unescaped pipes, every row has the header's cells
    md = (out / "table.md").read_text().splitlines()
    table = md[: md.index("")]
    width = len(_md_cells(table[0]))
    assert all(len(_md_cells(x)) == width for x in table)
    assert [_md_cells(x)[:2] for x in table[2:]] == [[ODD_DATASET, a] for a in ODD_ALGORITHMS]
    assert "\\$x\\$" in table[2] and "\\|" in table[2]  # no math, no cell break
    test_rows = [x for x in md if x.startswith("| run")]
    assert test_rows[2:] and all(len(_md_cells(x)) == 15 for x in test_rows[2:])
    # LaTeX: every special escaped, one line per row
    tex = (out / "table.tex").read_text()
    body = [x for x in tex.splitlines() if x.startswith("run")]
    assert len(body) == 2
    assert body[0].startswith(r'run \#1, "a|b" \$x\$ \& 50\% c\_d \textbackslash{}e & ekf|slam & ')
    assert r"fast slam, \#2 \{x\}\textasciitilde{}\textasciicircum{} & " in body[1]


# ------------------------------------------------------------------------ 5. messages


def test_complex_npy_says_complex_not_pickled(tmp_path, capsys):
    """A complex map_covariance.npy was reported as "(pickled objects are never loaded)"."""
    from slamrel.formats.bundle import write_bundle
    from slamrel.simulation.bundles import simulate_bundle

    b = simulate_bundle(2, steps=40, map_sigma=(0.02, 0.05), map_covariance=True)
    write_bundle(tmp_path / "b", b)
    p = tmp_path / "b" / "map_covariance.npy"
    np.save(p, np.eye(2 * b.map_ids.size, dtype=np.complex128))
    assert main(["recover", str(tmp_path / "b"), "-o", str(tmp_path / "t.txt"), "-q"]) == 3
    err = capsys.readouterr().err
    assert f"{p}: expected real float64, got complex128;" in err and "pickle" not in err


def test_false_not_converged_at_a_cost_of_rounding_level(tmp_path, capsys):
    """A cost of 9e-15 halved by the last allowed step was "NOT converged": the relative
    decrease of a cost at the level of rounding compares noise with noise."""
    src = tmp_path / "s.txt"
    src.write_text(ISAM_SQRT)
    argv = ["solve", str(src), "-o", str(tmp_path / "o"), "--batch", "0", "--max-iterations", "1"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("converged after 1 iterations") and captured.err == ""


def test_compare_spec_mistake_is_an_option_error(tmp_path, capsys):
    assert main(["compare", "nonsense", "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("slamrel compare: error: argument RESULT: 'nonsense': expected ")


def test_import_mrclam_fit_errors_name_the_file(tmp_path, capsys):
    """The calibration's 'overlap too short' named only the dataset folder."""
    d = tmp_path / "M"
    d.mkdir()
    (d / "Barcodes.dat").write_text("# subject barcode\n1 5\n2 14\n6 27\n")
    (d / "Landmark_Groundtruth.dat").write_text("# subject x y sx sy\n6 1.0 2.0 0.001 0.001\n")
    t = np.arange(0.0, 5.0, 0.02)
    (d / "Robot1_Odometry.dat").write_text("".join(f"{x:.3f} 0.1 0.0\n" for x in t))
    (d / "Robot1_Groundtruth.dat").write_text(
        "".join(f"{x:.3f} {0.1 * x:.6f} 0.0 0.0\n" for x in t)
    )
    (d / "Robot1_Measurement.dat").write_text("1.000 27 1.5 0.1\n2.000 27 1.4 0.1\n")
    rc = main(["import", "mrclam", str(d), "--robot", "1", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 3, err
    assert f"{d / 'Robot1_Odometry.dat'}: odometry and ground truth overlap for" in err
    assert "compared with Robot1_Groundtruth.dat" in err and "Traceback" not in err
