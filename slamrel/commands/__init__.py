"""Sub-commands of the ``slamrel`` CLI, one module each (see :mod:`slamrel.cli`)."""
