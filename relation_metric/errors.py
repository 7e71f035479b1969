"""The one exception family of slamrel.

Every error a user can cause with their input derives from :class:`SlamrelError`; the CLI
maps :class:`InputError` (and its subclasses) to exit code 3 and prints ``str(error)``, which
always names the file and, where one exists, the line. :class:`OptionError` (a command line
that parses but does not make sense) exits 2, like argparse's usage errors.
"""

from __future__ import annotations

import os

__all__ = ["SlamrelError", "InputError", "OptionError", "AssociationError", "DivergenceError"]


class SlamrelError(Exception):
    """Base class of all errors raised by slamrel."""


class InputError(SlamrelError, ValueError):
    """Bad input data: a file, a line in it, and what was expected.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    path : str or os.PathLike, optional
        The file the problem is in.
    line : int, optional
        1-based line number in ``path``.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | os.PathLike[str] | None = None,
        line: int | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else os.fspath(path)
        self.line = line
        super().__init__(self._format())

    def _format(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path if self.line is None else f"{self.path}:{self.line}"
            where += ": "
        elif self.line is not None:
            where = f"line {self.line}: "
        return where + self.message


class OptionError(SlamrelError, ValueError):
    """A mistake in the command line itself (an option value, or options that do not go
    together) found only after parsing: the CLI reports it like argparse, exit code 2.

    Parameters
    ----------
    message : str
        What is wrong and what would be accepted.
    option : str, optional
        The option (``"-o/--output"``) or argument it is about.
    """

    def __init__(self, message: str, *, option: str | None = None) -> None:
        self.message = message
        self.option = option
        super().__init__(message if option is None else f"argument {option}: {message}")


class AssociationError(InputError):
    """Relations that cannot be associated with the estimate (e.g. another time base)."""


class DivergenceError(SlamrelError):
    """A filter or optimiser left its valid domain (non-finite or non-PSD covariance, …)."""
