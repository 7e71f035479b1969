"""Issue 39: memory with a ceiling — the pair budget of the quadratic strategies.

``--strategy loops`` once grew to 23.7 GB on 10⁶ poses and ``all-pairs`` passed 6 GB on 10⁴
poses. A selection over the budget is now refused up front (exit 3, saying why and what to
change) and ``loops`` streams its candidate pairs; ``benchmarks/bench_memory.py`` measures
the peak memory at 10⁶ poses.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import relation_metric.relations as relations
from relation_metric.errors import InputError
from relation_metric.relations import MAX_RELATIONS, generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.cli import main

ROOT = Path(__file__).resolve().parent.parent


def _laps(n: int, spacing: float = 0.1) -> Trajectory:
    """``n`` poses ``spacing`` m apart at 1 m/s around a 50 m circle (many laps)."""
    t = np.arange(n) * spacing
    a = t / 50.0
    return Trajectory(t, np.column_stack((50 * np.cos(a), 50 * np.sin(a), a + np.pi / 2)))


def _write_plain(path: Path, traj: Trajectory) -> str:
    np.savetxt(path, np.column_stack((traj.timestamps, traj.poses)), fmt="%.6f")
    return str(path)


def test_streamed_loops_equal_brute_force(monkeypatch):
    """The chunked search finds exactly the pairs of a full distance matrix (the oracle),
    whatever the chunk size; the time or the travel rule is applied after it."""
    rng = np.random.default_rng(3)
    n = 1500
    t = np.cumsum(rng.uniform(0.05, 0.2, n))
    xy = np.cumsum(rng.normal(0, 0.3, (n, 2)), axis=0) % 6.0  # wrapped: many revisits
    traj = Trajectory(t, np.column_stack((xy, rng.uniform(-3, 3, n))))
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    s = traj.path_length()
    monkeypatch.setattr(relations, "LOOP_CHUNK_PAIRS", 997)
    monkeypatch.setattr(relations, "LOOP_COUNT_SEGMENT", 211)
    for radius, sep_t, sep_d in ((0.4, 5.0, None), (0.7, None, 3.0), (0.3, 20.0, 1.0)):
        i, j = np.nonzero(np.triu(d <= radius, k=1))
        keep = np.zeros(i.size, bool)
        if sep_t is not None:
            keep |= t[j] - t[i] >= sep_t
        if sep_d is not None:
            keep |= s[j] - s[i] >= sep_d
        rel = generate_relations(
            traj,
            "loops",
            radius=radius,
            min_separation_time=sep_t,
            min_separation_distance=sep_d,
            key="index",
        )
        assert rel.first.size > 1000
        np.testing.assert_array_equal(rel.first, i[keep])
        np.testing.assert_array_equal(rel.second, j[keep])


@pytest.mark.parametrize(
    ("strategy", "kw", "needles"),
    [
        ("loops", {"radius": 1.0}, ("strategy 'loops' finds at least", "a smaller radius")),
        ("all-pairs", {}, ("makes 1,999,000 pairs", "strategy 'random' with a count")),
        ("random", {"count": 1001}, ("a count of 1,001", "a smaller count")),
        ("global", {"count": 1001}, ("a count of 1,001", "a smaller count")),
    ],
)
def test_over_budget_is_refused_saying_what_to_change(strategy, kw, needles):
    traj = _laps(2000, spacing=1.0)  # 6.4 laps of 314 poses: 2,000 poses near each pose
    with pytest.raises(InputError) as err:
        generate_relations(traj, strategy, max_relations=1000, **kw)
    for needle in (*needles, "more than the 1,000 relations", "max_relations"):
        assert needle in str(err.value)
    # within the budget the same selection is made
    rel = generate_relations(traj, strategy, max_relations=2_000_000, **kw)
    assert 1000 < len(rel) <= 2_000_000


def test_cli_all_pairs_over_budget_exit_3_in_option_words(tmp_path, capsys):
    """3,163 poses have 5,000,703 pairs: one over the budget, refused before any is made."""
    n = 3163
    assert n * (n - 1) // 2 > MAX_RELATIONS >= (n - 1) * (n - 2) // 2
    ref = _write_plain(tmp_path / "ref.txt", _laps(n))
    assert main(["evaluate", "--strategy", "all-pairs", ref, ref, "-q"]) == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "strategy 'all-pairs' on 3,163 poses makes 5,000,703 pairs" in err
    assert "--strategy random with --count N" in err
    assert "max_relations" not in err  # a library word: the command has no such option


@pytest.mark.slow
def test_cli_loops_at_a_million_poses_under_a_memory_limit(tmp_path):
    """10⁶ poses, 318 laps: billions of pose pairs within 1 m. Under a 2 GB address-space
    limit the command refuses with exit 3 and the budget's message (it used to grow to
    23.7 GB); all-pairs likewise."""
    ref = _write_plain(tmp_path / "ref.txt", _laps(1_000_000))
    limit = 2 * 1024**3
    code = textwrap.dedent(
        f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
        from slamrel.cli import main
        sys.exit(main(sys.argv[1:]))
        """
    )
    for strategy, needle in (("loops", "finds at least"), ("all-pairs", "499,999,500,000")):
        done = subprocess.run(
            [sys.executable, "-c", code, "evaluate", "--strategy", strategy, ref, ref, "-q"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            env={"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin"},
            timeout=300,
        )
        assert done.returncode == 3, done.stderr[-2000:]
        assert needle in done.stderr and "more than the 5,000,000 relations" in done.stderr
        assert "MemoryError" not in done.stderr and "Traceback" not in done.stderr
