"""The one home of output handling: checks before any work, atomic files, staged folders.

The output rule of every ``slamrel`` command:

* outputs are checked **before** any input is read or anything is computed
  (:func:`check_output_file`, :func:`check_output_dir`, :func:`check_outputs`): an output is
  never an input, never inside an input folder, a folder output never contains an input, its
  parent folder exists (or can be created) and is writable, and two outputs of one command
  never share a path;
* an existing non-empty folder is replaced only with ``force`` and only when slamrel wrote it,
  recognised by its manifest :data:`MANIFEST` (or a ``bundle.json`` of format
  ``slamrel-bundle/1``);
* a file is written to a temporary file beside the target and renamed into place
  (:func:`atomic_write`); a folder is built in a temporary folder beside the target and
  swapped in as a unit (:func:`staged_directory`): an error or Ctrl-C leaves the previous
  output exactly as it was and no temporary file behind;
* files get ``0o666 & ~umask`` and folders ``0o777 & ~umask`` (the user's umask, read once);
* a file output that is a stream is written in place, never replaced (:func:`output_target`):
  ``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N`` go to that descriptor, a FIFO or a
  character device (``/dev/null``) is opened and written; a symbolic link is written through
  (its target is the output, with every rule above); a block device or socket is refused;
* a folder output is claimed (:func:`claim_outputs`, a lock file ``.NAME.slamrel-lock``
  beside it, held from the check to the swap): a second slamrel writing the same folder at
  the same time is refused, or with ``force`` waits and then replaces it whole; the swap
  re-checks the target, so a folder that appeared meanwhile is never replaced silently;
* hidden work folders carry the writer's pid (``.NAME.PID-XXXXXXXX.partial``); one whose
  process is gone (killed with ``SIGKILL``, a power cut) is removed by the next write of the
  same output, with a warning; so is one named as before the pid was added
  (``.NAME.XXXXXXXX.partial``) once nothing in it changed for an hour.

Every failure is an :class:`~relation_metric.errors.InputError` naming the output path.
"""

from __future__ import annotations

import atexit
import errno
import functools
import glob
import io
import json
import os
import re
import shutil
import stat
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Literal

from relation_metric.arrays import PathLike
from relation_metric.errors import InputError
from slamrel.constants import BUNDLE_FORMAT  # a bundle folder saying so is ours too

__all__ = [
    "MANIFEST",
    "current_umask",
    "file_mode",
    "dir_mode",
    "atomic_write",
    "write_bytes_atomic",
    "write_text_atomic",
    "check_output_file",
    "check_output_dir",
    "check_outputs",
    "output_target",
    "OutputTarget",
    "claim_outputs",
    "release_claims",
    "StaleOutputWarning",
    "remove_stale_work",
    "is_slamrel_output",
    "staged_directory",
    "resumable_directory",
]


#: The manifest written into every folder output; ``--force`` replaces only such folders.
MANIFEST = "slamrel-output.json"

_UMASK_LOCK = threading.Lock()


