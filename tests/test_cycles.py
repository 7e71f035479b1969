"""The set-level cycle check of reference relations (slamrel.scans.cycles).

Oracles: finite differences of the composition (the propagated covariance), exact relation
sets (nothing may fail), and planted gross errors (recall and false alarms against the
planted set).
"""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from slamrel.scans.cycles import (
    CycleOptions,
    check_cycles,
    check_scan_relations,
    compose_cycles,
    find_cycles,
    mark_contradicted,
)
from slamrel.scans.proposals import Proposals
from slamrel.scans.relations import ScanRelations
from slamrel.simulation.relation_sets import lap_relations


def _lap_world(seed: int, laps: int = 2, bad_share: float = 0.08):
    w = lap_relations(seed, laps=laps, bad_share=bad_share)
    return w.poses, w.pairs, w.delta, w.covariance, w.bad


def _fd_composition(delta, edges, signs, eps=1e-6):
    """The cycle's composition and its Jacobian w.r.t. each used edge, by central
    differences."""

    def comp(d):
        p = np.zeros(3)
        for e, s in zip(edges, signs, strict=True):
            if e >= 0:
                p = se2.compose(p, d[e] if s > 0 else se2.inverse(d[e]))
        return p

    jac = {}
    for e in set(int(v) for v in edges if v >= 0):
        j = np.zeros((3, 3))
        for k in range(3):
            dp, dm = delta.copy(), delta.copy()
            dp[e, k] += eps
            dm[e, k] -= eps
            diff = comp(dp) - comp(dm)
            diff[2] = se2.wrap_angle(diff[2])
            j[:, k] = diff / (2 * eps)
        jac[e] = j
    return comp(delta), jac


def test_cycle_covariance_is_the_first_order_propagation():
    rng = np.random.default_rng(3)
    delta = np.column_stack((rng.normal(0, 2, (4, 2)), rng.uniform(-3, 3, 4)))
    a = rng.normal(size=(4, 3, 3))
    cov = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(3)
    edges = np.array([[0, 1, 2, 3], [2, 0, 3, -1]])
    signs = np.array([[1, -1, 1, -1], [-1, 1, -1, 0]])
    pose, sc = compose_cycles(delta, cov, edges, signs)
    for c in range(2):
        want, jac = _fd_composition(delta, edges[c], signs[c])
        np.testing.assert_allclose(pose[c], want, atol=1e-12)
        expect = sum(j @ cov[e] @ j.T for e, j in jac.items())
        np.testing.assert_allclose(sc[c], expect, rtol=1e-6, atol=1e-8)


def test_cycles_found_close_in_the_true_poses():
    """Every cycle found composes exactly to the identity on exact relations, and the
    cycles of a square with both diagonals are the expected ones."""
    x, pairs, _, _, _ = _lap_world(0, bad_share=0.0)
    exact = se2.between(x[pairs[:, 0]], x[pairs[:, 1]])
    owner, edges, signs = find_cycles(pairs[:, 0], pairs[:, 1], np.ones(len(pairs), bool))
    assert owner.size > 10 * len(pairs)
    pose, _ = compose_cycles(exact, np.zeros((len(pairs), 3, 3)), edges, signs)
    assert np.abs(pose).max() < 1e-9
    # a square 0-1-2-3 with diagonals 0-2, 1-3: through edge 0→1, two triangles (via 2 and
    # via 3) and two quadrilaterals (0→1→2→3→0 and 0→1→3→2→0)
    first, second = np.array([0, 1, 2, 3, 0, 1]), np.array([1, 2, 3, 0, 2, 3])
    tested = np.array([True, False, False, False, False, False])
    owner, edges, _ = find_cycles(first, second, tested)
    got = sorted(tuple(sorted(int(v) for v in row if v >= 0)) for row in edges)
    assert got == sorted([(0, 1, 4), (0, 3, 5), (0, 1, 2, 3), (0, 2, 4, 5)])
    assert (owner == 0).all()


