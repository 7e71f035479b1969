"""Timing helper shared by the benchmark scripts."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_of(
    fn: Callable[[], object], repeat: int = 3, *, clock: Callable[[], float] = time.perf_counter
) -> float:
    """The shortest of ``repeat`` runs of ``fn``, in seconds (wall clock unless ``clock``)."""
    times = []
    for _ in range(repeat):
        start = clock()
        fn()
        times.append(clock() - start)
    return min(times)
