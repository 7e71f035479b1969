"""Synthetic relation sets with planted gross errors, to measure a relation check against an
oracle (the planted set): :func:`lap_relations`."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2

__all__ = ["PlantedRelations", "lap_relations"]


class PlantedRelations(NamedTuple):
    """Poses ``(N, 3)``, relations ``pairs (M, 2)``, ``delta (M, 3)``, ``covariance
    (M, 3, 3)``, and which are gross errors ``bad (M,)``."""

    poses: NDArray[np.float64]
    pairs: NDArray[np.int64]
    delta: NDArray[np.float64]
    covariance: NDArray[np.float64]
    bad: NDArray[np.bool_]


def lap_relations(seed: int, laps: int = 2, bad_share: float = 0.08) -> PlantedRelations:
    """Keyframes 0.5 m apart around a 30 × 20 m block, ``laps`` times (each lap shifted by
    N(0, 0.2²) m, headings by N(0, 0.05²) rad); relations: consecutive, skip-one and loop
    pairs (within 1 m, more than 20 keyframes apart), with 3 mm / 0.001 rad noise and that
    covariance; a random ``bad_share`` of them made gross: half moved 0.15–1 m in a random
    direction, half turned 3–15°."""
    rng = np.random.default_rng(seed)
    corners = np.array([[0, 0], [30, 0], [30, 20], [0, 20]], float)
    pts = []
    for _ in range(laps):
        off = rng.normal(0, 0.2, 2)
        for c in range(4):
            p, q = corners[c] + off, corners[(c + 1) % 4] + off
            n = int(np.hypot(*(q - p)) / 0.5)
            h = np.arctan2(q[1] - p[1], q[0] - p[0])
            pts += [[*(p + (q - p) * s / n), h + rng.normal(0, 0.05)] for s in range(n)]
    x = np.array(pts)
    n = len(x)
    k = np.arange(n)
    d = np.hypot(x[:, None, 0] - x[None, :, 0], x[:, None, 1] - x[None, :, 1])
    ii, jj = np.nonzero((d < 1.0) & (k[None, :] - k[:, None] > 20))
    pairs = np.concatenate(
        (
            np.column_stack((k[:-1], k[1:])),
            np.column_stack((k[:-2], k[2:])),
            np.column_stack((ii, jj)),
        )
    )
    true = se2.between(x[pairs[:, 0]], x[pairs[:, 1]])
    sd = np.array([0.003, 0.003, 0.001])
    delta = se2.compose(true, rng.normal(0, 1, true.shape) * sd)
    cov = np.broadcast_to(np.diag(sd**2), (len(pairs), 3, 3)).copy()
    bad = rng.random(len(pairs)) < bad_share
    nb = int(bad.sum())
    err = np.zeros((nb, 3))
    shift = rng.random(nb) < 0.5
    ang, r = rng.uniform(0, 2 * np.pi, nb), rng.uniform(0.15, 1.0, nb)
    err[shift, 0], err[shift, 1] = (r * np.cos(ang))[shift], (r * np.sin(ang))[shift]
    turn = rng.choice([-1, 1], nb) * rng.uniform(np.radians(3), np.radians(15), nb)
    err[~shift, 2] = turn[~shift]
    delta[bad] = se2.compose(delta[bad], err)
    return PlantedRelations(x, pairs.astype(np.int64), delta, cov, bad)