@functools.cache
def current_umask() -> int:
    """The process umask, read once.

    Read from ``/proc/self/status`` where the kernel reports it (no change to the process
    state); elsewhere set and restored at once under a lock. Tests that change the umask call
    ``current_umask.cache_clear()``.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def file_mode() -> int:
    """Permissions of a new output file: ``0o666 & ~umask``."""
    return 0o666 & ~current_umask()


def dir_mode() -> int:
    """Permissions of a new output folder: ``0o777 & ~umask``."""
    return 0o777 & ~current_umask()


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("slamrel")
    except Exception:  # not installed (source tree on PYTHONPATH)
        return "unknown"


def _os_error(exc: OSError, path: PathLike, doing: str = "cannot write") -> InputError:
    """An :class:`InputError` naming ``path`` for a failed write."""
    reason = exc.strerror or str(exc)
    if exc.errno == errno.EROFS:
        reason = "read-only file system"
    elif exc.errno in (errno.ENOSPC, errno.EDQUOT):
        reason = "no space left on the device"
    return InputError(f"{doing}: {reason}", path=path)


def _is_our_error(exc: OSError, *paths: PathLike) -> bool:
    """True when ``exc`` came from writing one of ``paths`` (or names no file at all)."""
    if exc.filename is None:
        return True
    names = {os.fspath(p) for p in paths}
    return os.fspath(exc.filename) in names


# ------------------------------------------------------------------------------- atomic files


def _make_parent(parent: Path, target: PathLike) -> None:
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"cannot write: {_nearest(parent)} is not a folder", path=target) from None
    except OSError as exc:
        raise _os_error(exc, target, "cannot create its folder") from None


_FD_LINK = re.compile(r"/dev/fd/(\d+)|/proc/(?:self|thread-self|(\d+))/fd/(\d+)")
_STD_LINK = {"/dev/stdout": 1, "/dev/stderr": 2}


@dataclass(frozen=True)
class OutputTarget:
    """Where a file output goes (see :func:`output_target`).

    Attributes
    ----------
    kind : {"file", "descriptor", "stream"}
        ``file``: a regular file written to a temporary file and renamed into place;
        ``descriptor``: an open descriptor of this process (``/dev/stdout``, ``/dev/fd/N``),
        written in place; ``stream``: an existing FIFO or character device, opened and
        written in place (never created, never replaced).
    path : Path
        The file to write: for a symbolic link its resolved target.
    fd : int or None
        The descriptor of kind ``descriptor``.
    """

    kind: Literal["file", "descriptor", "stream"]
    path: Path
    fd: int | None = None

    @property
    def is_stream(self) -> bool:
        """Written in place (a descriptor, FIFO or device), not replaced."""
        return self.kind != "file"


def _descriptor(path: PathLike) -> int | None:
    """The descriptor ``path`` names (``/dev/stdout``, ``/dev/fd/N``, ``/proc/self/fd/N``)."""
    name = os.path.abspath(os.fspath(path))
    if name in _STD_LINK:
        return _STD_LINK[name]
    m = _FD_LINK.fullmatch(name)
    if m is None:
        return None
    if m.group(1) is not None:
        return int(m.group(1))
    if m.group(2) is not None and int(m.group(2)) != os.getpid():
        return None  # another process's descriptor: a path like any other
    return int(m.group(3))


def output_target(path: PathLike) -> OutputTarget:
    """Classify the file output ``path``; touches nothing on disk.

    * ``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N``, ``/proc/self/fd/N``: the descriptor
      (whatever it is open on: a terminal, a pipe, a file at its current offset);
    * an existing FIFO or character device (``/dev/null``, a terminal), also through a
      symbolic link: a stream, opened for writing and written in place;
    * a block device or a socket: refused (:class:`InputError`);
    * a symbolic link (also a dangling one): its resolved target, a file like any other;
    * anything else: itself.
    """
    fd = _descriptor(path)
    if fd is not None:
        return OutputTarget("descriptor", Path(path), fd)
    try:
        mode: int | None = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        mode = None  # absent, or a dangling link: a new file
    except OSError as exc:
        raise _os_error(exc, path, "cannot inspect the output") from None
    if mode is not None:
        if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
            return OutputTarget("stream", Path(path))
        if stat.S_ISBLK(mode):
            raise InputError(
                "is a block device (a disk); refusing to write an output over it", path=path
            )
        if stat.S_ISSOCK(mode):
            raise InputError("is a socket; cannot write an output to it", path=path)
    if os.path.islink(path):
        return OutputTarget("file", Path(_real(path)))
    return OutputTarget("file", Path(path))


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


@contextmanager
def _stream_write(
    target: OutputTarget, path: PathLike, mode: str, encoding: str | None
) -> Iterator[IO[str] | IO[bytes]]:
    """Collect the output in memory; on success write it to the stream in place."""
    raw = io.BytesIO()
    if "b" in mode:
        yield raw
        data = raw.getvalue()
    else:
        text = io.TextIOWrapper(raw, encoding=encoding or "utf-8", newline="")
        yield text
        text.flush()
        data = raw.getvalue()
        text.detach()
    try:
        if target.fd is not None:
            for handle in (sys.stdout, sys.stderr):  # keep the order of what is printed
                try:
                    if handle is not None and handle.fileno() == target.fd:
                        handle.flush()
                except (OSError, ValueError, AttributeError):
                    pass
            _write_all(target.fd, data)
        else:
            fd = os.open(target.path, os.O_WRONLY | os.O_NOCTTY | os.O_CLOEXEC)
            try:
                _write_all(fd, data)
            finally:
                os.close(fd)
    except OSError as exc:
        raise _os_error(exc, path) from None


@contextmanager
def atomic_write(
    path: PathLike, mode: str = "w", *, encoding: str | None = "utf-8"
) -> Iterator[IO[str] | IO[bytes]]:
    """Write to a temporary file beside ``path`` and rename it into place on success.

    The file gets ``0o666 & ~umask``; its contents are flushed and ``fsync``-ed before the
    rename. An exception (or an interrupt) inside the block leaves ``path`` untouched and
    removes the temporary file. A failed write (permission, read-only file system, no space)
    raises :class:`InputError` naming ``path``.

    A stream (:func:`output_target`: ``/dev/stdout``, ``/dev/null``, a FIFO) is never
    replaced: the output is collected and, on success, written to it in place. A symbolic
    link is written through: its target gets the new file.
    """
    where = output_target(path)
    if where.is_stream:
        with _stream_write(where, path, mode, encoding) as stream:
            yield stream
        return
    target = where.path
    _make_parent(target.parent, path)
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.{os.getpid()}-", suffix=".tmp", dir=target.parent
        )
    except OSError as exc:
        raise _os_error(exc, path) from None
    binary = "b" in mode
    try:
        with os.fdopen(fd, mode, encoding=None if binary else encoding) as handle:
            os.fchmod(handle.fileno(), file_mode())  # mkstemp gives 0600
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        try:
            os.replace(tmp, target)
        except IsADirectoryError:
            raise InputError("is a folder; expected a file name", path=path) from None
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError) and _is_our_error(exc, tmp, target, path):
            raise _os_error(exc, path) from None
        raise


def write_bytes_atomic(path: PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path, "wb") as handle:
        handle.write(data)  # type: ignore[arg-type]


def write_text_atomic(path: PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    write_bytes_atomic(path, text.encode("utf-8"))


# ------------------------------------------------------------------------------------ checks


def _real(path: PathLike) -> str:
    return os.path.realpath(os.fspath(path))


def _inside(child: str, parent: str) -> bool:
    """True when real path ``child`` lies strictly inside real path ``parent``."""
    if child == parent:
        return False
    return os.path.commonpath([child, parent]) == parent


def _same(a: PathLike, b: PathLike) -> bool:
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links, bind mounts
    except OSError:
        return False


def _nearest(path: Path) -> Path:
    """The nearest existing ancestor of ``path`` (``path`` itself when it exists)."""
    p = Path(os.path.abspath(path))
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def _check_parent(path: PathLike) -> None:
    """The folder that will hold ``path`` exists or can be created, and is writable."""
    parent = Path(os.path.abspath(path)).parent
    base = _nearest(parent)
    if not base.is_dir():
        raise InputError(f"cannot write: {base} is not a folder", path=path)
    if not os.access(base, os.W_OK | os.X_OK):
        where = "" if base == parent else f" (the nearest existing folder is {base})"
        raise InputError(f"cannot write into its folder: permission denied{where}", path=path)


def _inputs(inputs: Iterable[PathLike | None]) -> list[PathLike]:
    return [p for p in inputs if p is not None and os.fspath(p) != ""]


def check_output_file(
    path: PathLike, *, inputs: Sequence[PathLike | None] = (), what: str = "output"
) -> None:
    """Refuse an output file that would destroy or mix data; touches nothing on disk.

    Refused (:class:`InputError` naming ``path``): an existing folder; one of ``inputs``
    (same real path, or the same file through a hard or symbolic link); a path inside an input
    folder; a parent that is not a folder or not writable. An existing regular file that is
    not an input is overwritten (atomically) later.

    A stream (:func:`output_target`: a descriptor, a FIFO, a character device such as
    ``/dev/null``) is written in place and destroys nothing, so only its descriptor is
    checked; a block device or a socket is refused; a symbolic link is checked as its
    target.
    """
    if os.fspath(path) == "":
        raise InputError(f"empty file name for the {what}")
    if os.path.isdir(path):
        raise InputError(f"is a folder; expected a file name for the {what}", path=path)
    where = output_target(path)
    if where.kind == "descriptor":
        assert where.fd is not None
        try:
            os.fstat(where.fd)
        except OSError:
            raise InputError(
                f"descriptor {where.fd} is not open; cannot write the {what} to it", path=path
            ) from None
        return
    if where.kind == "stream":
        return
    out = _real(path)
    for item in _inputs(inputs):
        if _same(path, item):
            raise InputError(f"refusing to overwrite an input file with the {what}", path=path)
        if os.path.isdir(item) and _inside(out, _real(item)):
            raise InputError(
                f"lies inside the input folder {os.fspath(item)}; refusing to write the {what} "
                "into an input",
                path=path,
            )
    _check_parent(where.path)


def is_slamrel_output(path: PathLike) -> bool:
    """True when folder ``path`` was written by slamrel (its manifest, or a slamrel bundle)."""
    root = Path(path)
    for name, key, value in (
        (MANIFEST, "tool", "slamrel"),
        ("bundle.json", "format", BUNDLE_FORMAT),
    ):
        try:
            data = json.loads((root / name).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and data.get(key) == value:
            return True
    return False


def _check_replaceable(path: PathLike, *, force: bool, what: str) -> None:
    """Refuse replacing what is at ``path`` unless it is absent, an empty folder, or ours."""
    if not os.path.lexists(path):
        return
    if not os.path.isdir(path):
        raise InputError(
            f"exists and is {_describe(path)}, not a folder; refusing to replace it with the "
            f"{what}",
            path=path,
        )
    try:
        empty = not any(os.scandir(path))
    except OSError as exc:
        raise _os_error(exc, path, "cannot list the existing folder") from None
    if empty:
        return
    if not force:
        raise InputError(
            f"exists and is not empty; pass --force to replace a folder slamrel wrote "
            f"(the {what} is replaced as a whole)",
            path=path,
        )
    if not is_slamrel_output(path):
        raise InputError(
            f"exists and was not written by slamrel (no {MANIFEST}); refusing to replace it "
            "even with --force: choose a new or empty folder",
            path=path,
        )


def _describe(path: PathLike) -> str:
    """What is at ``path`` (``a FIFO``, ``a symbolic link to a missing X``, …), for messages."""
    if os.path.islink(path) and not os.path.exists(path):
        return f"a symbolic link to the missing {_real(path)}"
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return "unreadable"
    kinds = (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISREG, "a file"),
    )
    kind = next((name for test, name in kinds if test(mode)), "a special file")
    return f"a symbolic link to {kind}" if os.path.islink(path) else kind


def _check_not_cwd(path: PathLike) -> None:
    out = _real(path)
    cwd = os.path.realpath(os.getcwd())
    if out == cwd or _inside(cwd, out):
        raise InputError(
            "is the current folder or contains it; a folder output is replaced as a whole: "
            "choose a new folder",
            path=path,
        )
    if Path(out).parent == Path(out):
        raise InputError("is the root folder; choose a new folder", path=path)


def check_output_dir(
    path: PathLike,
    *,
    inputs: Sequence[PathLike | None] = (),
    force: bool = False,
    what: str = "output folder",
) -> None:
    """Refuse a folder output that would destroy or mix data; touches nothing on disk.

    A folder output is replaced as a whole (:func:`staged_directory`). Refused
    (:class:`InputError` naming ``path``): an existing non-folder; a path equal to an input or
    inside an input folder; a path that contains an input (replacing it would delete the
    input), the current folder or one of its parents; an existing non-empty folder unless
    ``force``, and with ``force`` a folder slamrel did not write (no :data:`MANIFEST`); a
    parent that is not a folder or not writable. A new or empty folder is fine.
    """
    if os.fspath(path) == "":
        raise InputError(f"empty folder name for the {what}")
    out = _real(path)
    for item in _inputs(inputs):
        inp = _real(item)
        if _same(path, item):
            raise InputError(
                f"is also an input; refusing to replace an input with the {what}", path=path
            )
        if os.path.isdir(item) and _inside(out, inp):
            raise InputError(
                f"lies inside the input folder {os.fspath(item)}; refusing to write the {what} "
                "into an input",
                path=path,
            )
        if _inside(inp, out):
            raise InputError(
                f"contains the input {os.fspath(item)}; the {what} is replaced as a whole, "
                "which would delete the input",
                path=path,
            )
    _check_not_cwd(path)
    _check_replaceable(path, force=force, what=what)
    _check_parent(path)


def check_outputs(
    files: Sequence[PathLike | None] = (),
    *,
    dirs: Sequence[PathLike | None] = (),
    inputs: Sequence[PathLike | None] = (),
    force: bool = False,
) -> None:
    """Check every output of one command (see :func:`check_output_file`/:func:`check_output_dir`).

    Also refused: two outputs on one path, and a file output inside a folder output (the
    folder is replaced as a whole and would drop it).
    """
    seen: dict[str, PathLike] = {}
    streams = {os.fspath(f) for f in _inputs(files) if output_target(f).is_stream}
    for out in _inputs([*files, *dirs]):
        if os.fspath(out) in streams:
            continue  # /dev/null twice is fine: a stream is written in place
        key = _real(out)
        if key in seen:
            raise InputError("is given twice as an output", path=out)
        seen[key] = out
    folders = [_real(d) for d in _inputs(dirs)]
    for out in _inputs(files):
        if os.fspath(out) in streams:
            continue
        for d, name in zip(folders, _inputs(dirs)):
            if _inside(_real(out), d):
                raise InputError(
                    f"lies inside the output folder {os.fspath(name)}, which is replaced as a "
                    "whole; write it elsewhere",
                    path=out,
                )
    for d, name in zip(folders, _inputs(dirs)):
        for other, other_name in zip(folders, _inputs(dirs)):
            if other_name is not name and _inside(other, d):
                raise InputError(f"contains the output folder {os.fspath(other_name)}", path=name)
    for out in _inputs(files):
        check_output_file(out, inputs=inputs)
    for out in _inputs(dirs):
        check_output_dir(out, inputs=inputs, force=force)


# ------------------------------------------------------------------------------------ claims


class StaleOutputWarning(UserWarning):
    """A hidden work folder left by a slamrel that no longer runs was removed."""


#: The lock files this process holds, by the real path of the output they claim.
_CLAIMS: dict[str, tuple[int, Path, list[Path]]] = {}
_CLAIMS_LOCK = threading.Lock()

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no claims, the swap still re-checks
    fcntl = None  # type: ignore[assignment]


def _lock_path(final: Path) -> Path:
    return final.parent / f".{final.name}.slamrel-lock"


def _owner(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return ""
    return f" (pid {text})" if text.isdigit() else ""


def _acquire(final: Path, path: PathLike, *, wait: bool) -> int:
    """Lock ``final``'s lock file (``flock``); returns its descriptor."""
    assert fcntl is not None
    lock = _lock_path(final)
    warned = False
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, file_mode())
        except OSError as exc:
            raise _os_error(exc, path, "cannot create its lock file") from None
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                who = _owner(fd)
                if not wait:
                    raise InputError(
                        f"another slamrel{who} is writing it right now; wait for it to "
                        "finish or choose another folder (with --force this one waits and "
                        "then replaces it)",
                        path=path,
                    ) from None
                if not warned:
                    warnings.warn(
                        f"{os.fspath(path)}: another slamrel{who} is writing it; waiting for it "
                        "to finish, then --force replaces its output",
                        UserWarning,
                        stacklevel=3,
                    )
                    warned = True
                fcntl.flock(fd, fcntl.LOCK_EX)
            try:
                here = os.stat(lock)
                mine = os.fstat(fd)
                same = (here.st_dev, here.st_ino) == (mine.st_dev, mine.st_ino)
            except FileNotFoundError:
                same = False  # its holder removed it as we waited: take a new one
        except BaseException:
            os.close(fd)
            raise
        if same:
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
            except OSError as exc:  # a full disk: no lock file is left behind, one error
                _release(fd, final)
                raise _os_error(exc, path, "cannot write its lock file") from None
            return fd
        os.close(fd)


