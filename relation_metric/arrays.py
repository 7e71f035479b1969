"""The array type alias every package annotates with (one definition, imported)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["Array"]

Array = NDArray[np.float64]
"""A float64 numpy array of any shape (shapes are stated in each docstring)."""
