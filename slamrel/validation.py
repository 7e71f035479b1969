"""Is the recovery faithful? Monte Carlo study of recovered vs. online trajectories.

Over seeded runs of the reference EKF-SLAM with different noise types and deliberately
degraded maps (a fraction of the data associations corrupted), the relation metric of the
trajectory recovered from each run's final map should rank the runs as the relation metric of
the trajectory the filter estimated online does. :func:`faithfulness_study` runs the
pipeline for every configuration and returns both scores per run; Kendall's τ measures the
agreement of the two rankings. Recovery runs without an innovation gate (its default), so a
broken map is scored as broken (DESIGN.md, measured pitfalls).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import kendalltau

from slamrel.pipeline import run_pipeline

__all__ = ["FaithfulnessStudy", "faithfulness_study"]


@dataclass(frozen=True)
class FaithfulnessStudy:
    """Per-run mean translational relation errors of the online and recovered trajectories.

    Attributes
    ----------
    configs : list of dict
        ``{"noise", "corrupt_fraction", "seed"}`` per run.
    online, recovered : dict of relation set → ndarray, shape (R,)
        Mean translational error per run on ``"global"`` and ``"consecutive"`` relations.
    """

    world: str
    configs: list[dict[str, object]]
    online: dict[str, NDArray[np.float64]]
    recovered: dict[str, NDArray[np.float64]]

    def kendall_tau(self, relations: str = "global") -> float:
        """Kendall's τ between the online and the recovered ranking of the runs."""
        return float(kendalltau(self.online[relations], self.recovered[relations]).statistic)

    def ratio(self, relations: str = "global") -> NDArray[np.float64]:
        """Recovered / online mean error per run."""
        return self.recovered[relations] / self.online[relations]


def faithfulness_study(
    world: str = "complex1",
    *,
    noises: Sequence[str] = ("a", "b", "c"),
    corruptions: Sequence[float] = (0.0, 0.01, 0.02, 0.04),
    seeds: Sequence[int] = (0, 1),
) -> FaithfulnessStudy:
    """Run the pipeline for every (seed, noise, corruption) and collect both scores."""
    configs: list[dict[str, object]] = []
    rows: list[list[float]] = []
    for seed, noise, corrupt in itertools.product(seeds, noises, corruptions):
        r = run_pipeline(
            world, noise=noise, seed=seed, corrupt_fraction=corrupt, max_outlier_run=None
        )
        configs.append({"noise": noise, "corrupt_fraction": corrupt, "seed": seed})
        rows.append(
            [
                r.evaluations[k][s].translation["abs"].mean
                for k in ("online", "recovered")
                for s in ("global", "consecutive")
            ]
        )
    a = np.asarray(rows)
    return FaithfulnessStudy(
        world=world,
        configs=configs,
        online={"global": a[:, 0], "consecutive": a[:, 1]},
        recovered={"global": a[:, 2], "consecutive": a[:, 3]},
    )
