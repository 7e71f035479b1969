"""The output rule of every command, driven through the CLI (docs/commands.md, "Outputs").

One test per class, parametrised over the commands: outputs that are, lie inside or contain an
input are refused and nothing on disk changes; a foreign folder is never replaced; a slamrel
folder is replaced whole with ``--force``; a failed or interrupted write leaves the previous
output intact; files and folders follow the umask; outputs are checked before any work.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import stat
from collections.abc import Callable
from pathlib import Path

import pytest

from slamrel import outputs
from slamrel.cli import main
from slamrel.outputs import MANIFEST

ISAM = """ODOMETRY 0 1 1.0 0 0 10 0 0 10 0 100
LANDMARK 1 2 1.0 1.0 5 0 5
ODOMETRY 1 3 1.0 0 1.5707963 10 0.1 0 10 0 100
LANDMARK 3 2 1.0 0.0 5 0 5
"""

Argv = Callable[[Path, str], list[str]]

# Commands whose output is a folder: argv from (inputs root, output path).
FOLDER: dict[str, Argv] = {
    "run": lambda r, o: ["run", str(r / "S"), "-o", o],
    "simulate": lambda r, o: ["simulate", "simple1", "--noise", "a", "--seed", "0", "-o", o],
    "slam": lambda r, o: ["slam", str(r / "B"), "-o", o, "--store-online"],
    "import-isam": lambda r, o: [
        "import",
        "isam",
        str(r / "a.txt"),
        "-o",
        str(r / "side.g2o"),
        "--bundle",
        o,
    ],  # fmt: skip
    "solve": lambda r, o: ["solve", str(r / "a.g2o"), "-o", o],
    "compare": lambda r, o: [
        "compare",
        f"d:est={r / 'per1.csv'}",
        f"d:ref={r / 'per2.csv'}",
        "-o",
        o,
    ],  # fmt: skip
    "example": lambda r, o: ["example", "-o", o],
    # needs the real MRCLAM logs to succeed: used where the command is refused before reading
    "import-mrclam": lambda r, o: ["import", "mrclam", str(r / "M"), "-o", o],
}
RUNNABLE_FOLDER = [k for k in FOLDER if k != "import-mrclam"]

# Commands whose outputs are files.
FILE: dict[str, Argv] = {
    "recover": lambda r, o: ["recover", str(r / "S"), "-o", o],
    "evaluate": lambda r, o: [
        "evaluate",
        str(r / "ex" / "reference.relations"),
        str(r / "ex" / "estimate.txt"),
        "--json",
        o,
    ],  # fmt: skip
    "relations": lambda r, o: ["relations", "generate", str(r / "ex" / "reference.txt"), "-o", o],
    "map-compare": lambda r, o: [
        "map-compare",
        str(r / "S" / "map.csv"),
        str(r / "B" / "landmarks_groundtruth.csv"),
        "--json",
        o,
    ],  # fmt: skip
    "import-isam": lambda r, o: ["import", "isam", str(r / "a.txt"), "-o", o],
}


def _written() -> list[object]:
    """(kind, command) of every command that writes, for the failed-write and umask tests:
    ``slamrel run`` renders a report with four figures each time, so its cases there are the
    full tier's; its ``--force`` case and every refusal stay in the default tier."""
    folders = [
        pytest.param("folder", c, marks=pytest.mark.slow) if c == "run" else ("folder", c)
        for c in RUNNABLE_FOLDER
    ]
    return folders + [("file", c) for c in FILE]