def _release(fd: int, final: Path) -> None:
    try:
        os.unlink(_lock_path(final))  # still holding it: a waiter re-checks the name
    except OSError:
        pass
    os.close(fd)


def claim_outputs(paths: Iterable[PathLike | None], *, wait: bool = False) -> None:
    """Claim the folder outputs ``paths`` for this process until :func:`release_claims`.

    A lock file ``.NAME.slamrel-lock`` beside each folder is locked (``flock``, released by
    the kernel when the process dies, whatever kills it). Another slamrel holding it: refused
    with :class:`InputError` naming the folder, or with ``wait`` (``--force``) waited for.
    A missing parent folder is created (and removed again by :func:`release_claims` when
    nothing was written into it). Claims are taken in path order (no deadlock between two
    commands with several outputs). Streams and symbolic links are claimed as what they
    name.
    """
    if fcntl is None:
        return
    named = {_real(p): p for p in reversed(_inputs(paths))}
    for key in sorted(named):
        with _CLAIMS_LOCK:
            if key in _CLAIMS:
                continue
        final = Path(key)
        made = _missing_parents(final.parent)
        _make_parent(final.parent, named[key])
        try:
            fd = _acquire(final, named[key], wait=wait)
        except BaseException:
            _remove_empty(made)
            raise
        with _CLAIMS_LOCK:
            _CLAIMS[key] = (fd, final, made)


