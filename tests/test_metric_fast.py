"""The metric's fast paths give the bits of the plain computations they replace."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from relation_metric import se2
from relation_metric.groups import SE2
from relation_metric.metric import relation_errors
from relation_metric.relations import RelationSet
from relation_metric.stats import summarize, summarize_with_squares
from relation_metric.time_association import associate
from relation_metric.trajectory import Trajectory


def bits(x):
    return np.asarray(x, dtype=np.float64).view(np.int64)


def plain_wrap(angle):
    """The reduction formula applied to every element (the oracle of se2.wrap_angle)."""
    a = np.asarray(angle, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        wrapped = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    wrapped = np.where(wrapped >= np.pi, wrapped - 2.0 * np.pi, wrapped)
    return np.where((a >= -np.pi) & (a < np.pi), a, wrapped)


def plain_errors(d, r, w, mode):
    """Six components, squared, weighted and summed over (M, 6) as before the fast path."""
    if mode == "paper":
        vec = SE2.error_components(SE2.ominus(d, r))
    else:
        vec = SE2.parameters(d) - SE2.parameters(r)
        vec[:, 3:6] = se2.wrap_angle(vec[:, 3:6])
    sq = vec * vec * np.asarray(w)
    trans2, rot2 = sq[:, 0:3].sum(axis=1), sq[:, 3:6].sum(axis=1)
    return np.sqrt(trans2), np.sqrt(rot2), np.sqrt(trans2 + rot2), vec


finite = st.floats(-1e6, 1e6, allow_nan=False)
edges = st.sampled_from(
    [np.pi, -np.pi, np.nextafter(np.pi, 0), np.nextafter(-np.pi, -4), 3 * np.pi, -0.0, 0.0]
)


@settings(max_examples=100, deadline=None)
@given(arrays(np.float64, st.integers(0, 40), elements=st.one_of(finite, edges)))
def test_wrap_angle_equals_the_formula_on_every_element(a):
    assert np.array_equal(bits(se2.wrap_angle(a)), bits(plain_wrap(a)))


def test_wrap_angle_keeps_shape_and_does_not_alias(rng):
    a = rng.uniform(-10, 10, (4, 5))
    out = se2.wrap_angle(a)
    assert out.shape == (4, 5) and not np.shares_memory(out, a)
    assert np.array_equal(bits(out), bits(plain_wrap(a)))
    assert float(se2.wrap_angle(3 * np.pi)) == float(plain_wrap(3 * np.pi))


nonneg = st.one_of(st.floats(0, 1e10), st.sampled_from([0.0, 1.0, 2.0, 1e-160]))


@settings(max_examples=150, deadline=None)
@given(arrays(np.float64, st.integers(0, 30), elements=nonneg))
def test_summarize_with_squares_equals_two_summaries(v):
    got = summarize_with_squares(v)
    want = (summarize(v), summarize(v * v))
    for g, w in zip(got, want):
        assert g.count == w.count
        for name in ("mean", "std", "min", "max", "median", "rmse"):
            assert bits(getattr(g, name)) == bits(getattr(w, name)), name


@pytest.mark.parametrize("n", [1, 2, 3, 1000, 1001])
def test_summarize_with_squares_large_and_tied(rng, n):
    v = np.round(np.abs(rng.normal(size=n)), 1)  # many ties
    got = summarize_with_squares(v)
    assert repr(got) == repr((summarize(v), summarize(v * v)))


def test_summarize_with_squares_falls_back_on_negative_and_nan():
    for v in (np.array([-1.0, 2.0, 3.0]), np.array([1.0, np.nan, 3.0])):
        got = summarize_with_squares(v)
        assert repr(got) == repr((summarize(v), summarize(v * v)))


@pytest.mark.parametrize("mode", ["paper", "metricevaluator"])
@pytest.mark.parametrize("weights", [None, "1,2,0,0,0,0.5", "0,0,3,1,1,0"])
def test_planar_errors_equal_the_six_component_sums(rng, mode, weights):
    m = 2000
    d = rng.normal(0, 5, (m, 3))
    r = rng.normal(0, 5, (m, 3))
    d[:, 2] = rng.uniform(-12, 12, m)  # unwrapped angles on purpose
    r[:, 2] = se2.wrap_angle(rng.uniform(-4, 4, m))
    d[:7] = np.nan
    w = np.ones(6) if weights is None else np.array([float(x) for x in weights.split(",")])
    with np.errstate(invalid="ignore"):
        got = relation_errors(d, r, mode=mode, weights=weights)
        want = plain_errors(d, r, w, mode)
    for g, x in zip((got.translation, got.rotation, got.combined, got.vector), want):
        assert np.array_equal(bits(g), bits(x))


def test_index_association_gathers_the_poses(rng):
    n, m = 50, 300
    est = Trajectory(np.arange(n) * 0.1, rng.normal(size=(n, 3)))
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    rel = RelationSet(i.astype(float), j.astype(float), np.zeros((m, 3)), key="index")
    a = associate(rel, est)
    assert np.array_equal(a.pose_first, est.poses[i]) and np.array_equal(
        a.pose_second, est.poses[j]
    )
    assert np.array_equal(a.index_first, i) and np.array_equal(a.index_second, j)
    assert a.valid.all() and not a.via_odometry.any() and not a.interpolated.any()
    assert not (a.reason != 0).any()
    # one index out of range: that relation alone is unassociated, the rest gathered as above
    j2 = j.copy()
    j2[3] = n
    b = associate(
        RelationSet(i.astype(float), j2.astype(float), np.zeros((m, 3)), key="index"), est
    )
    assert np.flatnonzero(~b.valid).tolist() == [3]
    assert np.array_equal(b.pose_first[b.valid], a.pose_first[b.valid])
    assert np.array_equal(b.index_second[b.valid], j[b.valid]) and b.index_second[3] == -1


@pytest.mark.parametrize("kind", ["uniform", "jitter", "ties", "gap", "short"])
def test_insertion_points_equal_searchsorted(rng, kind):
    from relation_metric.time_association import insertion_points

    n = 5 if kind == "short" else 3000
    times = {
        "uniform": 1.1e9 + np.arange(n) * 0.1,
        "jitter": np.sort(np.arange(n) * 0.1 + rng.uniform(0, 0.3, n)),
        "ties": np.sort(rng.integers(0, 40, n).astype(float)),
        "gap": np.concatenate((np.arange(n // 2) * 0.01, 1e5 + np.arange(n - n // 2) * 0.01)),
        "short": np.arange(n, dtype=float),
    }[kind]
    q = np.concatenate(
        (
            rng.uniform(times[0] - 5, times[-1] + 5, 4000),
            times,
            np.nextafter(times, np.inf),
            np.nextafter(times, -np.inf),
            [times[0] - 1e12, times[-1] + 1e12],
        )
    )
    want = np.searchsorted(times, q, side="left")
    assert np.array_equal(insertion_points(times, q), want)
