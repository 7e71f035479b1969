"""Relation-set adjustment (slamrel.backends.relation_adjust): oracles independent of the fit.

- Redundancy: in the (near-)linear regime the whitened squared error of the fitted relations
  sums, on average, to the dimension of the space of relations that poses can explain,
  ``3(N − C)``, against ``3E`` for the raw relations (least squares is a projection): a
  Monte Carlo over synthetic ladders with known noise.
- A gross relation is not spread: exact relations plus one 20 cm off — the off one is set
  aside, every other comes back exact (to rounding); without the guard it would move them.
- A tree (no cycle) comes back unchanged; two separate ladders are each fitted.
"""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.backends.relation_adjust import adjust_relations


def _ladder(n: int = 20, rungs: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two passes along a corridor (poses 0..n-1 going +x at y = 0, n..2n-1 coming back at
    y = 0.4, heading π), consecutive links along each, and a rung between the poses at the
    same x: true poses (2n, 3), pairs i, j."""
    x = 0.5 * np.arange(n)
    first = np.column_stack((x, np.zeros(n), np.zeros(n)))
    second = np.column_stack((x[::-1], np.full(n, 0.4), np.full(n, np.pi)))
    truth = np.vstack((first, second))
    i = [*range(n - 1), *range(n, 2 * n - 1)]
    j = [*range(1, n), *range(n + 1, 2 * n)]
    if rungs:
        i += list(range(n))
        j += list(range(2 * n - 1, n - 1, -1))
    return truth, np.array(i), np.array(j)


def test_whitened_error_drops_as_the_redundancy_predicts():
    truth, i, j = _ladder()
    exact = se2.between(truth[i], truth[j])
    e, n = i.size, truth.shape[0]
    sd = np.array([0.002, 0.001, 0.0005])  # anisotropic, small: the linear regime
    cov = np.tile(np.diag(sd**2), (e, 1, 1))
    rng = np.random.default_rng(7)
    raw, fitted = [], []
    for _ in range(150):
        noisy = se2.compose(exact, rng.normal(size=(e, 3)) * sd)
        adj = adjust_relations(i, j, noisy, cov)
        for out, d in ((raw, noisy), (fitted, adj.delta)):
            r = se2.between(exact, d)
            out.append(float(np.sum((r / sd) ** 2)))
        assert adj.redundancy == 3 * e - 3 * (n - 1)
        assert not adj.set_aside.any()
    # expectation 3E and 3(N - 1); the Monte Carlo's sd of the mean is about 2.5 % here
    assert np.mean(raw) == pytest.approx(3 * e, rel=0.08)
    assert np.mean(fitted) == pytest.approx(3 * (n - 1), rel=0.08)
    assert np.mean(fitted) / np.mean(raw) == pytest.approx((n - 1) / e, rel=0.1)


def test_a_gross_relation_is_set_aside_not_spread():
    truth, i, j = _ladder()
    exact = se2.between(truth[i], truth[j])
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-7]), (i.size, 1, 1))
    bad = exact.copy()
    k = i.size - 7  # a rung
    bad[k] = se2.compose(bad[k], [0.2, 0.0, 0.0])
    adj = adjust_relations(i, j, bad, cov)
    assert np.flatnonzero(adj.set_aside).tolist() == [k]
    np.testing.assert_array_equal(adj.delta[k], bad[k])  # kept as aligned
    others = np.arange(i.size) != k
    np.testing.assert_allclose(adj.delta[others], exact[others], atol=1e-9)
    # without the guard the fit pulls its cycles' relations toward it
    loose = adjust_relations(i, j, bad, cov, max_move=np.inf, max_move_angle=np.inf)
    moved = np.hypot(*(loose.delta[others] - exact[others])[:, :2].T)
    assert moved.max() > 0.01


def test_unused_relations_are_neither_used_nor_changed():
    truth, i, j = _ladder()
    exact = se2.between(truth[i], truth[j])
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-7]), (i.size, 1, 1))
    bad = exact.copy()
    bad[5] += [0.3, -0.2, 0.1]
    use = np.ones(i.size, dtype=bool)
    use[5] = False
    cov[5] = np.nan  # an unused relation may carry anything
    adj = adjust_relations(i, j, bad, cov, use=use)
    np.testing.assert_array_equal(adj.delta[5], bad[5])
    assert not adj.adjusted[5] and np.isnan(adj.chi2[5])
    np.testing.assert_allclose(adj.delta[use], exact[use], atol=1e-9)


def test_a_tree_comes_back_unchanged_and_separate_ladders_are_each_fitted():
    truth, i, j = _ladder(rungs=False)  # two chains: no cycle
    rng = np.random.default_rng(3)
    d = se2.compose(se2.between(truth[i], truth[j]), rng.normal(size=(i.size, 3)) * 0.01)
    cov = np.tile(np.eye(3) * 1e-4, (i.size, 1, 1))
    adj = adjust_relations(i, j, d, cov)
    np.testing.assert_allclose(adj.delta, d, atol=1e-9)
    assert not adj.adjusted.any() and adj.redundancy == 0
    # two ladders under different scan ids: the same fit as each alone
    t, a, b = _ladder(8)
    ex = se2.between(t[a], t[b])
    noisy = se2.compose(ex, rng.normal(size=(a.size, 3)) * [0.002, 0.002, 0.001])
    c = np.tile(np.diag([4e-6, 4e-6, 1e-6]), (a.size, 1, 1))
    alone = adjust_relations(a, b, noisy, c).delta
    both = adjust_relations(
        np.concatenate((a, a + 100)),
        np.concatenate((b, b + 100)),
        np.vstack((noisy, noisy)),
        np.concatenate((c, c)),
    ).delta
    np.testing.assert_allclose(both[: a.size], alone, atol=1e-9)
    np.testing.assert_allclose(both[a.size :], alone, atol=1e-9)


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda i, j, d, c: (i[:-1], j, d, c), "need i, j"),
        (lambda i, j, d, c: (i, i, d, c), "to itself"),
        (lambda i, j, d, c: (i, j, d, -c), "positive definite"),
        (lambda i, j, d, c: (i, j, np.where(d == d[0, 0], np.inf, d), c), "finite"),
    ],
)
def test_bad_input_is_one_clear_error(change, words):
    truth, i, j = _ladder(5)
    d = se2.between(truth[i], truth[j])
    c = np.tile(np.eye(3) * 1e-6, (i.size, 1, 1))
    with pytest.raises(InputError, match=words):
        adjust_relations(*change(i, j, d, c))
    with pytest.raises(InputError, match="positive"):
        adjust_relations(i, j, d, c, max_move=0.0)


@pytest.mark.parametrize(
    "option, value",
    [
        ("--adjust-max-move", "0"),
        ("--adjust-max-move", "-1"),
        ("--adjust-max-move", "nan"),
        ("--adjust-max-move", "11"),
        ("--adjust-max-move-angle", "0"),
        ("--adjust-max-move-angle", "4"),
    ],
)
def test_cli_adjust_limits_out_of_range_exit_2(tmp_path, capsys, option, value):
    from slamrel.cli import main

    argv = ["relations", "align", str(tmp_path / "none.clf"), "-o", str(tmp_path / "o.rel")]
    assert main([*argv, "--adjust", option, value]) == 2
    assert option in capsys.readouterr().err


@pytest.mark.slow
def test_cli_adjust_brings_the_relations_closer_to_the_truth(tmp_path, capsys):
    """``relations align --loops --adjust`` on the loop world (seed 0, keyframes by motion,
    guesses from the log's odometry with the default loop growth): the written relations'
    mean translational error against the true relations drops, none moves by more than the
    fit's limit, the summary says what was done."""
    from slamrel.cli import main
    from slamrel.formats.relations import read_relations
    from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log
    from tests.test_cycles import _flaser_log

    corners = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])
    truth = loop_path(corners, 0.3)
    log = simulate_laser_log(laser_world("loop"), np.vstack((truth, truth[:60])), seed=0)
    path = tmp_path / "loop.clf"
    _flaser_log(path, log.scans)
    errors = []
    for extra in ([], ["--adjust"]):
        out = tmp_path / f"r{len(extra)}.relations"
        argv = ["relations", "align", str(path), "--loops", "--keyframes", "motion", "-o"]
        assert main([*argv, str(out), *extra]) == 0
        said = capsys.readouterr().out
        assert ("adjusted: " in said) == bool(extra)
        rel = read_relations(out)
        k1 = np.rint(rel.first / 0.2).astype(int)
        k2 = np.rint(rel.second / 0.2).astype(int)
        err = se2.between(se2.between(log.truth[k1], log.truth[k2]), rel.delta)
        errors.append(np.hypot(err[:, 0], err[:, 1]))
    assert errors[1].size == errors[0].size
    assert np.abs(errors[1] - errors[0]).max() <= 0.05
    assert errors[1].mean() < 0.97 * errors[0].mean(), (errors[0].mean(), errors[1].mean())