def release_claims() -> None:
    """Release every claim of this process and remove its lock files (also run at exit)."""
    with _CLAIMS_LOCK:
        held = list(_CLAIMS.values())
        _CLAIMS.clear()
    for fd, final, made in held:
        _release(fd, final)
        _remove_empty(made)


atexit.register(release_claims)


def _missing_parents(folder: Path) -> list[Path]:
    """The folders from ``folder`` up that do not exist yet (deepest first)."""
    out = []
    p = Path(os.path.abspath(folder))
    while not os.path.lexists(p) and p != p.parent:
        out.append(p)
        p = p.parent
    return out


def _remove_empty(folders: list[Path]) -> None:
    for f in folders:
        try:
            f.rmdir()
        except OSError:
            return


@contextmanager
def _swap_lock(final: Path) -> Iterator[None]:
    """Hold the claim on ``final`` for a swap: this process's own, or one taken for it."""
    with _CLAIMS_LOCK:
        held = _real(final) in _CLAIMS
    if held or fcntl is None:
        yield
        return
    fd = _acquire(final, final, wait=True)
    try:
        yield
    finally:
        _release(fd, final)


_WORK = re.compile(r"(\d+)-[a-z0-9_]+\.(?:partial|old)")
# Before the pid was in the name (slamrel 0.1.0 up to 2026-12-01): ``.NAME.XXXXXXXX.partial``,
# the 8 characters of ``tempfile.mkdtemp``. Nothing says whether its writer still runs, so
# one is removed only when nothing in it has changed for :data:`OLD_STYLE_STALE_AGE` seconds.
_OLD_STYLE_WORK = re.compile(r"[a-z0-9_]{8}\.partial")
#: Seconds without a change after which an old-style work folder (no pid in its name) is
#: taken as left behind: a slamrel that builds one writes into it far more often than that.
OLD_STYLE_STALE_AGE = 3600.0


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it runs, as another user
        return True
    return True


