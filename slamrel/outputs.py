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
* files get ``0o666 & ~umask`` and folders ``0o777 & ~umask`` (the user's umask, read once).

Every failure is an :class:`~relation_metric.errors.InputError` naming the output path.
"""

from __future__ import annotations

import errno
import functools
import json
import os
import shutil
import tempfile
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO

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


@contextmanager
def atomic_write(
    path: PathLike, mode: str = "w", *, encoding: str | None = "utf-8"
) -> Iterator[IO[str] | IO[bytes]]:
    """Write to a temporary file beside ``path`` and rename it into place on success.

    The file gets ``0o666 & ~umask``; its contents are flushed and ``fsync``-ed before the
    rename. An exception (or an interrupt) inside the block leaves ``path`` untouched and
    removes the temporary file. A failed write (permission, read-only file system, no space)
    raises :class:`InputError` naming ``path``.
    """
    target = Path(path)
    _make_parent(target.parent, path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
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
        if isinstance(exc, OSError) and _is_our_error(exc, tmp, target):
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
    """
    if os.fspath(path) == "":
        raise InputError(f"empty file name for the {what}")
    if os.path.isdir(path):
        raise InputError(f"is a folder; expected a file name for the {what}", path=path)
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
    _check_parent(path)


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
            f"exists and is not a folder; refusing to replace it with the {what}", path=path
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
    for out in _inputs([*files, *dirs]):
        key = _real(out)
        if key in seen:
            raise InputError("is given twice as an output", path=out)
        seen[key] = out
    folders = [_real(d) for d in _inputs(dirs)]
    for out in _inputs(files):
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
        The folder output. A symbolic link is followed (the linked folder is replaced).
    kind : str
        What the folder holds (``"report"``, ``"bundle"``, …), recorded in :data:`MANIFEST`.
    force : bool
        May an existing non-empty folder slamrel wrote be replaced? A folder slamrel did not
        write, or a file, is never replaced (:class:`InputError`).

    The new folder (mode ``0o777 & ~umask``) gets the manifest first. When the block ends
    normally the old ``target`` is renamed aside, the new folder renamed in and the old one
    removed. On any exception or ``KeyboardInterrupt`` the new folder is removed and
    ``target`` is left exactly as it was.
    """
    final = Path(_real(target))
    _check_not_cwd(final)
    _check_replaceable(final, force=force, what="output folder")
    _make_parent(final.parent, target)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
    except OSError as exc:
        raise _os_error(exc, target) from None
    try:
        try:
            os.chmod(tmp, dir_mode())
        except OSError as exc:
            raise _os_error(exc, target) from None
        write_manifest(tmp, kind)
        yield tmp
        try:
            _swap(tmp, final)
        except OSError as exc:
            raise _os_error(exc, target, "cannot replace the folder") from None
    except InputError as exc:
        _remove(tmp)
        raise _renamed(exc, tmp, Path(target)) from None
    except BaseException:
        _remove(tmp)
        raise


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
    aside = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old", dir=final.parent))
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
            raise InputError(
                f"exists and is not a {kind} folder slamrel wrote "
                f"({MANIFEST} says {found!s}); choose a new or empty folder",
                path=path,
            )
    check_output_dir(path, inputs=list(inputs), force=True)
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
