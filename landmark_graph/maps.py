"""Landmark maps as a record: M landmarks with integer ids and optional covariances.

:class:`LandmarkMap` checks itself when it is built (unique integer ids, finite positions,
symmetric positive semi-definite covariances; :func:`relation_metric.landmarks.
check_landmarks`). Its files (the bundle's ``map.csv``, MRCLAM landmarks, g2o ``VERTEX_XY``)
are read and written by :mod:`slamrel.formats.landmark_maps`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.landmarks import check_landmarks
from relation_metric.trajectory import readonly

__all__ = ["LandmarkMap"]


@dataclass(frozen=True)
class LandmarkMap:
    """M landmarks ``w_p_l`` with integer ids and optional 2 × 2 covariances.

    Parameters
    ----------
    ids : array_like of int, shape (M,)
        Unique.
    xy : array_like, shape (M, 2)
        Finite positions.
    cov : array_like, shape (M, 2, 2), optional
        Symmetric positive semi-definite; a landmark whose file left its covariance empty
        has NaN in all four entries.

    Checked by :func:`relation_metric.landmarks.check_landmarks` (the readers' rule).
    """

    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    cov: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        xy = np.asarray(self.xy, dtype=np.float64).reshape(-1, 2)
        ids = check_landmarks(self.ids, xy, self.cov)
        object.__setattr__(self, "ids", readonly(ids, np.int64))
        object.__setattr__(self, "xy", readonly(xy))
        if self.cov is not None:
            object.__setattr__(self, "cov", readonly(np.asarray(self.cov, dtype=np.float64)))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def subset(self, index: ArrayLike) -> LandmarkMap:
        """The landmarks at ``index`` (rows)."""
        k = np.asarray(index)
        return LandmarkMap(self.ids[k], self.xy[k], None if self.cov is None else self.cov[k])
