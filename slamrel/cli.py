"""The ``slamrel`` command line.

Exit codes: 0 success, 2 usage error (argparse, option values, and
:class:`~relation_metric.errors.OptionError` found after parsing), 3 bad input (any
:class:`relation_metric.errors.SlamrelError`, printed with file and line, or a file that
cannot be read or written), 130 interrupted (Ctrl-C, ``SIGINT``), 143 terminated
(``SIGTERM``: ``kill``, ``timeout``, Docker, CI) and 129 hung up (``SIGHUP``), i.e.
128 + the signal number as shells report it, 1 a bug in slamrel (one line, no traceback
unless ``SLAMREL_DEBUG=1``). ``SIGTERM`` and ``SIGHUP`` are handled like Ctrl-C: the
output being written is abandoned, its hidden work folder removed, earlier outputs kept.
Each sub-command lives in its own module under :mod:`slamrel.commands` and exposes
``register(subparsers)``, which sets ``func(args) -> int`` on its parser.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from types import FrameType

from relation_metric.errors import OptionError, SlamrelError

# Sub-commands and their modules, in the order ``slamrel --help`` lists them. A command line
# that names its command builds only that command's parser (the others' modules are not
# imported): a start-up cost every command would pay otherwise.
COMMANDS = {
    "run": "slamrel.commands.run",
    "evaluate": "slamrel.commands.evaluate",
    "ape": "slamrel.commands.evo_cli",
    "rpe": "slamrel.commands.evo_cli",
    "traj": "slamrel.commands.traj",
    "nees": "slamrel.commands.nees",
    "recover": "slamrel.commands.recover",
    "relations": "slamrel.commands.relations",
    "map-compare": "slamrel.commands.map_compare",
    "review": "slamrel.commands.review",
    "simulate": "slamrel.commands.simulate",
    "slam": "slamrel.commands.simulate",
    "compare": "slamrel.commands.compare",
    "import": "slamrel.commands.importers",
    "solve": "slamrel.commands.solve",
    "example": "slamrel.commands.example",
    "study": "slamrel.commands.study",
    "batch": "slamrel.commands.batch",
}
COMMAND_MODULES = tuple(dict.fromkeys(COMMANDS.values()))

EXIT_OK, EXIT_BUG, EXIT_USAGE, EXIT_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered, or only the module of
    ``command`` (a name of :data:`COMMANDS`; the command line's first word)."""
    from slamrel import __version__

    parser = argparse.ArgumentParser(
        prog="slamrel",
        description="Accuracy of filter-based SLAM results with the relation metric "
        "(Kümmerle et al. 2009).",
    )
    parser.add_argument("--version", action="version", version=f"slamrel {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    modules = (COMMANDS[command],) if command in COMMANDS else COMMAND_MODULES
    for name in modules:
        importlib.import_module(name).register(sub)
    _describe(sub)
    return parser


def _describe(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """A (sub-)command without a description of its own is described by its one-line help,
    so that ``slamrel CMD --help`` always says what CMD does; nested commands too."""
    for pseudo in sub._choices_actions:
        parser = sub.choices[pseudo.dest]
        if parser.description is None and pseudo.help:
            parser.description = pseudo.help[0].upper() + pseudo.help[1:] + "."
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                _describe(action)


class Terminated(KeyboardInterrupt):
    """``SIGTERM`` or ``SIGHUP`` arrived: unwinds like Ctrl-C, so every cleanup runs."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


#: Signals handled like Ctrl-C (exit 128 + the signal number).
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


def _stop(signum: int, frame: FrameType | None) -> None:
    for s in STOP_SIGNALS:  # a second signal must not cut the cleanup short
        signal.signal(s, signal.SIG_IGN)
    raise Terminated(signum)


@contextmanager
def _stop_signals() -> Iterator[None]:
    """Turn ``SIGTERM``/``SIGHUP`` into :class:`Terminated` while the command runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for s in STOP_SIGNALS:
        if signal.getsignal(s) is signal.SIG_IGN:
            continue  # nohup: keep ignoring it
        previous[s] = signal.signal(s, _stop)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _show_warning(message, category, filename, lineno, file=None, line=None):  # type: ignore[no-untyped-def]
    print(f"warning: {_warning_text(message, category, filename, lineno)}", file=sys.stderr)


def _warning_text(message: object, category: type[Warning], filename: str, lineno: int) -> str:
    """What a warning says on the command line. slamrel's own warnings are sentences; a
    floating-point warning of numpy (``invalid value encountered in divide``) is not meant
    for users: it is said as what it is, where, and that it is slamrel's to fix."""
    if issubclass(category, RuntimeWarning) and "encountered" in str(message):
        where = filename
        for root in ("relation_metric", "recovery", "landmark_graph", "slamrel", "numpy"):
            k = filename.rfind(os.sep + root + os.sep)
            if k >= 0:
                where = filename[k + 1 :]
                break
        return (
            f"floating-point problem inside slamrel: {message} ({where}:{lineno}); a number "
            "computed through it may be NaN or infinite. This is a bug in slamrel, please "
            "report it with the command line"
        )
    return str(message)


def _os_error_text(exc: OSError) -> str:
    """``FILE: reason`` for an operating-system error (permissions, disk full, …)."""
    reason = exc.strerror or type(exc).__name__
    name = exc.filename if exc.filename is not None else None
    return f"{name}: {reason.lower()}" if name is not None else reason.lower()


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (also used by the console script).

    No input or option ends in a traceback: option mistakes exit 2 (argparse), bad input
    and failed reads/writes exit 3 with the file named, Ctrl-C exits 130 (also during
    start-up), ``SIGTERM``/``SIGHUP`` exit 143/129 after the same cleanup. Anything else
    is a bug in slamrel: one line saying so, exit 1; set ``SLAMREL_DEBUG=1`` to see the
    traceback.
    """
    command = "slamrel"
    _single_threaded_blas()
    _no_huge_page_requests()
    thresholds = gc.get_threshold()
    gc.set_threshold(GC_YOUNG_THRESHOLD, *thresholds[1:])
    try:
        with _stop_signals():
            try:
                return _main(argv)
            finally:
                outputs = sys.modules.get("slamrel.outputs")  # imported by commands that write
                if outputs is not None:
                    outputs.release_claims()  # the lock files of folder outputs
                gc.set_threshold(*thresholds)  # a caller's own (main called in process)
    except Terminated as exc:  # arrived between the command's end and the handlers' reset
        return _terminated("slamrel", exc)
    except KeyboardInterrupt:
        print(f"{command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


#: The BLAS thread count a command runs with unless the user's environment sets one.
BLAS_THREADS = "1"

#: numpy's huge-page requests unless the user's environment says (``"0"``: none).
NUMPY_MADVISE_HUGEPAGE = "0"

#: Allocations between two collections of Python's youngest generation in a command
#: (Python's default: 700). A command imports numpy, scipy and its own modules and reads
#: files into lists of tokens, allocating objects that are never garbage: at 700 a core
#: ``solve`` of Manhattan 10⁴ ran 131 collections, 26–40 ms, against 9 and 12.7 ms at this
#: threshold (measured with ``gc.callbacks``, 2026-12-02). Cyclic garbage is still collected,
#: every 10⁴ allocations instead of 700.
GC_YOUNG_THRESHOLD = 10_000


def _single_threaded_blas() -> None:
    """One BLAS thread per ``slamrel`` process unless ``OPENBLAS_NUM_THREADS`` is set.

    numpy's and scipy's OpenBLAS start a thread per core at import, and those threads spin
    idle for a while: CPU time taken from the command's own work in every process. slamrel's
    dense work gains nothing from them at the sizes it meets (EKF-SLAM at 400 landmarks
    measured no faster with them; the figures: benchmarks/README.md). Set only before numpy
    is imported (it is read then), and never over the user's value.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)


def _no_huge_page_requests() -> None:
    """numpy asks for no transparent huge pages unless ``NUMPY_MADVISE_HUGEPAGE`` is set.

    numpy calls ``madvise`` for huge pages on every array of 4 MiB or more. Where the kernel
    answers such a request by compacting memory on the first touch (Linux's THP ``defrag``
    setting ``madvise``, a common default), that touch waits while the kernel moves pages:
    on a busy machine the first supernodal factorisation of a large graph (tens of MB of new
    buffers) took up to several times as long, most of the extra in the kernel, as with
    ordinary pages; later factorisations and the other steps measured the same either way
    (the figures: benchmarks/README.md). Set only before numpy is imported (it is read
    then), and never over the user's value.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", NUMPY_MADVISE_HUGEPAGE)


def _terminated(command: str, exc: Terminated) -> int:
    name = signal.Signals(exc.signum).name
    print(f"{command}: stopped by {name}", file=sys.stderr)
    return 128 + exc.signum


def _main(argv: Sequence[str] | None) -> int:
    command = "slamrel"
    try:
        words = sys.argv[1:] if argv is None else list(argv)
        parser = build_parser(words[0] if words else None)
        args = parser.parse_args(words)
        sub = [
            getattr(args, k)
            for k in ("import_command", "relations_command", "evo_kind")
            if hasattr(args, k)
        ]
        command = " ".join(["slamrel", args.command, *sub])
        with warnings.catch_warnings():
            warnings.simplefilter("always", UserWarning)
            warnings.showwarning = _show_warning
            return int(args.func(args) or EXIT_OK)
    except OptionError as exc:  # a command line that parses but does not make sense
        print(f"{command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except SlamrelError as exc:
        print(f"{command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except Terminated as exc:
        return _terminated(command, exc)
    except KeyboardInterrupt:
        print(f"{command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # e.g. `slamrel evaluate ... | head`
        sys.stderr.close()
        return EXIT_OK
    except OSError as exc:
        print(f"{command}: error: {_os_error_text(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except MemoryError:
        print(f"{command}: error: out of memory", file=sys.stderr)
        return EXIT_INPUT
    except Exception as exc:
        if os.environ.get("SLAMREL_DEBUG"):
            raise
        print(
            f"{command}: internal error ({type(exc).__name__}: {exc}); this is a bug in "
            "slamrel, please report it with the command line (SLAMREL_DEBUG=1 shows the "
            "traceback)",
            file=sys.stderr,
        )
        return EXIT_BUG


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
