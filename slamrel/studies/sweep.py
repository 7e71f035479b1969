"""Resumable sweeps of pure tasks: each result stored atomically under a key of its inputs.

A sweep is a list of :class:`Task` — a picklable module-level function and its keyword
arguments (JSON-serialisable). A task's key is readable (``name``) plus a hash of its
function and arguments, so changing any input gives a new key. Results are JSON files
``DIR/<key>.json`` written atomically (a temporary file renamed into place), so a sweep that
is killed at any moment leaves only whole results; a re-run skips the tasks whose result
exists. A task that raises is recorded in ``DIR/<key>.error.json`` (and retried on the next
run); it does not stop the sweep.

Execution: in a pool of ``workers`` spawned processes (``workers=0``: in this process), or on
a Dask cluster (``scheduler=ADDRESS``, or ``"local"`` for a ``LocalCluster``; needs the optional
``dask[distributed]``). Progress goes to a callback as counts and an ETA.

The processes this module starts run single-threaded BLAS (``OPENBLAS_NUM_THREADS=1`` and
the like, unless the environment sets them): the tasks are many small linear-algebra calls,
for which BLAS threads only contend: with OpenBLAS's default threads a study ran an order of
magnitude slower than with one thread (measured in benchmarks/README.md).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from relation_metric.errors import InputError
from slamrel.formats.text import loads_json, write_text_atomic

__all__ = [
    "Task",
    "SweepReport",
    "run_sweep",
    "load_results",
    "stored_results",
    "format_progress",
]


@dataclass(frozen=True)
class Task:
    """One pure task: ``function(**kwargs)`` returning a JSON-serialisable dict.

    Attributes
    ----------
    name : str
        Readable part of the key (file-name safe: letters, digits, ``-_.=``).
    function : str
        ``"module:function"`` of a module-level function (picklable by name).
    kwargs : dict
        JSON-serialisable keyword arguments.
    outputs : tuple of str
        Files the task writes besides its result (not part of the key): a stored result
        whose outputs are missing is computed again.
    """

    name: str
    function: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    outputs: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        blob = json.dumps([self.function, self.kwargs], sort_keys=True, separators=(",", ":"))
        return f"{self.name}-{hashlib.sha256(blob.encode()).hexdigest()[:12]}"


@dataclass(frozen=True)
class SweepReport:
    """What a sweep did: tasks run now, skipped (already done) and failed (by key)."""

    ran: int
    skipped: int
    failed: tuple[str, ...]
    seconds: float
    #: Stored result files that were damaged (cut off, not JSON, not this task's record) and
    #: were recomputed, by path.
    damaged: tuple[str, ...] = ()


def _stored_record(path: Path, task: Task) -> tuple[dict[str, Any] | None, str | None]:
    """The stored record of ``task`` at ``path``: ``(record, None)``; ``(None, None)`` when
    there is none; ``(None, why)`` when the file is damaged (a writer that was stopped before
    the atomic rename cannot leave one, but a copy, a full disk or a hand edit can)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None, None
    except (OSError, UnicodeDecodeError) as exc:
        return None, f"unreadable ({exc})"
    try:
        record: Any = loads_json(text, path=str(path))
    except json.JSONDecodeError as exc:
        return None, f"not valid JSON ({exc.msg}, line {exc.lineno})"
    except InputError as exc:  # a key given twice: which value was meant is unknown
        return None, exc.message
    except RecursionError:
        return None, "JSON nested too deeply"
    if not isinstance(record, dict) or "result" not in record:
        return None, "not a result record (expected a JSON object with a 'result')"
    if record.get("key") != task.key:
        return None, f"the record of another task (key {str(record.get('key'))[:60]!r})"
    if record.get("result_sha256") != _checksum(record["result"]):
        return None, (
            "its result does not match the checksum slamrel stored with it (edited, or "
            "written by an older slamrel)"
        )
    return record, None


def _checksum(result: Any) -> str:
    """SHA-256 of a result's canonical JSON (stored with it: a hand-edited result, e.g. a
    number turned into NaN, is found on resume and computed again)."""
    blob = json.dumps(result, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()


def _call(function: str, kwargs: dict[str, Any]) -> dict[str, Any]:
    module, _, name = function.partition(":")
    return getattr(importlib.import_module(module), name)(**kwargs)  # type: ignore[no-any-return]


def _guarded(function: str, kwargs: dict[str, Any]) -> tuple[bool, Any]:
    """Run a task; ``(True, result)`` or ``(False, error text)`` (never raises)."""
    try:
        return True, _call(function, kwargs)
    except Exception as exc:  # noqa: BLE001 - a failed task is recorded, the sweep goes on
        return False, f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=5)}"


def _store(directory: Path, task: Task, ok: bool, value: Any) -> None:
    record = {"key": task.key, "name": task.name, "function": task.function, "kwargs": task.kwargs}
    err = directory / f"{task.key}.error.json"
    if ok:
        record["result"] = value
        record["result_sha256"] = _checksum(value)
        write_text_atomic(directory / f"{task.key}.json", json.dumps(record, sort_keys=True))
        if err.exists():
            err.unlink()
    else:
        record["error"] = value
        write_text_atomic(err, json.dumps(record, sort_keys=True))


_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


class _single_threaded_blas_env:
    """Set the BLAS thread variables to 1 (where unset) while child processes start."""

    def __enter__(self) -> None:
        self.saved = {k: os.environ.get(k) for k in _BLAS_THREADS}
        for k, v in self.saved.items():
            if v is None:
                os.environ[k] = "1"

    def __exit__(self, *exc: object) -> None:
        for k, v in self.saved.items():
            if v is None:
                os.environ.pop(k, None)


