"""Outputs at the edges (issue 25): special files, concurrent writers, SIGTERM/SIGHUP.

* a file output that is a stream (a FIFO, a character device, a descriptor such as
  ``/dev/fd/N``) is written in place and stays what it was; a symbolic link is written
  through, and still refused when it leads to an input; a folder output given a special file
  or a link to one is refused, a link to a folder is followed;
* two slamrel writing one folder at once: one succeeds, the others fail clearly (exit 3)
  unless ``--force``, no result is lost, no lock file is left;
* ``SIGTERM``/``SIGHUP`` while a folder is built leave no hidden work folder (exit 128 + n),
  and a work folder left by a killed slamrel is removed by the next run, which says so.

No test touches the machine's ``/dev/null`` or ``/dev/stdout``: FIFOs, links, pipes and
(as root) a device node live in ``tmp_path``; ``/dev/stdout`` is only classified.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from relation_metric.errors import InputError
from slamrel import outputs
from slamrel.cli import main
from slamrel.outputs import MANIFEST

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_FILES = {MANIFEST, "reference.txt", "estimate.txt", "reference.relations"}


def _cli(*argv: str, cwd: Path) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.Popen(
        [sys.executable, "-m", "slamrel", *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _hidden(folder: Path, name: str) -> list[str]:
    """The hidden work files of output ``name`` in ``folder`` (partials, old, tmp, locks)."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(f".{name}."))


