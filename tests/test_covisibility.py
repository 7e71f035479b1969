"""landmark_graph.covisibility against a dense pose × landmark incidence oracle."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from landmark_graph.covisibility import covisible_pairs, shared_observations
from relation_metric.errors import InputError


def _log(rng: np.random.Generator, n: int, n_lm: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    pose = rng.integers(0, n, k)
    landmark = rng.choice(np.arange(100, 100 + 3 * n_lm, 3), k)  # sparse, unsorted ids
    return pose, landmark


def _dense_row(pose: np.ndarray, landmark: np.ndarray, n: int) -> np.ndarray:
    """(n, L) index of the last observation of each landmark at each pose, −1: none."""
    ids = np.unique(landmark)
    row = np.full((n, ids.size), -1)
    for r, (p, lid) in enumerate(zip(pose, landmark, strict=True)):  # the oracle loops
        row[p, np.searchsorted(ids, lid)] = r
    return row


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n=st.integers(1, 12),
    n_lm=st.integers(1, 8),
    k=st.integers(0, 40),
    min_common=st.integers(1, 3),
    min_gap=st.integers(1, 3),
)
def test_covisible_pairs_equal_dense_counts(seed, n, n_lm, k, min_common, min_gap):  # type: ignore[no-untyped-def]
    pose, landmark = _log(np.random.default_rng(seed), n, n_lm, k)
    seen = (_dense_row(pose, landmark, n) >= 0).astype(int)
    common = seen @ seen.T
    want = [
        (i, j, common[i, j])
        for i in range(n)
        for j in range(i + min_gap, n)
        if common[i, j] >= min_common
    ]
    i, j, c = covisible_pairs(pose, landmark, n, min_common=min_common, min_gap=min_gap)
    assert list(zip(i.tolist(), j.tolist(), c.tolist(), strict=True)) == want


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 10), k=st.integers(0, 40))
def test_shared_observations_equal_dense_join(seed, n, k):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    pose, landmark = _log(rng, n, 5, k)
    pairs = rng.integers(0, n, (7, 2))
    row = _dense_row(pose, landmark, n)
    both = (row[pairs[:, 0]] >= 0) & (row[pairs[:, 1]] >= 0)
    seg, lm = np.nonzero(both)
    sh = shared_observations(pose, landmark, n, pairs)
    np.testing.assert_array_equal(sh.pair, seg)
    np.testing.assert_array_equal(sh.landmark, lm)
    np.testing.assert_array_equal(sh.first, row[pairs[seg, 0], lm])
    np.testing.assert_array_equal(sh.second, row[pairs[seg, 1], lm])


def test_hand_example_and_repeated_observation() -> None:
    # pose 0 sees 7, 9; pose 1 sees 9, 9 (twice), 7; pose 2 sees 5
    pose = np.array([0, 0, 1, 1, 1, 2])
    landmark = np.array([7, 9, 9, 9, 7, 5])
    i, j, c = covisible_pairs(pose, landmark, 3)
    assert (i.tolist(), j.tolist(), c.tolist()) == ([0], [1], [2])
    sh = shared_observations(pose, landmark, 3, [[0, 1], [1, 2]])
    assert sh.pair.tolist() == [0, 0]
    assert sh.first.tolist() == [0, 1] and sh.second.tolist() == [4, 3]  # the last 9 at pose 1


def test_refusals() -> None:
    with pytest.raises(InputError, match=r"pose index out of range 0\.\.2"):
        covisible_pairs([0, 3], [1, 1], 3)
    with pytest.raises(InputError, match="max_pairs"):
        covisible_pairs([0, 1, 2], [1, 1, 1], 3, max_pairs=2)  # C(3, 2) = 3 candidate pairs
    with pytest.raises(InputError, match="pair pose index"):
        shared_observations([0], [1], 2, [[0, 2]])
    i, j, c = covisible_pairs([], [], 4)
    assert i.size == j.size == c.size == 0
    assert shared_observations([], [], 4, [[0, 1]]).pair.size == 0
