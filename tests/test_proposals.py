"""Keyframe spacing of the proposed pairs (:func:`slamrel.scans.proposals.keyframes`).

Oracles: the path length summed here from the poses' steps (``np.linalg.norm`` of their
differences), and the first scan at or past each multiple of the spacing found by
``np.searchsorted`` on it — not the module's own loop.
"""

from __future__ import annotations

import numpy as np
import pytest

from slamrel.cli import main
from slamrel.scans.proposals import consecutive_pairs, keyframes, loop_pairs


def _drive(steps: np.ndarray) -> np.ndarray:
    """Poses ``(N + 1, 3)`` driving straight along x by ``steps`` ``(N,)`` [m]."""
    x = np.concatenate(([0.0], np.cumsum(steps)))
    return np.column_stack((x, np.zeros_like(x), np.zeros_like(x)))


def test_travel_keyframes_are_the_first_scans_past_each_multiple_of_the_distance():
    rng = np.random.default_rng(3)
    poses = _drive(rng.uniform(0.02, 0.3, 500))
    path = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))))
    marks = np.arange(1, int(path[-1] / 0.5) + 1) * 0.5
    expected = np.unique(np.concatenate(([0], np.searchsorted(path, marks, side="left"))))
    got = keyframes(poses, 0.5, 0.3, spacing="travel")
    np.testing.assert_array_equal(got, expected)


def test_travel_keyframes_are_as_dense_from_noisy_steps_as_from_exact_ones():
    """200 m of 0.1 m steps: exact, and with 5 mm noise a step (odometry). By travel both
    keep one keyframe per 0.5 m of their path; by motion the noisy steps overshoot 0.5 m by
    part of a step at every keyframe and keep markedly fewer (the bias ``travel`` removes)."""
    rng = np.random.default_rng(7)
    exact = _drive(np.full(2000, 0.1) + 1e-9)
    noisy = _drive(0.1 + rng.normal(0, 0.005, 2000))
    for poses in (exact, noisy):
        path = float(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1).sum())
        n = keyframes(poses, 0.5, 0.3, spacing="travel").size
        assert abs(n - (int(path / 0.5) + 1)) <= 1, (n, path)
    by_travel = keyframes(noisy, 0.5, 0.3, spacing="travel").size
    assert keyframes(noisy, 0.5, 0.3, spacing="motion").size < 0.95 * by_travel
    assert keyframes(exact, 0.5, 0.3, spacing="motion").size >= by_travel - 1


def test_travel_keyframes_keep_the_turns_on_the_spot():
    """Turning on the spot (no travel) in 0.07 rad steps: a keyframe each time the turn since
    the last one reaches 0.3 rad, i.e. every fifth pose (0.35 rad), across ±π."""
    theta = np.angle(np.exp(1j * 0.07 * np.arange(200)))  # wrapped: more than two turns
    poses = np.column_stack((np.zeros(200), np.zeros(200), theta))
    np.testing.assert_array_equal(
        keyframes(poses, 0.5, 0.3, spacing="travel"), np.arange(0, 200, 5)
    )


def test_pairs_follow_the_spacing_and_refuse_an_unknown_one():
    rng = np.random.default_rng(11)
    poses = _drive(0.1 + rng.normal(0, 0.005, 400))
    times = np.arange(poses.shape[0], dtype=float)
    key = keyframes(poses, 0.5, 0.3, spacing="travel")
    prop = consecutive_pairs(poses, times, distance=0.5, angle=0.3, spacing="travel")
    np.testing.assert_array_equal(prop.pairs, np.column_stack((key[:-1], key[1:])))
    back = poses[::-1].copy()  # the same corridor driven back: loop pairs between the legs
    back[:, 2] = np.pi
    both = np.vstack((poses, back))
    loops = loop_pairs(
        both,
        np.arange(both.shape[0], dtype=float),
        radius=0.3,
        min_travel=5.0,
        distance=0.5,
        angle=0.3,
        spacing="travel",
    )
    assert set(loops.pairs.ravel().tolist()) <= set(
        keyframes(both, 0.5, 0.3, spacing="travel").tolist()
    )
    assert len(loops) > 0
    with pytest.raises(ValueError, match="spacing"):
        keyframes(poses, 0.5, 0.3, spacing="time")


def test_cli_keyframes_travel_proposes_one_pair_per_distance_of_path(tmp_path):
    """Steps of 0.11 m: by motion a keyframe every fifth scan (0.55 m), by travel one per
    0.5 m of path (``relations align --keyframes travel``)."""
    ranges = " ".join(["1.00"] * 181)
    poses = [(0.11 * k, 0.0, 0.0) for k in range(60)]
    log = tmp_path / "log.clf"
    log.write_text(
        "".join(
            f"FLASER 181 {ranges} {x} {y} {t} {x} {y} {t} {10 + 0.2 * n} host {10 + 0.2 * n}\n"
            for n, (x, y, t) in enumerate(poses)
        )
    )

    def rows(*extra: str) -> int:
        rep = tmp_path / "r.csv"
        argv = ["relations", "align", str(log), "-o", str(tmp_path / "o.relations"), "-q"]
        argv += ["--aligner", "icp", "--global-search", "never", "--report", str(rep)]
        assert main([*argv, *extra]) == 0
        return len(rep.read_text().splitlines()) - 1

    assert rows() == len(range(0, 60, 5)) - 1
    assert rows("--keyframes", "travel") == int(0.11 * 59 / 0.5)


def _pair_counts(poses: np.ndarray, times: np.ndarray, spacing: str) -> tuple[int, int]:
    """(all, loop) pairs of ``relations align --loops --loop-max-angle 45``'s rules."""
    key = dict(distance=0.5, angle=0.3, spacing=spacing)
    cons = consecutive_pairs(poses, times, **key)
    loops = loop_pairs(poses, times, radius=1.0, min_travel=10.0, max_angle=np.pi / 4, **key)
    return len(cons) + len(loops), len(loops)


def test_chain_proposes_as_many_pairs_as_the_truth_when_keyframes_go_by_travel():
    """Issue 37's scoring acceptance rests on the pairs: loop pairs carry a drifting
    estimate's largest errors, so a reference with fewer of them scores it lower. On
    corridor world 107 (0.1 m steps) the scans' own chain proposes within 3 % of the pairs
    and 10 % of the loop pairs the true poses propose when keyframes go by travel; by motion
    it drops a fifth of the loop pairs (measured: 499 and 44 against 497 and 43 by travel;
    30 loop pairs against 38 by motion)."""
    from slamrel.scans.own_guesses import chain_guesses
    from slamrel.simulation.corridors import corridor_log

    _, log = corridor_log(107)
    s = log.scans
    chain = chain_guesses(s, s.laser_pose).poses
    travel = [_pair_counts(p, s.timestamps, "travel") for p in (chain, log.truth)]
    motion = [_pair_counts(p, s.timestamps, "motion") for p in (chain, log.truth)]
    (got, got_loops), (want, want_loops) = travel
    assert abs(got - want) <= 0.03 * want and abs(got_loops - want_loops) <= 0.1 * want_loops
    assert motion[0][1] < 0.85 * motion[1][1], motion