def test_exact_relations_contradict_nothing():
    x, pairs, delta, cov, _ = _lap_world(1, bad_share=0.0)
    got = check_cycles(pairs[:, 0], pairs[:, 1], delta, cov)
    assert got.count == 0 and got.unchecked == 0
    # the χ² test at alpha = 0.01 on right relations (with the 1 cm floor): few failures
    assert got.failed.sum() <= 0.01 * got.cycles.sum()


@pytest.mark.parametrize("seed", [2, 5])
def test_planted_gross_errors_are_found(seed):
    """Recall and false alarms against the planted set (measured on seeds 0–4 of the
    3-lap world: recall 0.96–1.00, no false alarm)."""
    _, pairs, delta, cov, bad = _lap_world(seed)
    got = check_cycles(pairs[:, 0], pairs[:, 1], delta, cov)
    recall = np.count_nonzero(got.contradicted & bad) / np.count_nonzero(bad)
    false_alarm = np.count_nonzero(got.contradicted & ~bad) / np.count_nonzero(~bad)
    assert recall >= 0.93, recall
    assert false_alarm <= 0.005, false_alarm
    assert (got.blamed[got.contradicted] >= 2).all()


def test_one_cycle_cannot_say_who_is_wrong():
    """A triangle with one bad side: every side fails its only cycle; none is flagged."""
    x = np.array([[0, 0, 0], [2, 0, 0.3], [1, 1.5, -0.2]])
    first, second = np.array([0, 1, 2]), np.array([1, 2, 0])
    delta = se2.between(x[first], x[second])
    delta[1, 0] += 0.5
    got = check_cycles(first, second, delta, np.zeros((3, 3, 3)))
    assert got.cycles.tolist() == [1, 1, 1] and got.failed.tolist() == [1, 1, 1]
    assert got.count == 0


def test_chain_joins_loop_relations():
    """Loop relations alone close no cycle; with the odometry chain they do, and a planted
    bad loop relation is flagged while the chain takes no blame it does not deserve."""
    x, pairs, delta, cov, _ = _lap_world(4, bad_share=0.0)
    loop_rows = np.flatnonzero(pairs[:, 1] - pairs[:, 0] > 2)
    _, one = np.unique(pairs[loop_rows, 0], return_index=True)  # one loop per keyframe
    loops = np.zeros(len(pairs), bool)
    loops[loop_rows[one]] = True
    seq = pairs[:, 1] - pairs[:, 0] == 1
    alone = check_cycles(pairs[loops, 0], pairs[loops, 1], delta[loops], cov[loops])
    assert alone.unchecked > 0
    d = delta[loops].copy()
    d[7, 1] += 0.4
    chain = (pairs[seq, 0], pairs[seq, 1], delta[seq], cov[seq])
    got = check_cycles(pairs[loops, 0], pairs[loops, 1], d, cov[loops], chain=chain)
    assert np.flatnonzero(got.contradicted).tolist() == [7]
    assert got.unchecked < alone.unchecked


def _scan_relations(pairs, delta, cov, flags) -> ScanRelations:
    p = len(pairs)
    t1, t2 = pairs[:, 0] * 0.2, pairs[:, 1] * 0.2
    return ScanRelations(
        proposals=Proposals(pairs, t1, t2, np.full(p, "x"), np.zeros(p)),
        guess=delta,
        delta=delta,
        covariance=cov,
        matched_fraction=np.ones(p),
        residual=np.zeros(p),
        condition=np.ones(p),
        weak_direction=np.zeros((p, 2)),
        converged=np.ones(p, bool),
        initialiser=np.full(p, "guess"),
        flags=flags,
        suspicion=np.zeros(p),
    )