@pytest.fixture(scope="module")
def ex(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("inputs") / "ex"
    assert main(["example", "-o", str(out), "-q"]) == 0
    return out


def _evaluate(ex: Path, *extra: str) -> list[str]:
    return ["evaluate", str(ex / "reference.relations"), str(ex / "estimate.txt"), "-q", *extra]


class _Reader(threading.Thread):
    """Reads a FIFO to its end (the writer opens it after the reader: no deadlock)."""

    def __init__(self, fifo: Path) -> None:
        super().__init__(daemon=True)
        self.fifo, self.data = fifo, b""

    def run(self) -> None:
        with open(self.fifo, "rb") as f:
            self.data = f.read()


# ------------------------------------------------------------------------- special files


def test_fifo_output_is_streamed_not_replaced(ex: Path, tmp_path: Path) -> None:
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    reader = _Reader(fifo)
    reader.start()
    assert main(_evaluate(ex, "--json", str(fifo))) == 0
    reader.join(timeout=30)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still the FIFO
    assert json.loads(reader.data)["relations"] > 0
    assert _hidden(tmp_path, "out.fifo") == []


def test_symlink_to_fifo_is_written_through(ex: Path, tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    link = tmp_path / "link"
    link.symlink_to(fifo)
    reader = _Reader(fifo)
    reader.start()
    assert main(["relations", "generate", str(ex / "reference.txt"), "-o", str(link), "-q"]) == 0
    reader.join(timeout=30)
    assert link.is_symlink() and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert reader.data.count(b"\n") > 10


def test_character_device_is_written_in_place(ex: Path, tmp_path: Path) -> None:
    if os.geteuid() != 0:
        pytest.skip("creating a private character device node needs root (os.mknod)")
    null = tmp_path / "null"  # a private node of the null device, not the machine's /dev/null
    try:
        os.mknod(null, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except OSError as exc:
        pytest.skip(f"cannot create a device node here: {exc.strerror}")
    before = os.lstat(null)
    assert main(_evaluate(ex, "--json", str(null), "--per-relation", str(null))) == 0
    after = os.lstat(null)
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev
    assert after.st_ino == before.st_ino
    assert _hidden(tmp_path, "null") == []


def _drain(fd: int, into: list[bytes]) -> None:
    with os.fdopen(fd, "rb") as f:
        into.append(f.read())


def test_descriptor_output_goes_to_that_descriptor(ex: Path) -> None:
    for form in ("/dev/fd/{}", "/proc/self/fd/{}"):
        if not Path(form.format(0)).parent.exists():
            continue
        r, w = os.pipe()
        got: list[bytes] = []
        reader = threading.Thread(target=_drain, args=(r, got))
        reader.start()
        try:
            assert main(_evaluate(ex, "--json", form.format(w))) == 0
        finally:
            os.close(w)
        reader.join(timeout=30)
        assert json.loads(got[0])["relations"] > 0


def test_std_streams_are_classified_as_descriptors() -> None:
    # classification only: nothing is written to the machine's /dev/stdout
    assert outputs.output_target("/dev/stdout").fd == 1
    assert outputs.output_target("/dev/stderr").fd == 2
    assert outputs.output_target("/dev/fd/7").fd == 7
    assert outputs.output_target("/proc/self/fd/5").fd == 5
    assert outputs.output_target("/dev/null").kind == "stream"


def test_closed_descriptor_is_refused(ex: Path, capsys: pytest.CaptureFixture[str]) -> None:
    r, w = os.pipe()
    os.close(r)
    os.close(w)
    assert main(_evaluate(ex, "--json", f"/dev/fd/{w}")) == 3
    assert "is not open" in capsys.readouterr().err


def test_symlink_to_file_is_written_through(ex: Path, tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    link = tmp_path / "link.json"
    link.symlink_to(real.name)
    assert main(_evaluate(ex, "--json", str(link))) == 0
    assert link.is_symlink() and os.readlink(link) == real.name
    assert json.loads(real.read_text())["relations"] > 0
    assert stat.S_IMODE(real.stat().st_mode) == outputs.file_mode()


def test_symlink_to_an_input_is_refused(
    ex: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    link = tmp_path / "sneaky.json"
    link.symlink_to(ex / "estimate.txt")
    before = (ex / "estimate.txt").read_bytes()
    assert main(_evaluate(ex, "--json", str(link))) == 3
    assert "refusing to overwrite an input" in capsys.readouterr().err
    assert (ex / "estimate.txt").read_bytes() == before and link.is_symlink()


@pytest.mark.parametrize("kind", ["fifo", "link-to-fifo", "dangling-link"])
def test_folder_output_on_a_special_file_is_refused(
    tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    if kind == "fifo":
        os.mkfifo(out)
    elif kind == "link-to-fifo":
        os.mkfifo(tmp_path / "pipe")
        out.symlink_to("pipe")
    else:
        out.symlink_to("missing")
    before = os.lstat(out)
    assert main(["example", "-o", str(out), "-q"]) == 3
    err = capsys.readouterr().err
    assert "not a folder; refusing to replace it" in err and str(out) in err
    after = os.lstat(out)
    assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)
    assert not (tmp_path / "missing").exists()
    assert _hidden(tmp_path, "out") == []


def test_symlink_to_a_folder_is_followed(tmp_path: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to("real")
    assert main(["example", "-o", str(link), "-q"]) == 0
    assert link.is_symlink() and {p.name for p in real.iterdir()} == EXAMPLE_FILES
    assert _hidden(tmp_path, "real") == [] and _hidden(tmp_path, "link") == []


# ----------------------------------------------------------------------- concurrent writers


def test_concurrent_writers_one_wins_the_others_fail_clearly(tmp_path: Path) -> None:
    procs = [_cli("example", "-o", "cx", "-q", "--seed", str(k), cwd=tmp_path) for k in range(4)]
    results = [(p.wait(timeout=120), p.stderr.read() if p.stderr else "") for p in procs]
    codes = [c for c, _ in results]
    assert codes.count(0) == 1 and codes.count(3) == 3, results
    for code, err in results:
        if code == 3:
            assert "cx: " in err and (
                "another slamrel" in err or "exists and is not empty" in err
            ), err
            assert "Traceback" not in err
    assert {p.name for p in (tmp_path / "cx").iterdir()} == EXAMPLE_FILES
    assert _hidden(tmp_path, "cx") == []  # no partial, no lock file


@pytest.mark.slow
def test_two_concurrent_runs_one_wins(tmp_path: Path) -> None:
    procs = [_cli("run", "simple1", "-o", "cc", "-q", cwd=tmp_path) for _ in range(2)]
    results = [(p.wait(timeout=300), p.stderr.read() if p.stderr else "") for p in procs]
    assert sorted(c for c, _ in results) == [0, 3], results
    err = next(e for c, e in results if c == 3)
    assert "cc: " in err and ("another slamrel" in err or "exists and is not empty" in err)
    assert (tmp_path / "cc" / "report.html").is_file()
    assert _hidden(tmp_path, "cc") == []


def test_concurrent_force_writers_all_replace_whole(tmp_path: Path) -> None:
    assert main(["example", "-o", str(tmp_path / "cx"), "-q"]) == 0
    procs = [
        _cli("example", "-o", "cx", "-q", "--force", "--seed", str(k), cwd=tmp_path)
        for k in range(3)
    ]
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0]
    assert {p.name for p in (tmp_path / "cx").iterdir()} == EXAMPLE_FILES
    assert _hidden(tmp_path, "cx") == []


@pytest.mark.slow
def test_a_held_claim_refuses_then_waits_with_force(tmp_path: Path) -> None:
    out = tmp_path / "cx"
    outputs.claim_outputs([out])  # this test process is "another slamrel" writing cx
    try:
        assert (tmp_path / ".cx.slamrel-lock").read_text().strip() == str(os.getpid())
        refused = _cli("example", "-o", "cx", "-q", cwd=tmp_path)
        assert refused.wait(timeout=120) == 3
        err = refused.stderr.read() if refused.stderr else ""
        assert f"another slamrel (pid {os.getpid()}) is writing it" in err
        waiting = _cli("example", "-o", "cx", "-q", "--force", cwd=tmp_path)
        time.sleep(2.0)
        assert waiting.poll() is None and not out.exists()  # it waits for the claim
    finally:
        outputs.release_claims()
    assert waiting.wait(timeout=120) == 0
    assert {p.name for p in out.iterdir()} == EXAMPLE_FILES
    assert _hidden(tmp_path, "cx") == []


def test_swap_rechecks_a_folder_that_appeared_meanwhile(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(InputError, match="appeared while this slamrel"):
        with outputs.staged_directory(out, kind="example", force=False) as tmp:
            (tmp / "a.txt").write_text("new\n")
            out.mkdir()
            (out / "theirs.txt").write_text("someone else's\n")
    assert [p.name for p in out.iterdir()] == ["theirs.txt"]  # not replaced, not lost
    assert _hidden(tmp_path, "out") == []


# ------------------------------------------------------------------------------- signals


def _wait_for_partial(folder: Path, name: str, proc: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if any(n.endswith(".partial") for n in _hidden(folder, name)):
            return
        time.sleep(0.005)
    pytest.fail(f"no partial folder appeared (exit {proc.poll()})")


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP"])
def test_signal_while_writing_leaves_no_partial(tmp_path: Path, signame: str) -> None:
    signum = getattr(signal, signame)
    if signal.getsignal(signum) is signal.SIG_IGN:
        pytest.skip(f"{signame} is ignored here (nohup): slamrel keeps ignoring it")
    proc = _cli("run", "simple1", "-o", "big", "-q", cwd=tmp_path)
    _wait_for_partial(tmp_path, "big", proc)
    proc.send_signal(signum)
    assert proc.wait(timeout=120) == 128 + signum
    err = proc.stderr.read() if proc.stderr else ""
    assert f"stopped by {signame}" in err and "Traceback" not in err
    assert not (tmp_path / "big").exists()
    assert _hidden(tmp_path, "big") == []


@pytest.mark.slow
def test_sigterm_stops_a_study_with_its_workers_at_once(tmp_path: Path) -> None:
    """SIGTERM reaches the study's process only (not its worker processes, unlike Ctrl-C in
    a terminal): leaving the pool used to run every pending case first, for minutes."""
    argv = ["study", "pose-only", "-o", "st", "--worlds", "hu-simple1", "--noise", "a"]
    proc = _cli(*argv, "--runs", "6", "--workers", "2", cwd=tmp_path)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if any((tmp_path / "st").glob("cases/*.json")):  # a case stored: workers busy
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the study ended before the signal"
    children = subprocess.run(
        ["pgrep", "-P", str(proc.pid)], capture_output=True, text=True
    ).stdout.split()
    assert children, "the study runs no worker processes"
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    assert time.monotonic() - sent < 20, "the study ran on after SIGTERM"
    err = proc.stderr.read() if proc.stderr else ""
    assert "stopped by SIGTERM" in err and "Traceback" not in err, err
    for pid in map(int, children):  # no worker left computing
        for _ in range(100):
            if not Path(f"/proc/{pid}").exists() or "Z" in _state(pid):
                break
            time.sleep(0.1)
        else:
            pytest.fail(f"worker {pid} still runs after the study stopped")


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return "Z"


def test_next_run_removes_work_folders_of_a_dead_slamrel(tmp_path: Path) -> None:
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    stale = tmp_path / f".cx.{gone.pid}-abcd1234.partial"
    stale.mkdir()
    (stale / "reference.txt").write_text("half\n")
    old = tmp_path / f".cx.{gone.pid}-efgh5678.old"
    old.mkdir()
    alive = tmp_path / f".cx.{os.getpid()}-ijkl9012.partial"  # this process runs: kept
    alive.mkdir()
    proc = _cli("example", "-o", "cx", "-q", cwd=tmp_path)
    assert proc.wait(timeout=120) == 0
    err = proc.stderr.read() if proc.stderr else ""
    assert err.count("removed an unfinished output left by a slamrel that stopped") == 2, err
    assert not stale.exists() and not old.exists() and alive.exists()
    assert _hidden(tmp_path, "cx") == [alive.name]


def test_old_style_work_folders_are_removed_once_idle(tmp_path: Path) -> None:
    """Work folders named before the pid was added (``.NAME.XXXXXXXX.partial``) say nothing
    of their writer: removed when nothing in them changed for an hour, kept when recent."""
    from slamrel.outputs import OLD_STYLE_STALE_AGE

    left = tmp_path / ".cx.01yrwy9x.partial"
    (left / "figures").mkdir(parents=True)
    (left / "figures" / "a.png").write_text("half\n")
    hour_ago = time.time() - OLD_STYLE_STALE_AGE - 60
    for p in (left / "figures" / "a.png", left / "figures", left):
        os.utime(p, (hour_ago, hour_ago))
    recent = tmp_path / ".cx.q8m2k4za.partial"  # could be an older slamrel writing now
    recent.mkdir()
    (recent / "b.txt").write_text("being written\n")
    os.utime(recent, (hour_ago, hour_ago))  # the folder old, a file in it fresh: kept
    other = tmp_path / ".cx.notours.partial"  # not slamrel's pattern: never touched
    other.mkdir()
    os.utime(other, (hour_ago, hour_ago))
    proc = _cli("example", "-o", "cx", "-q", cwd=tmp_path)
    assert proc.wait(timeout=120) == 0
    err = proc.stderr.read() if proc.stderr else ""
    assert err.count("removed an unfinished output") == 1, err
    assert "unchanged for 1.0 h" in err
    assert not left.exists() and recent.exists() and other.exists()


def test_socket_and_block_device_outputs_are_refused(
    ex: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import socket

    sock_path = tmp_path / "s"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(sock_path))
        assert main(_evaluate(ex, "--json", str(sock_path))) == 3
    assert "is a socket" in capsys.readouterr().err
    assert stat.S_ISSOCK(os.lstat(sock_path).st_mode)
    if os.geteuid() != 0:
        return  # a block device node needs root
    disk = tmp_path / "disk"  # a private node (loop0's numbers); refused before any open
    try:
        os.mknod(disk, stat.S_IFBLK | 0o600, os.makedev(7, 0))
    except OSError:
        return
    assert main(_evaluate(ex, "--json", str(disk))) == 3
    assert "is a block device" in capsys.readouterr().err
    assert stat.S_ISBLK(os.lstat(disk).st_mode)