def remove_stale_work(final: Path) -> list[Path]:
    """Remove the hidden work folders of ``final`` whose slamrel no longer runs.

    Work folders are ``.NAME.PID-XXXXXXXX.partial`` (being built) and ``….old`` (the
    previous output during a swap); one whose process ``PID`` is gone was left by a
    slamrel killed with ``SIGKILL`` or a power cut. Each removal is announced with a
    :class:`StaleOutputWarning`. Returns the removed paths.
    """
    prefix = f".{final.name}."
    removed: list[Path] = []
    try:
        entries = [e.name for e in os.scandir(final.parent) if e.name.startswith(prefix)]
    except OSError:
        return removed
    for name in entries:
        path = final.parent / name
        m = _WORK.fullmatch(name[len(prefix) :])
        if m is not None:
            pid = int(m.group(1))
            if pid == os.getpid() or _alive(pid):
                continue
            why = f"pid {pid}, no longer running"
        elif _OLD_STYLE_WORK.fullmatch(name[len(prefix) :]) and path.is_dir():
            idle = _idle_seconds(path)
            if idle < OLD_STYLE_STALE_AGE:
                continue
            why = f"an earlier slamrel's folder, unchanged for {idle / 3600:.1f} h"
        else:
            continue
        _remove(path)
        removed.append(path)
        warnings.warn(
            f"{path}: removed an unfinished output left by a slamrel that stopped ({why})",
            StaleOutputWarning,
            stacklevel=3,
        )
    return removed