# The function that does each command's first real work (reading inputs or computing).
HEAVY = {  # the module that owns it: commands import the library inside their run functions
    "run": ("slamrel.pipeline", "read_run_input"),  # SOURCE is a bundle folder here
    "simulate": ("slamrel.simulation.worlds", "make_world"),
    "slam": ("slamrel.formats.bundle", "read_bundle"),
    "import-isam": ("slamrel.formats.isam", "read_isam"),
    "import-mrclam": ("slamrel.importers.mrclam", "mrclam_bundle"),
    "solve": ("slamrel.commands.solve", "_load"),
    "compare": ("slamrel.report.tables", "read_per_relation"),
    "example": ("slamrel.simulation.example", "example_pair"),
    "recover": ("slamrel.formats.bundle", "read_bundle"),
    "evaluate": ("slamrel.evaluation", "load_reference"),
    "relations": ("slamrel.evaluation", "load_trajectory"),
    "map-compare": ("slamrel.formats.landmark_maps", "read_map"),
}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Small inputs of every command, built once through the CLI."""
    r = tmp_path_factory.mktemp("inputs")
    q = ["-q"]
    assert main(["simulate", "simple1", "--noise", "a", "--seed", "0", "-o", str(r / "B"), *q]) == 0
    assert main(["slam", str(r / "B"), "-o", str(r / "S"), *q]) == 0
    assert main(["example", "-o", str(r / "ex"), *q]) == 0
    rel, est, ref = (
        str(r / "ex" / n) for n in ("reference.relations", "estimate.txt", "reference.txt")
    )
    assert main(["evaluate", rel, est, "--per-relation", str(r / "per1.csv"), *q]) == 0
    assert main(["evaluate", rel, ref, "--per-relation", str(r / "per2.csv"), *q]) == 0
    (r / "a.txt").write_text(ISAM)
    assert main(["import", "isam", str(r / "a.txt"), "-o", str(r / "a.g2o"), *q]) == 0
    (r / "M").mkdir()
    (r / "M" / "Landmark_Groundtruth.dat").write_text("# placeholder, never read\n")
    return r


@pytest.fixture
def root(built: Path, tmp_path: Path) -> Path:
    """A private copy of the inputs (tests may damage it)."""
    r = tmp_path / "w"
    shutil.copytree(built, r)
    return r


@pytest.fixture
def umask() -> Callable[[int], None]:
    """Set the process umask for one test (restored after)."""
    old = os.umask(0o022)
    os.umask(old)

    def set_mask(mask: int) -> None:
        os.umask(mask)
        outputs.current_umask.cache_clear()

    yield set_mask
    os.umask(old)
    outputs.current_umask.cache_clear()


def tree(path: Path) -> dict[str, tuple[str, int, str]]:
    """Every entry below ``path`` (hidden ones included): kind, mode, content hash."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(path):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            digest = hashlib.sha256(p.read_bytes()).hexdigest() if stat.S_ISREG(st.st_mode) else ""
            out[str(p.relative_to(path))] = (
                "d" if stat.S_ISDIR(st.st_mode) else "f",
                stat.S_IMODE(st.st_mode),
                digest,
            )
    return out


def names(path: Path) -> set[str]:
    return {str(p.relative_to(path)) for p in path.rglob("*")}


def refused(argv: list[str], capsys: pytest.CaptureFixture[str], path: str) -> str:
    """Run ``argv``; it must exit 3 with a one-line error naming ``path``, no traceback."""
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 3, err
    command = " ".join(argv[:2]) if argv[0] in ("import", "relations") else argv[0]
    assert err.startswith(f"slamrel {command}: error: ") and path in err, err
    assert "Traceback" not in err and err.count("\n") == 1, err
    return err


# ------------------------------------------------------------------------------------ classes


def _link(r: Path) -> str:
    os.link(r / "ex" / "estimate.txt", r / "hard.txt")
    return str(r / "hard.txt")


def _symlink(r: Path) -> str:
    os.symlink(r / "ex" / "estimate.txt", r / "soft.txt")
    return str(r / "soft.txt")


def _solved_inside(r: Path) -> list[str]:
    (r / "X").mkdir()
    shutil.copy(r / "a.g2o", r / "X" / "solved.g2o")
    return ["solve", str(r / "X" / "solved.g2o"), "-o", str(r / "X"), "--force"]


def _table_inside(r: Path) -> list[str]:
    (r / "T").mkdir()
    shutil.copy(r / "per1.csv", r / "T" / "table.csv")
    return ["compare", f"d:a={r / 'T' / 'table.csv'}", f"d:b={r / 'per2.csv'}", "-o", str(r / "T")]


