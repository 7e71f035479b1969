"""The type aliases every package annotates with (one definition each, imported)."""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import NDArray

__all__ = ["Array", "PathLike"]

Array = NDArray[np.float64]
"""A float64 numpy array of any shape (shapes are stated in each docstring)."""

PathLike = str | os.PathLike[str]
"""A file-system path as a string or a path object."""