def _exit_with_parent(parent: int) -> None:
    """Pool initializer: end this worker when the sweep's process dies (e.g. SIGKILL)."""
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def format_progress(done: int, total: int, failed: int, elapsed: float) -> str:
    """``"12/48 done, 1 failed, 35 s elapsed, ETA 1 min 45 s"``."""

    def dur(s: float) -> str:
        s = int(round(s))
        return f"{s // 60} min {s % 60} s" if s >= 60 else f"{s} s"

    eta = "?" if done == 0 else dur(elapsed / done * (total - done))
    return f"{done}/{total} done, {failed} failed, {dur(elapsed)} elapsed, ETA {eta}"


def run_sweep(
    tasks: Sequence[Task],
    directory: str | os.PathLike[str],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> SweepReport:
    """Run the tasks whose result is not stored yet; store each result as it arrives.

    Parameters
    ----------
    tasks : sequence of Task
        Keys must be distinct.
    directory : path
        Where results live (created).
    workers : int
        Worker processes (spawned, single-threaded BLAS; 0: this process); with
        ``scheduler="local"`` the Dask workers.
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:8786``) or ``"local"`` for a
        ``LocalCluster`` with ``workers`` single-threaded workers.
    progress : callable, optional
        Called with a progress line after each finished task.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("two tasks of the sweep have the same inputs (key)")
    todo, damaged = [], []
    for t in tasks:
        path = out / f"{t.key}.json"
        record, why = _stored_record(path, t)
        missing = [o for o in t.outputs if not Path(o).is_file()]
        if record is not None and not missing:
            continue
        if record is not None:
            why = f"its output {missing[0]} is missing"
        if why is not None:  # recomputed below, and said
            damaged.append(str(path))
            if progress is not None:
                progress(f"damaged result {path}: {why}; recomputing it")
        todo.append(t)
    skipped = len(tasks) - len(todo)
    failed: list[str] = []
    start = time.monotonic()
    done = 0

    def finished(task: Task, ok: bool, value: Any) -> None:
        nonlocal done
        _store(out, task, ok, value)
        done += 1
        if not ok:
            failed.append(task.key)
        if progress is not None:
            progress(format_progress(done, len(todo), len(failed), time.monotonic() - start))

    if scheduler is not None:
        _run_dask(todo, scheduler, workers, finished)
    elif workers <= 0 or not todo:
        for t in todo:
            finished(t, *_guarded(t.function, t.kwargs))
    else:
        ctx = multiprocessing.get_context("spawn")
        with _single_threaded_blas_env():
            pool = ProcessPoolExecutor(
                workers, mp_context=ctx, initializer=_exit_with_parent, initargs=(os.getpid(),)
            )
        try:
            futures = {pool.submit(_guarded, t.function, t.kwargs): t for t in todo}
            for fut in as_completed(futures):
                finished(futures[fut], *fut.result())
        except BaseException:  # SIGTERM (Terminated), Ctrl-C, a failed store: stop now
            _stop_pool(pool)
            raise
        pool.shutdown()
    return SweepReport(
        len(todo), skipped, tuple(sorted(failed)), time.monotonic() - start, tuple(damaged)
    )


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a pool at once: pending cases cancelled, running ones' workers terminated.

    ``shutdown(wait=True)`` (what leaving a ``with`` block does) would first run every
    pending case: a ``SIGTERM``, which reaches the sweep's process only, left a study
    running for minutes. The workers are ended through the executor's process table
    (``_processes``, not public API; absent, the workers end with their parent anyway,
    :func:`_exit_with_parent`). Stored results stay: the sweep resumes from them.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown()
    pool.shutdown(wait=False, cancel_futures=True)  # which forgets them
    for proc in processes:
        try:
            proc.terminate()
        except (OSError, ValueError):  # already gone
            continue
    for proc in processes:
        proc.join(timeout=5)


def _run_dask(
    todo: Sequence[Task],
    scheduler: str,
    workers: int,
    finished: Callable[[Task, bool, Any], None],
) -> None:
    try:
        from dask.distributed import Client, LocalCluster
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise InputError(
            "running on Dask needs the optional dependency: pip install 'dask[distributed]'"
        ) from None
    cluster = None
    if scheduler == "local":
        with _single_threaded_blas_env():
            cluster = LocalCluster(n_workers=max(workers, 1), threads_per_worker=1, processes=True)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = {
            client.submit(_guarded, t.function, t.kwargs, key=t.key, pure=True): t for t in todo
        }
        for fut in dask_completed(list(futures)):
            finished(futures[fut], *fut.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def load_results(directory: str | os.PathLike[str], tasks: Iterable[Task]) -> list[dict[str, Any]]:
    """The stored records of ``tasks`` that finished, in the order of ``tasks``.

    Raises
    ------
    InputError
        When a stored result is damaged (:func:`run_sweep` recomputes such files; one found
        here was damaged since), naming the file.
    """
    out = []
    for t in tasks:
        p = Path(directory) / f"{t.key}.json"
        record, why = _stored_record(p, t)
        if why is not None:
            raise InputError(
                f"damaged study result: {why}; expected the JSON record slamrel writes "
                "(delete the file, or run the study again to recompute it)",
                path=p,
            )
        if record is not None:
            out.append(record)
    return out


def stored_results(
    directory: str | os.PathLike[str], tasks: Iterable[Task]
) -> list[dict[str, Any] | None]:
    """The stored result of each of ``tasks``, in their order; ``None`` where none is stored
    (the task failed or has not run). A damaged file is an :class:`InputError` as in
    :func:`load_results`."""
    tasks = list(tasks)
    done = {r["key"]: r["result"] for r in load_results(directory, tasks)}
    return [done.get(t.key) for t in tasks]