def _idle_seconds(folder: Path) -> float:
    """Seconds since anything in ``folder`` (itself included, links not followed) changed."""
    newest = 0.0
    for root, dirs, files in os.walk(folder):
        for name in (root, *(os.path.join(root, n) for n in (*dirs, *files))):
            try:
                newest = max(newest, os.lstat(name).st_mtime)
            except OSError:
                continue
    return time.time() - newest


# ---------------------------------------------------------------------------- staged folders


def write_manifest(directory: PathLike, kind: str) -> None:
    """Write :data:`MANIFEST` (``{"tool": "slamrel", "version": …, "kind": kind}``)."""
    data = {"tool": "slamrel", "version": _version(), "kind": kind}
    write_text_atomic(Path(directory) / MANIFEST, json.dumps(data, indent=2) + "\n")


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except OSError:
            pass


@contextmanager
def staged_directory(target: PathLike, *, kind: str, force: bool = True) -> Iterator[Path]:
    """Yield a fresh hidden folder beside ``target``; on success it replaces ``target`` whole.

    Parameters
    ----------
    target : str or PathLike
        The folder output. A symbolic link to a folder is followed (the linked folder is
        replaced, the link stays); a link to anything else, or a dangling one, is refused.
    kind : str
        What the folder holds (``"report"``, ``"bundle"``, …), recorded in :data:`MANIFEST`.
    force : bool
        May an existing non-empty folder slamrel wrote be replaced? A folder slamrel did not
        write, or a file, is never replaced (:class:`InputError`).

    The new folder (mode ``0o777 & ~umask``) gets the manifest first. When the block ends
    normally the old ``target`` is renamed aside, the new folder renamed in and the old one
    removed. On any exception or ``KeyboardInterrupt`` (the CLI turns ``SIGTERM`` and
    ``SIGHUP`` into one) the new folder is removed and ``target`` is left exactly as it was.

    The swap holds the claim on ``target`` (:func:`claim_outputs`; taken for the swap when
    the caller holds none) and re-checks it: without ``force``, a folder that appeared while
    this one was built is not replaced (:class:`InputError`). Work folders of a slamrel that
    no longer runs are removed first (:func:`remove_stale_work`).
    """
    final = Path(_real(target))
    _check_not_cwd(final)
    _check_replaceable(final, force=force, what="output folder")
    existed = _nonempty_dir(final)
    _make_parent(final.parent, target)
    remove_stale_work(final)
    prefix = f".{final.name}.{os.getpid()}-"
    before = set(final.parent.glob(f"{glob.escape(prefix)}*.partial"))
    tmp: Path | None = None
    try:
        try:
            tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=".partial", dir=final.parent))
        except OSError as exc:
            raise _os_error(exc, target) from None
        try:
            os.chmod(tmp, dir_mode())
        except OSError as exc:
            raise _os_error(exc, target) from None
        write_manifest(tmp, kind)
        yield tmp
        with _swap_lock(final):
            if not force and not existed and _nonempty_dir(final):
                raise InputError(
                    "appeared while this slamrel was writing it (another slamrel wrote it "
                    "meanwhile?); left as it is: pass --force to replace it",
                    path=target,
                )
            _check_replaceable(final, force=force, what="output folder")
            try:
                _swap(tmp, final)
            except OSError as exc:
                raise _os_error(exc, target, "cannot replace the folder") from None
    except InputError as exc:
        _remove_partial(tmp, final.parent, prefix, before)
        raise exc if tmp is None else _renamed(exc, tmp, Path(target)) from None
    except BaseException:
        _remove_partial(tmp, final.parent, prefix, before)
        raise


