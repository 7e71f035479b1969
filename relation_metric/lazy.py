"""Lazy public names for a package (PEP 562): each is imported from its module on first use.

The packages' ``__init__`` files list their public names with the module that defines each,
and get ``__getattr__`` and ``__dir__`` from :func:`lazy_exports`, so that importing a
package imports no numpy and ``slamrel --help`` stays light::

    _EXPORTS = {"Trajectory": "relation_metric.trajectory", ...}
    if TYPE_CHECKING:  # what mypy and IDEs see
        from relation_metric.trajectory import Trajectory
    else:
        __getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, MutableMapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    namespace: MutableMapping[str, Any], exports: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package whose globals are ``namespace``.

    ``exports`` maps each public name to the module that defines it. On first access the
    name is imported from that module and stored in ``namespace`` (then it is a plain
    global); any other name raises :class:`AttributeError` as a module would. ``__dir__``
    lists the globals and ``namespace["__all__"]``.
    """
    package = namespace["__name__"]

    def __getattr__(name: str) -> Any:
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(exports[name]), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(namespace.get("__all__", ())))

    return __getattr__, __dir__
