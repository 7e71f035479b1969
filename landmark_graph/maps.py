"""Landmark maps and their file formats.

Formats: the SLAM result bundle's ``map.csv`` (``landmark,x,y[cxx,cxy,cyy]``) and
``landmarks_groundtruth.csv`` (``landmark,x,y``); MRCLAM ``Landmark_Groundtruth.dat``
(``subject x y σx σy``, ``#`` headers, tabs and spaces); g2o ``VERTEX_XY id x y`` (other g2o
records are skipped). Readers are strict: NaN coordinates, duplicate ids, a covariance that is
not symmetric positive semi-definite and an empty map are errors naming the file (and line).
Writers (:func:`write_map`) speak the same formats, with 17 significant digits, so that a
written map reads back bit for bit.
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