# (argv builder, the path the message names); cwd is the inputs root
INPUT_CASES: dict[str, Callable[[Path], tuple[list[str], str]]] = {
    "run into its source": lambda r: (FOLDER["run"](r, str(r / "S")) + ["--force"], str(r / "S")),
    "run onto a file of its source": lambda r: (
        FOLDER["run"](r, str(r / "S" / "map.csv")),
        str(r / "S" / "map.csv"),
    ),
    "run into the parent of its source": lambda r: (FOLDER["run"](r, str(r)) + ["--force"], str(r)),
    "run -o .": lambda r: (FOLDER["run"](r, ".") + ["--force"], "."),
    "run -o ..": lambda r: (["run", "../S", "-o", "..", "--force"], ".."),
    "slam into a folder inside its input": lambda r: (
        FOLDER["slam"](r, str(r / "B" / "sub")),
        str(r / "B" / "sub"),
    ),
    "slam onto its input": lambda r: (FOLDER["slam"](r, str(r / "B")) + ["--force"], str(r / "B")),
    "solve X/solved.g2o -o X": lambda r: (_solved_inside(r), str(r / "X")),
    "compare into the folder of an input": lambda r: (_table_inside(r), str(r / "T")),
    "import isam --bundle around its input": lambda r: (
        FOLDER["import-isam"](r, str(r)) + ["--force"],
        str(r),
    ),
    "import isam onto its input": lambda r: (FILE["import-isam"](r, str(r / "a.txt")), "a.txt"),
    "import isam file inside its --bundle": lambda r: (
        [
            "import",
            "isam",
            str(r / "a.txt"),
            "-o",
            str(r / "V" / "v.g2o"),
            "--bundle",
            str(r / "V"),
        ],
        str(r / "V" / "v.g2o"),
    ),
    "import mrclam inside its input": lambda r: (
        FOLDER["import-mrclam"](r, str(r / "M" / "logs")),
        str(r / "M" / "logs"),
    ),
    "recover onto a bundle file": lambda r: (
        FILE["recover"](r, str(r / "S" / "map.csv")),
        str(r / "S" / "map.csv"),
    ),
    "recover into its bundle": lambda r: (
        FILE["recover"](r, str(r / "S" / "new.txt")),
        str(r / "S" / "new.txt"),
    ),
    "recover two outputs on one path": lambda r: (
        FILE["recover"](r, str(r / "o.txt")) + ["--report", str(r / "o.txt")],
        str(r / "o.txt"),
    ),
    "evaluate onto its estimate": lambda r: (
        FILE["evaluate"](r, str(r / "ex" / "estimate.txt")),
        "estimate.txt",
    ),
    "evaluate onto a hard link of its estimate": lambda r: (
        FILE["evaluate"](r, p := _link(r)),
        p,
    ),
    "evaluate onto a symlink to its estimate": lambda r: (
        FILE["evaluate"](r, p := _symlink(r)),
        p,
    ),
    "relations onto its reference": lambda r: (
        FILE["relations"](r, str(r / "ex" / "reference.txt")),
        "reference.txt",
    ),
    "map-compare onto its map": lambda r: (
        FILE["map-compare"](r, str(r / "S" / "map.csv")),
        "map.csv",
    ),
}


