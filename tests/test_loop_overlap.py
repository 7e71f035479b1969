"""Loop pairs whose scans cannot overlap (:func:`slamrel.scans.proposals.expected_overlap`,
:func:`~slamrel.scans.proposals.can_overlap`, ``relations align --loop-min-overlap``).

Oracles: scans ray-cast in hand-built corridors (:func:`slamrel.simulation.laser.ray_cast`,
no noise) whose shared returns follow from the geometry by hand — two 180° scans back to
back see disjoint half-planes; two scans facing the same way down a straight corridor see
each other's every return; a wall between two corridors hides everything; two scans facing
each other ``L`` apart in a corridor of half width ``w`` share the side walls between
them, the beams from ``atan(w / L)`` to 90° on each side — and the property that the
overlap bounded over an uncertainty is at least the exact overlap at any pose within it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from relation_metric import se2
from slamrel.cli import main
from slamrel.commands.relations import LOOP_MIN_OVERLAP
from slamrel.scans.proposals import (
    Proposals,
    can_overlap,
    drop_unseen_loops,
    expected_overlap,
)
from slamrel.simulation.laser import LaserSensor, simulate_laser_log

EXACT = {"spread_xy": 0.0, "spread_theta": 0.0}


def _box(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]]


#: A straight corridor, 2 m wide (half width 1), 60 m long, closed at both ends.
CORRIDOR = np.array(_box(-30.0, -1.0, 30.0, 1.0))


def _scans(walls: np.ndarray, poses: list[tuple[float, float, float]]):
    """Noise-free 361-beam, 180° scans at ``poses`` (their poses as the log's)."""
    log = simulate_laser_log(
        walls,
        np.asarray(poses, dtype=float),
        sensor=LaserSensor(sigma=0.0),
        odometry_sigma=(0.0, 0.0, 0.0),
        seed=0,
    )
    return log.scans, log.truth


def _overlap(scans, truth, i: int = 0, j: int = 1, **spread) -> float:
    delta = se2.between(truth[i], truth[j])[None]
    return float(expected_overlap(scans, np.array([[i, j]]), delta, **(spread or EXACT))[0])


def test_back_to_back_scans_share_nothing_and_the_same_scans_facing_one_way_share_all():
    """Back to back 1 m apart (A at x = 0.5 facing +x, B at x = −0.5 facing −x): every
    return of A lies at x ≥ 0.5, i.e. 1 m or more behind B, and the other way round: 0.
    Turned to face +x both, B sees every return of A (nothing in between in a straight
    corridor): 1. Within a 0.3 m / 0.05 rad uncertainty the back-to-back pair still cannot
    share a tenth."""
    scans, truth = _scans(CORRIDOR, [(0.5, 0.0, 0.0), (-0.5, 0.0, math.pi), (-0.5, 0.0, 0.0)])
    assert _overlap(scans, truth, 0, 1) == 0.0
    assert _overlap(scans, truth, 0, 2) == 1.0
    assert _overlap(scans, truth, 0, 1, spread_xy=0.3, spread_theta=0.05) < 0.1
    pairs = np.array([[0, 1], [0, 2]])
    delta = se2.between(truth[pairs[:, 0]], truth[pairs[:, 1]])
    got = can_overlap(
        scans, pairs, delta, spread_xy=0.3, spread_theta=0.05, min_overlap=LOOP_MIN_OVERLAP
    )
    assert got.tolist() == [False, True]


@pytest.mark.parametrize("gap", [0.5, 1.0, 2.0])
def test_facing_each_other_share_the_side_walls_between_them(gap):
    """A at x = 0 facing +x, B at x = gap facing −x, half width 1: A's returns that B can
    see are those on the side walls with 0 < x < gap (beyond B they are behind it), the
    beams whose bearing lies between atan(1 / gap) and 90° on both sides (hand count on
    the 0.5° beam grid, ±90° included), of A's 361 returns."""
    scans, truth = _scans(CORRIDOR, [(0.0, 0.0, 0.0), (gap, 0.0, math.pi)])
    bearing = np.radians(np.arange(-180, 181) * 0.5)
    lateral = np.abs(np.sin(bearing)) > 1e-9
    along = np.full(bearing.shape, np.inf)
    along[lateral] = 1.0 / np.abs(np.tan(bearing[lateral]))
    along[np.abs(np.abs(bearing) - np.pi / 2) < 1e-9] = 0.0  # abeam: x = 0
    want = np.count_nonzero(along < gap) / 361  # B's side of the tolerance aside
    got = _overlap(scans, truth)
    assert abs(got - want) <= 3 / 361, (got, want)


def test_a_wall_between_two_corridors_hides_everything():
    """Two parallel corridors (y in [−1, 1] and [1.3, 3.3]) behind a 0.3 m wall; scans 2.3
    m apart facing the same way: by field of view and range alone they would share all,
    but every ray from one to the other's returns meets the wall first. (The beams
    bracketing a return's bearing are consulted: with a 0.2 m wall the beam next to the
    other corridor's wall at 3° would still reach within 10 cm of it at 22.9 m, grazing
    its own; 0.3 m keeps every such return beyond the 30 m corridor.)"""
    walls = np.vstack((CORRIDOR, _box(-30.0, 1.3, 30.0, 3.3)))
    scans, truth = _scans(walls, [(0.0, 0.0, 0.0), (0.0, 2.3, 0.0)])
    assert _overlap(scans, truth) == 0.0
    delta = se2.between(truth[0], truth[1])[None]
    blind = expected_overlap(scans, np.array([[0, 1]]), delta, tolerance=1e3, **EXACT)
    assert blind[0] > 0.9  # the wall is what hides them


def test_the_bound_over_the_uncertainty_is_never_below_the_overlap_at_a_pose_within_it():
    """Property: for a guess off the true relation by at most (s_xy, s_θ), the overlap
    bounded over that uncertainty is at least the exact overlap at the true pose — a pair
    is never judged by a guess that is off by the stated uncertainty. Scans along a
    corridor with a side room, random poses, random errors on the boundary of the set."""
    walls = np.vstack((CORRIDOR, _box(2.0, 1.0, 6.0, 5.0)))
    rng = np.random.default_rng(5)
    n = 40
    poses = np.column_stack(
        (rng.uniform(-5, 8, n), rng.uniform(-0.7, 0.7, n), rng.uniform(-np.pi, np.pi, n))
    )
    scans, truth = _scans(walls, [tuple(p) for p in poses])
    pairs = rng.integers(0, n, (300, 2))
    true = se2.between(truth[pairs[:, 0]], truth[pairs[:, 1]])
    exact = expected_overlap(scans, pairs, true, **EXACT)
    s_xy, s_th = rng.uniform(0.0, 1.0, 300), rng.uniform(0.0, 0.3, 300)
    ang = rng.uniform(-np.pi, np.pi, 300)
    guess = true.copy()
    guess[:, 0] += s_xy * np.cos(ang)
    guess[:, 1] += s_xy * np.sin(ang)
    guess[:, 2] += s_th * rng.choice([-1.0, 1.0], 300)
    bound = expected_overlap(scans, pairs, guess, spread_xy=s_xy, spread_theta=s_th)
    assert np.all(bound >= exact - 1e-12)
    assert exact.min() < 0.2 < 0.8 < exact.max()  # the draw holds both kinds of pair
    for level in (0.1, 0.3, 0.5, 0.7):
        kept = can_overlap(
            scans, pairs, guess, spread_xy=s_xy, spread_theta=s_th, min_overlap=level
        )
        assert kept[exact >= level].all(), level
    turned = true.copy()  # off in rotation only, by up to 0.6 rad
    turned[:, 2] += rng.uniform(-0.6, 0.6, 300)
    spread = np.abs(turned[:, 2] - true[:, 2])
    for level in (0.3, 0.6):
        kept = can_overlap(
            scans, pairs, turned, spread_xy=0.0, spread_theta=spread, min_overlap=level
        )
        assert kept[exact >= level].all(), level


def test_a_guess_off_by_the_uncertainty_does_not_drop_an_overlapping_pair():
    """The truth: A at x = 0 facing +x, B at x = 1 facing −x (facing each other: half of
    A's returns shared, by the count above). The guess puts B 1.5 m behind A (x = −0.5,
    back to back: nothing shared there). Judged within 0.3 m the pair cannot overlap;
    within 1.5 m (the guess's error) it can, and it is kept."""
    scans, truth = _scans(CORRIDOR, [(0.0, 0.0, 0.0), (1.0, 0.0, math.pi)])
    assert _overlap(scans, truth) > 0.4
    guess = np.array([[-0.5, 0.0, math.pi]])
    pair = np.array([[0, 1]])
    assert expected_overlap(scans, pair, guess, **EXACT)[0] == 0.0
    key = {"spread_theta": 0.05, "min_overlap": LOOP_MIN_OVERLAP}
    assert not can_overlap(scans, pair, guess, spread_xy=0.3, **key)[0]
    assert can_overlap(scans, pair, guess, spread_xy=1.5, **key)[0]


def test_consecutive_and_given_pairs_are_never_dropped():
    """Back to back scans (nothing shared) as a consecutive pair and as a loop pair: only
    the loop pair is left out, and counted."""
    scans, truth = _scans(CORRIDOR, [(0.5, 0.0, 0.0), (-0.5, 0.0, math.pi)])
    pair = np.array([[0, 1]])
    t = scans.timestamps
    prop = Proposals(
        np.vstack((pair, pair, pair)),
        t[[0, 0, 0]],
        t[[1, 1, 1]],
        np.array(["consecutive", "given", "loop"]),
        np.zeros(3),
    )
    kept, dropped = drop_unseen_loops(prop, scans, truth, min_overlap=LOOP_MIN_OVERLAP)
    assert dropped == 1 and kept.kind.tolist() == ["consecutive", "given"]
    same, none = drop_unseen_loops(prop, scans, truth, min_overlap=0.0)
    assert none == 0 and len(same) == 3


def _write_log(path, scans) -> None:
    """``scans`` as a CARMEN FLASER log (361 beams: CARMEN's 0.5° rule)."""
    lines = []
    for k in range(len(scans)):
        r = " ".join(f"{v:.3f}" for v in scans.ranges[k])
        x, y, th = scans.laser_pose[k]
        t = scans.timestamps[k] + 10
        lines.append(f"FLASER 361 {r} {x} {y} {th} {x} {y} {th} {t} host {t}\n")
    path.write_text("".join(lines))


def _out_and_back() -> list[tuple[float, float, float]]:
    """15 m out along the corridor's centre line facing +x, a half turn on the spot, 15 m
    back 0.1 m aside facing −x (0.1 m steps)."""
    out = [(0.1 * k, 0.0, 0.0) for k in range(151)]
    spin = [(15.0, 0.0, 0.1 * k) for k in range(1, 32)]
    back = [(15.0 - 0.1 * k, 0.1, math.pi) for k in range(1, 151)]
    return out + spin + back


def test_cli_leaves_out_loop_pairs_seen_back_to_back_and_says_so(tmp_path, capsys):
    """Out and back along a corridor, loop pairs within 1.6 m: every one joins a scan facing
    +x and one facing −x. Those back to back (the +x scan ahead of the −x one) share
    nothing and are left out; those facing each other 1 m or more apart (≥ 50 % shared, by
    the count above) are kept. What is left out is counted in the summary: with
    ``--loop-min-overlap 0`` the same pairs are aligned (or left beyond reach)."""
    scans, truth = _scans(CORRIDOR, _out_and_back())
    log = tmp_path / "log.clf"
    _write_log(log, scans)

    def loop_rows(*extra: str) -> tuple[np.ndarray, str]:
        rep = tmp_path / "r.csv"
        argv = ["relations", "align", str(log), "-o", str(tmp_path / "o.relations")]
        argv += ["--loops", "--loop-radius", "1.6", "--aligner", "icp"]
        argv += ["--global-search", "never", "--report", str(rep)]
        assert main([*argv, *extra]) == 0
        rows = np.genfromtxt(rep, delimiter=",", skip_header=1, usecols=(0, 1))
        t1, t2 = rows.T
        i = np.searchsorted(scans.timestamps + 10, t1 - 1e-6)
        j = np.searchsorted(scans.timestamps + 10, t2 - 1e-6)
        loop = np.abs(truth[i, 2] - truth[j, 2]) > 3.0  # one facing +x, one −x
        ahead = np.where(truth[i, 2] == 0.0, truth[i, 0] - truth[j, 0], truth[j, 0] - truth[i, 0])
        out = capsys.readouterr().out
        return np.round(ahead[loop], 3), out

    def count(said: str, before: str) -> int:
        return int(said.split(before)[0].split()[-1]) if before in said else 0

    every, said_every = loop_rows("--loop-min-overlap", "0")
    kept, said = loop_rows()
    assert (every > 0.05).sum() > 10  # back to back: aligned without the test
    assert not (kept > 0.05).any()  # and left out with it
    facing = every[every <= -1.0]
    assert facing.size > 10 and sorted(facing) == sorted(kept[kept <= -1.0])
    before = count(said, "before alignment")
    after = int(
        said.split("before alignment (at any pose within the guesses' uncertainty), ")[1].split()[0]
    )
    reach = "loop candidate(s) aligned beyond reach"
    assert before > 0 and after >= 0
    # every pair is accounted for: aligned, left beyond reach, or left out for its overlap
    assert len(every) + count(said_every, reach) == len(kept) + count(said, reach) + before + after


@pytest.mark.parametrize("value", ["-0.01", "nan", "1.5"])
def test_cli_loop_min_overlap_out_of_range_exits_2(tmp_path, capsys, value):
    log = tmp_path / "log.clf"
    log.write_text("")
    argv = ["relations", "align", str(log), "-o", str(tmp_path / "o.relations"), "--loops"]
    assert main([*argv, "--loop-min-overlap", value]) == 2
    assert "--loop-min-overlap must lie in [0, 1]" in capsys.readouterr().err


def test_cli_at_given_pairs_ignores_the_overlap_test(tmp_path):
    """``--at`` (the acceptance's true pairs) aligns every given pair whatever the minimum
    overlap: back-to-back pairs included, the same bytes."""
    scans, _ = _scans(CORRIDOR, [(0.5, 0.0, 0.0), (-0.5, 0.0, math.pi), (-0.5, 0.0, 0.0)])
    log = tmp_path / "log.clf"
    _write_log(log, scans)
    t = scans.timestamps + 10
    rel = tmp_path / "given.relations"
    rel.write_text(f"{t[0]} {t[1]} 0 0 0 0 0 0\n{t[0]} {t[2]} 0 0 0 0 0 0\n")
    out = []
    for value in ("0", "1"):
        o, r = tmp_path / f"o{value}.relations", tmp_path / f"r{value}.csv"
        argv = ["relations", "align", str(log), "--at", str(rel), "-o", str(o), "-q"]
        assert main([*argv, "--report", str(r), "--loop-min-overlap", value]) == 0
        out.append((o.read_bytes(), r.read_bytes()))
    assert out[0] == out[1]
    assert len(out[0][1].splitlines()) == 3  # header + both given pairs, reported


def test_the_default_minimum_overlap_is_the_documented_one():
    """docs/commands.md: ``--loop-min-overlap`` defaults to 0.3 (chosen on corridor worlds
    103 and 107, docs/laser-relations.md)."""
    from slamrel.cli import build_parser

    args = build_parser().parse_args(["relations", "align", "log.clf", "-o", "x.relations"])
    assert args.loop_min_overlap == LOOP_MIN_OVERLAP == 0.3