def _remove_partial(tmp: Path | None, parent: Path, prefix: str, before: set[Path]) -> None:
    """Remove the work folder; when a signal came between ``mkdtemp``'s ``mkdir`` and its
    return (``tmp`` unknown), the ones of this process made since ``before``."""
    if tmp is not None:
        _remove(tmp)
        return
    for made in set(parent.glob(f"{glob.escape(prefix)}*.partial")) - before:
        _remove(made)


def _nonempty_dir(path: Path) -> bool:
    try:
        return path.is_dir() and any(os.scandir(path))
    except OSError:
        return False


def _renamed(exc: InputError, tmp: Path, target: Path) -> InputError:
    """``exc`` naming the file in ``target`` instead of its hidden staging folder ``tmp``."""
    if exc.path is None or not _inside(_real(exc.path), _real(tmp)):
        return exc
    relative = os.path.relpath(_real(exc.path), _real(tmp))
    return type(exc)(exc.message, path=target / relative, line=exc.line)


def _swap(new: Path, final: Path) -> None:
    """Move ``new`` to ``final``; an existing ``final`` is renamed aside and then removed."""
    if not os.path.lexists(final):
        os.replace(new, final)
        return
    aside = Path(
        tempfile.mkdtemp(prefix=f".{final.name}.{os.getpid()}-", suffix=".old", dir=final.parent)
    )
    moved = False
    try:
        os.replace(final, aside / final.name)
        moved = True
        os.replace(new, final)
    except BaseException:
        if moved and not os.path.lexists(final):
            os.replace(aside / final.name, final)  # put the old output back
        _remove(aside)
        raise
    _remove(aside)


