"""The ``slamrel`` command line.

Exit codes: 0 success, 2 usage error (argparse), 3 bad input (any
:class:`relation_metric.errors.SlamrelError`, printed with file and line), 130 interrupted.
Each sub-command lives in its own module under :mod:`slamrel.commands` and exposes
``register(subparsers)``, which sets ``func(args) -> int`` on its parser.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from collections.abc import Sequence

from relation_metric.errors import SlamrelError

# Sub-command modules, in the order ``slamrel --help`` lists them.
COMMAND_MODULES = (
    "slamrel.commands.run",
    "slamrel.commands.evaluate",
    "slamrel.commands.recover",
    "slamrel.commands.relations",
    "slamrel.commands.map_compare",
    "slamrel.commands.simulate",
    "slamrel.commands.compare",
    "slamrel.commands.graph",
    "slamrel.commands.example",
)

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_INTERRUPTED = 0, 2, 3, 130


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered."""
    from slamrel import __version__

    parser = argparse.ArgumentParser(
        prog="slamrel",
        description="Accuracy of filter-based SLAM results with the relation metric "
        "(Kümmerle et al. 2009).",
    )
    parser.add_argument("--version", action="version", version=f"slamrel {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None):  # type: ignore[no-untyped-def]
    print(f"warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (also used by the console script)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("always", UserWarning)
        warnings.showwarning = _show_warning
        try:
            return int(args.func(args) or EXIT_OK)
        except SlamrelError as exc:
            print(f"slamrel {args.command}: error: {exc}", file=sys.stderr)
            return EXIT_INPUT
        except KeyboardInterrupt:
            print(f"slamrel {args.command}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