@pytest.mark.parametrize("case", INPUT_CASES)
def test_outputs_on_in_or_around_inputs_are_refused_and_nothing_changes(
    case: str, root: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(root / "ex" if case == "run -o .." else root)
    argv, path = INPUT_CASES[case](root)
    before = tree(root.parent)
    refused(argv, capsys, path)
    assert tree(root.parent) == before  # nothing written, nothing deleted, no temp left


@pytest.mark.parametrize("force", [False, True], ids=["plain", "force"])
@pytest.mark.parametrize("existing", ["foreign folder", "file"])
@pytest.mark.parametrize("command", FOLDER)
def test_a_foreign_folder_or_a_file_is_never_replaced(
    command: str, existing: str, force: bool, root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = root / "mine"
    if existing == "file":
        out.write_text("my only copy\n")
    else:
        out.mkdir()
        (out / "notes.txt").write_text("my only copy\n")
    before = tree(root.parent)
    err = refused(FOLDER[command](root, str(out)) + ["-q"] + ["--force"] * force, capsys, str(out))
    if existing == "file":
        assert "not a folder" in err
    else:
        assert ("not written by slamrel" if force else "--force") in err
    assert tree(root.parent) == before


@pytest.mark.parametrize("command", RUNNABLE_FOLDER)
def test_a_slamrel_folder_is_replaced_whole_only_with_force(
    command: str, root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fresh, out = root / "fresh", root / "out"
    fresh.mkdir()  # an existing empty folder may be used
    assert main(FOLDER[command](root, str(fresh)) + ["-q"]) == 0
    assert (fresh / MANIFEST).is_file()
    assert main(FOLDER[command](root, str(out)) + ["-q"]) == 0
    (out / "stale.csv").write_text("from an earlier run\n")
    bundle = out / "bundle.json"
    if bundle.exists():  # a bundle written before manifests existed is recognised too
        (out / MANIFEST).unlink()
    before = tree(root.parent)
    err = refused(FOLDER[command](root, str(out)) + ["-q"], capsys, str(out))
    assert "--force" in err and tree(root.parent) == before
    assert main(FOLDER[command](root, str(out)) + ["-q", "--force"]) == 0
    assert names(out) == names(fresh)  # the stale file is gone, the manifest back
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]


def _fail_on_fsync(monkeypatch: pytest.MonkeyPatch, call: int, exc: BaseException) -> None:
    """Make the ``call``-th fsync (the call-th output file) raise ``exc``."""
    count = [0]
    real = os.fsync

    def fsync(fd: int) -> None:
        count[0] += 1
        if count[0] == call:
            raise exc
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


FAILURES = {
    "ctrl-c": (KeyboardInterrupt(), 130),
    "disk full": (OSError(errno.ENOSPC, "No space left on device"), 3),
}


@pytest.mark.parametrize("failure", FAILURES)
@pytest.mark.parametrize("kind,command", _written())
def test_a_failed_write_leaves_the_previous_output_intact(
    kind: str,
    command: str,
    failure: str,
    root: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    out = root / ("out" if kind == "folder" else "out.txt")
    argv = (FOLDER if kind == "folder" else FILE)[command](root, str(out)) + ["-q"]
    assert main(argv) == 0
    # mark the previous output, so that a rewrite of the same bytes cannot pass for intact
    for f in [out] if out.is_file() else out.rglob("*"):
        if f.is_file() and f.name not in (MANIFEST, "bundle.json"):
            with open(f, "ab") as handle:
                handle.write(b"\n# previous run\n")
    before = tree(root.parent)
    exc, code = FAILURES[failure]
    # a folder fails after its manifest and at least one more file; a file on its only write
    _fail_on_fsync(monkeypatch, 3 if kind == "folder" else 1, exc)
    assert main(argv + ["--force"] * (kind == "folder")) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if code == 3:
        assert "no space left" in err and f"error: {out}" in err, err
    assert tree(root.parent) == before  # old output intact, no temporary file or folder


@pytest.mark.parametrize("mask", [0o022, 0o077], ids=["022", "077"])
@pytest.mark.parametrize("kind,command", _written())
def test_outputs_follow_the_umask(
    kind: str, command: str, mask: int, root: Path, umask: Callable[[int], None]
) -> None:
    umask(mask)
    out = root / "new" / ("out" if kind == "folder" else "out.txt")  # parent created too
    assert main((FOLDER if kind == "folder" else FILE)[command](root, str(out)) + ["-q"]) == 0
    made = [out.parent, out, *(out.rglob("*") if kind == "folder" else [])]
    modes = {p: stat.S_IMODE(p.stat().st_mode) for p in made}
    for p, mode in modes.items():
        want = (0o777 if p.is_dir() else 0o666) & ~mask
        assert mode == want, f"{p}: {mode:o} != {want:o}"
    assert any(p.is_file() for p in made)


@pytest.mark.parametrize(
    "kind,command", [("folder", c) for c in FOLDER] + [("file", c) for c in FILE]
)
def test_outputs_are_checked_before_any_work(
    kind: str,
    command: str,
    root: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import importlib

    module, name = HEAVY[command]

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError(f"{name} ran before the outputs were checked")

    monkeypatch.setattr(importlib.import_module(module), name, never)
    ro = root / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root writes anywhere: emulate the read-only folder
        real = os.access
        monkeypatch.setattr(
            os,
            "access",
            lambda p, m, **k: False if m & os.W_OK and Path(p) == ro else real(p, m, **k),
        )
    out = ro / "sub" / ("out" if kind == "folder" else "out.txt")
    try:
        before = tree(root.parent)
        argv = (FOLDER if kind == "folder" else FILE)[command](root, str(out)) + ["-q"]
        err = refused(argv, capsys, str(out))
        assert "permission denied" in err and str(ro) in err
        assert tree(root.parent) == before
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize("where", ["a folder", "under a file"])
@pytest.mark.parametrize("command", FILE)
def test_a_file_output_onto_a_folder_or_under_a_file_is_refused(
    command: str, where: str, root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (root / "d").mkdir()
    (root / "d" / "keep.txt").write_text("mine\n")
    out = root / "d" if where == "a folder" else root / "d" / "keep.txt" / "out.txt"
    before = tree(root.parent)
    err = refused(FILE[command](root, str(out)) + ["-q"], capsys, str(out))
    assert ("is a folder" if where == "a folder" else "is not a folder") in err
    assert tree(root.parent) == before