def resumable_directory(
    path: PathLike, *, kind: str, inputs: Iterable[PathLike | None] = ()
) -> Path:
    """Open the folder of a resumable job (e.g. a study), creating it when absent.

    A resumable job keeps its finished tasks in its output folder and skips them when run
    again, so the folder is reused, not swapped: it must be absent, empty, or a folder that
    slamrel wrote for the same ``kind`` (its manifest says so). Anything else is refused
    before any work, with the other rules of :func:`check_output_dir` (not an input, not
    inside one, not containing one, not the current folder or above it, writable parent).
    Each file inside is then written atomically by the job.
    """
    root = Path(path)
    if root.is_dir() and any(os.scandir(root)):
        try:
            data = json.loads((root / MANIFEST).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            data = None
        if not isinstance(data, dict) or data.get("kind") != kind:
            found = data.get("kind") if isinstance(data, dict) else None
            article = "an" if kind[:1] in "aeiou" else "a"
            raise InputError(
                f"exists and is not {article} {kind} folder slamrel wrote "
                f"({MANIFEST} says {found!s}); choose a new or empty folder",
                path=path,
            )
    check_output_dir(path, inputs=list(inputs), force=True)
    claim_outputs([path])  # a second job on the same folder at once is refused
    if root.is_dir() and any(os.scandir(root)):
        return root
    _make_parent(root.parent, path)
    try:
        root.mkdir(mode=dir_mode(), exist_ok=True)
        os.chmod(root, dir_mode())
    except OSError as exc:
        raise _os_error(exc, path, "cannot create the folder") from None
    write_manifest(root, kind)
    return root
