"""relation_metric.ids.rows_of: the one id lookup, against a dict oracle."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from relation_metric.ids import first_missing, first_repeat, rows_of

small_ids = st.lists(st.integers(-5, 20), max_size=30)


@settings(max_examples=200, deadline=None)
@given(small_ids, small_ids)
def test_rows_of_matches_a_dict_of_first_rows(ids, wanted):
    first: dict[int, int] = {}
    for row, i in enumerate(ids):
        first.setdefault(i, row)
    expected = [first.get(w, -1) for w in wanted]
    got = rows_of(np.array(ids, dtype=np.int64), np.array(wanted, dtype=np.int64))
    assert got.dtype == np.int64 and got.tolist() == expected


def test_rows_of_sorted_unsorted_and_shapes(rng):
    ids = rng.permutation(1000)[:700] * 3
    wanted = rng.integers(0, 3000, (50, 2))
    rows = rows_of(ids, wanted)
    assert rows.shape == (50, 2)
    hit = rows >= 0
    assert np.array_equal(ids[rows[hit]], wanted[hit])
    assert not np.isin(wanted[~hit], ids).any()
    s = np.sort(ids)  # the sorted path (no argsort) gives the same rows of the sorted column
    assert np.array_equal(s[rows_of(s, wanted)[hit]], wanted[hit])


def test_rows_of_empty_and_first_missing():
    assert rows_of(np.empty(0, np.int64), [1, 2]).tolist() == [-1, -1]
    assert rows_of([4, 5], np.empty(0, np.int64)).shape == (0,)
    assert first_missing(np.array([0, 3, -1, -1])) == 2
    assert first_missing(np.array([[0, 1], [2, -1]])) == 3
    assert first_missing(np.array([1, 2])) is None


def test_first_repeat_is_the_smallest_repeated_id_at_its_first_two_places():
    assert first_repeat(np.array([5, 3, 9], dtype=np.int64)) is None
    assert first_repeat(np.array([], dtype=np.int64)) is None
    # 7 and 2 both repeat: 2 is the smaller; its occurrences are at positions 3 and 4
    assert first_repeat(np.array([7, 1, 7, 2, 2, 2], dtype=np.int64)) == (3, 4)
    # with a tiebreak (line numbers), the earliest two lines win, not array order
    ids = np.array([4, 4, 4], dtype=np.int64)
    assert first_repeat(ids, tiebreak=np.array([30, 10, 20], dtype=np.int64)) == (1, 2)
