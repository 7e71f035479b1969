"""The one exception family of slamrel.

Every error a user can cause with their input derives from :class:`SlamrelError`; the CLI
maps :class:`InputError` (and its subclasses) to exit code 3 and prints ``str(error)``, which
always names the file and, where one exists, the line.
"""

from __future__ import annotations

import os

__all__ = ["SlamrelError", "InputError", "AssociationError", "DivergenceError"]


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


class AssociationError(InputError):
    """Relations that cannot be associated with the estimate (e.g. another time base)."""


class DivergenceError(SlamrelError):
    """A filter or optimiser left its valid domain (non-finite or non-PSD covariance, …)."""