def test_scan_relations_flagged_ones_stay_out():
    x, pairs, delta, cov, bad = _lap_world(6, laps=2, bad_share=0.05)
    p = len(pairs)
    flags = np.where(np.arange(p) % 50 == 0, "low overlap", "")
    result = _scan_relations(pairs, delta, cov, flags)
    got = check_scan_relations(result)
    use = flags == ""
    direct = check_cycles(pairs[use, 0], pairs[use, 1], delta[use], cov[use])
    assert (got.cycles[~use] == 0).all() and not got.contradicted[~use].any()
    np.testing.assert_array_equal(got.contradicted[use], direct.contradicted)
    np.testing.assert_array_equal(got.failed[use], direct.failed)
    assert len(got.contradicted) == p


def test_options_bound_the_work():
    _, pairs, delta, cov, _ = _lap_world(7, bad_share=0.0)
    small = CycleOptions(max_cycles=3, max_length=3)
    owner, edges, _ = find_cycles(pairs[:, 0], pairs[:, 1], np.ones(len(pairs), bool), small)
    assert np.bincount(owner).max() <= 3
    assert (edges[:, 3] == -1).all()


def test_mark_contradicted_adds_the_flag_and_raises_suspicion():
    _, pairs, delta, cov, bad = _lap_world(8, laps=2, bad_share=0.05)
    p = len(pairs)
    result = _scan_relations(pairs, delta, cov, np.full(p, ""))
    check = check_scan_relations(result)
    assert check.count > 0
    marked = mark_contradicted(result, check)
    c = check.contradicted
    assert (marked.flags[c] == "contradicted").all() and (marked.flags[~c] == "").all()
    assert (marked.suspicion[c] > 1.5).all() and (marked.suspicion[~c] == 0).all()
    assert marked.flagged.sum() == check.count
    # a relation already flagged keeps its flags, the new one appended
    first = np.flatnonzero(c)[0]
    flags = np.where(np.arange(p) == first, "degenerate", "")
    again = mark_contradicted(_scan_relations(pairs, delta, cov, flags), check)
    assert again.flags[first] == "degenerate, contradicted"


def _flaser_log(path, scans) -> None:
    lines = []
    for k in range(len(scans)):
        r = " ".join(f"{v:.4f}" for v in scans.ranges[k])
        pose = " ".join(f"{v:.6f}" for v in scans.laser_pose[k])
        t = scans.timestamps[k]
        lines.append(f"FLASER {scans.ranges.shape[1]} {r} {pose} {pose} {t:.3f} sim {t:.3f}\n")
    path.write_text("".join(lines))


def test_align_cycle_check_option(tmp_path, capsys):
    """``relations align --cycle-check``: the flags written in the report are those of
    ``check_scan_relations`` on the command's own alignments (here: none contradicted in a
    well-observed room, every relation in some cycle)."""
    from slamrel.cli import main
    from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

    corners = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 4.5], [1.5, 4.5]])
    log = simulate_laser_log(laser_world("room"), loop_path(corners, 0.25)[:60], seed=3)
    path = tmp_path / "room.clf"
    _flaser_log(path, log.scans)
    out, report = tmp_path / "r.relations", tmp_path / "r.csv"
    args = ["relations", "align", str(path), "-o", str(out), "--report", str(report)]
    assert main([*args, "--distance", "0.25", "--cycle-check"]) == 0
    text = capsys.readouterr().out
    assert "cycle check: 0 contradicted by their cycles" in text
    assert "contradicted" not in report.read_text()


def test_confirmed_means_cycles_and_none_failed():
    _, pairs, delta, cov, bad = _lap_world(9, laps=2, bad_share=0.05)
    got = check_cycles(pairs[:, 0], pairs[:, 1], delta, cov)
    conf = got.confirmed()
    np.testing.assert_array_equal(conf, (got.cycles >= 2) & (got.failed == 0))
    assert not (conf & bad).any()  # a gross error fails its cycles
    # without gross errors nearly every relation is confirmed (alpha = 0.01 a cycle)
    _, pairs, delta, cov, _ = _lap_world(9, laps=2, bad_share=0.0)
    assert check_cycles(pairs[:, 0], pairs[:, 1], delta, cov).confirmed().mean() > 0.9
    assert (got.confirmed(min_cycles=10) <= conf).all()
