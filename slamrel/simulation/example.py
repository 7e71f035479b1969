"""The example pair of ``slamrel example``: a reference drive, a drifting estimate, relations.

No landmarks and no sensor: the estimate is dead reckoning along the reference (its relative
motions with Gaussian noise), the smallest input that shows what the relation metric sees.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from relation_metric import se2
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.trajectory import Trajectory

__all__ = ["ExamplePair", "example_pair", "example_trajectories"]


class ExamplePair(NamedTuple):
    """What ``slamrel example`` writes.

    Attributes
    ----------
    reference, estimate : Trajectory
        Same timestamps, shape (N, 3) poses.
    relations : RelationSet
        Consecutive relations of the reference, then its loop closures.
    consecutive, loops : int
        How many of each ``relations`` holds.
    """

    reference: Trajectory
    estimate: Trajectory
    relations: RelationSet
    consecutive: int
    loops: int


def example_trajectories(
    seed: int = 0, n: int = 600, dt: float = 0.5
) -> tuple[Trajectory, Trajectory]:
    """A reference figure-eight drive and a drifting estimate of it (seeded).

    The reference is a figure eight 40 m × 20 m, ``n`` poses ``dt`` seconds apart, heading
    along the path. The estimate chains the reference's relative motions with Gaussian noise
    (σ = 2 cm, 2 cm, 0.005 rad per step), i.e. dead reckoning with good odometry.

    Returns
    -------
    reference, estimate : Trajectory
    """
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 2.0 * np.pi, n)
    xy = np.column_stack((20.0 * np.sin(s), 10.0 * np.sin(2.0 * s)))
    d = np.gradient(xy, axis=0)
    theta = np.arctan2(d[:, 1], d[:, 0])
    ref = np.column_stack((xy, theta))
    steps = se2.between(ref[:-1], ref[1:])
    noisy = steps + rng.normal(0.0, [0.02, 0.02, 0.005], size=steps.shape)
    est = se2.cumulative_compose(noisy, start=ref[0])
    # float64 arange: the same numbers (float × int arange is floating[Any] to the stubs)
    t = dt * np.arange(n, dtype=np.float64)
    return Trajectory(t, ref), Trajectory(t, est)


def example_pair(seed: int = 0) -> ExamplePair:
    """:func:`example_trajectories` with its reference relations: consecutive, then loops.

    Loops join poses within 2 m of each other and at least 60 s apart.
    """
    reference, estimate = example_trajectories(seed)
    local = generate_relations(reference, "consecutive")
    loops = generate_relations(reference, "loops", radius=2.0, min_separation_time=60.0)
    both = RelationSet(
        np.concatenate((local.first, loops.first)),
        np.concatenate((local.second, loops.second)),
        np.concatenate((local.delta, loops.delta)),
    )
    return ExamplePair(reference, estimate, both, len(local), len(loops))
