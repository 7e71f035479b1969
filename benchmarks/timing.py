"""Timing helper shared by the benchmark scripts."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple


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


class Timed(NamedTuple):
    """Best wall and best CPU seconds over the runs (taken separately), and the last result."""

    wall: float
    cpu: float
    result: Any


def best_wall_cpu(fn: Callable[[], object], repeat: int = 3) -> Timed:
    """``repeat`` runs of ``fn``: the shortest wall time (``perf_counter``), the shortest CPU
    time (``process_time``, less sensitive to a shared machine) and the last result."""
    wall, cpu, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return Timed(wall, cpu, out)
