"""The simulator's two range–bearing sensors, named and kept apart on purpose.

Both return measurements one row per (pose, landmark) pair, in pose order and, per pose, in
landmark order, with the range noise drawn before the bearing noise. They differ in what
they see and in how they do the arithmetic, and every seeded world and bundle depends on
those differences bit for bit, so they are two explicit models rather than one with
silently merged behaviour:

==================  ==========================================  ==============================
                    :func:`observe_field_of_view`               :func:`observe_all_around`
==================  ==========================================  ==============================
used by             the worlds of Hu et al.                     :func:`~slamrel.simulation.
                    (:func:`~slamrel.simulation.worlds.        bundles.simulate_bundle` (the
                    make_world`)                                test/benchmark bundles)
sees                ``min ≤ r ≤ max``, ``|bearing| ≤ fov/2``     ``min < r < max``, all around
geometry            landmark in the pose frame                  world-frame difference, bearing
                    (``inverse_transform_points``)              ``atan2(Δy, Δx) − θ``
noise               ``|r + n_r|`` (a range is a distance) and    ``r + n_r`` and bearing noise
                    bearing noise; or (``cartesian_sigma``)      (no reflection)
                    ``N(0, σ² I)`` on the relative position,
                    stored in polar form
measured from       the poses given                             the poses given, optionally a
                                                                fraction of the next increment
                                                                later (measurement times
                                                                between control times)
==================  ==========================================  ==============================
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from relation_metric.errors import InputError

__all__ = [
    "AllAroundSensor",
    "FieldOfViewSensor",
    "Readings",
    "observe_all_around",
    "observe_field_of_view",
]


class FieldOfViewSensor(NamedTuple):
    """Hu et al.'s sensor: a field of view and a range window, body-frame geometry.

    Attributes
    ----------
    sigma_range, sigma_bearing : float
        Polar noise (m, rad); unused when ``cartesian_sigma`` is given.
    max_range, min_range : float
        Inclusive range window (m).
    fov : float
        Full opening angle (rad), centred on the heading.
    cartesian_sigma : float, optional
        The paper's observation noise: ``N(0, σ² I)`` on the relative position (m).
    """

    sigma_range: float
    sigma_bearing: float
    max_range: float
    min_range: float
    fov: float
    cartesian_sigma: float | None = None


class AllAroundSensor(NamedTuple):
    """The test bundles' sensor: every landmark strictly inside a range window, all around.

    Attributes
    ----------
    sigma_range, sigma_bearing : float
        Polar noise (m, rad).
    max_range, min_range : float
        Exclusive range window (m).
    """

    sigma_range: float
    sigma_bearing: float
    max_range: float
    min_range: float = 0.5


class Readings(NamedTuple):
    """Measurements of one sensor sweep over a trajectory.

    Attributes
    ----------
    pose : ndarray of int, shape (K,)
        Row of the observing pose.
    landmark : ndarray of int, shape (K,)
        Row of the landmark seen.
    range, bearing : ndarray, shape (K,)
        Noisy measurement; bearing wrapped to ``[−π, π)``.
    """

    pose: NDArray[np.int64]
    landmark: NDArray[np.int64]
    range: NDArray[np.float64]
    bearing: NDArray[np.float64]


def observe_field_of_view(
    poses: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    sensor: FieldOfViewSensor,
    rng: np.random.Generator,
) -> Readings:
    """Every landmark in the field of view of every pose (see the module table).

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
    landmarks : ndarray, shape (L, 2)
    sensor : FieldOfViewSensor
    rng : numpy.random.Generator
        Draws the noise (``K`` ranges, then ``K`` bearings; or ``K × 2`` Cartesian).
    """
    # All pose × landmark pairs at once: (N, L, 2) landmark positions in each pose frame.
    k_p_l = se2.inverse_transform_points(poses[:, None, :], landmarks[None, :, :])
    r = np.hypot(k_p_l[..., 0], k_p_l[..., 1])
    b = np.arctan2(k_p_l[..., 1], k_p_l[..., 0])
    seen = (r <= sensor.max_range) & (np.abs(b) <= sensor.fov / 2) & (r >= sensor.min_range)
    k, lm = np.nonzero(seen)  # row-major: time order, then landmark id
    k, lm = k.astype(np.int64), lm.astype(np.int64)
    if sensor.cartesian_sigma is not None:
        z = k_p_l[k, lm] + rng.normal(0.0, sensor.cartesian_sigma, (k.size, 2))
        z_r, z_b = np.hypot(z[:, 0], z[:, 1]), np.arctan2(z[:, 1], z[:, 0])
        return Readings(k, lm, z_r, se2.wrap_angle(z_b))
    # a range is a distance: the rare noisy value below zero is reflected (|r + n|)
    z_r = np.abs(r[k, lm] + rng.normal(0.0, sensor.sigma_range, k.size))
    z_b = se2.wrap_angle(b[k, lm] + rng.normal(0.0, sensor.sigma_bearing, k.size))
    return Readings(k, lm, z_r, z_b)


def observe_all_around(
    truth: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    at: NDArray[np.int64],
    sensor: AllAroundSensor,
    rng: np.random.Generator,
    *,
    increments: NDArray[np.float64] | None = None,
    offset: float = 0.0,
) -> Readings:
    """Every landmark in the range window of the poses ``truth[at]`` (see the module table).

    Parameters
    ----------
    truth : ndarray, shape (N, 3)
    landmarks : ndarray, shape (L, 2)
    at : ndarray of int, shape (M,)
        Rows of ``truth`` that measure.
    sensor : AllAroundSensor
    rng : numpy.random.Generator
        Draws ``K`` range noises, then ``K`` bearing noises.
    increments : ndarray, shape (N − 1, 3), optional
        The true increments ``truth[k]⁻¹ ∘ truth[k+1]``; needed with ``offset``.
    offset : float
        Measure from ``truth[k] ∘ exp(offset · log u_k)`` (a constant twist), not ``truth[k]``.
    """
    if offset and increments is None:
        raise InputError("observe_all_around: an offset needs the increments")
    pose_k, lm_k = _candidates(truth, landmarks, at, sensor.max_range + 1.0)
    if offset:
        assert increments is not None  # checked on entry: an offset needs the increments
        pose_m = se2.compose(truth[pose_k], se2.exp(offset * se2.log(increments[pose_k])))
    else:
        pose_m = truth[pose_k]
    rel = landmarks[lm_k] - pose_m[:, :2]
    dist = np.hypot(rel[:, 0], rel[:, 1])
    keep = (dist < sensor.max_range) & (dist > sensor.min_range)
    pose_k, lm_k, pose_m, dist = pose_k[keep], lm_k[keep], pose_m[keep], dist[keep]
    bearing = np.arctan2(rel[keep, 1], rel[keep, 0]) - pose_m[:, 2]
    z_r = dist + sensor.sigma_range * rng.standard_normal(dist.shape[0])
    z_b = se2.wrap_angle(bearing + sensor.sigma_bearing * rng.standard_normal(dist.shape[0]))
    return Readings(pose_k, lm_k, z_r, z_b)


def _candidates(
    truth: NDArray[np.float64], lm: NDArray[np.float64], at: NDArray[np.int64], reach: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(pose, landmark) pairs closer than ``reach``, in chunks of poses (bounded memory)."""
    ks, ls = [], []
    chunk = max(1, 2_000_000 // max(lm.shape[0], 1))
    for start in range(0, at.shape[0], chunk):
        k = at[start : start + chunk]
        d = np.hypot(lm[None, :, 0] - truth[k, None, 0], lm[None, :, 1] - truth[k, None, 1])
        i, j = np.nonzero(d < reach)
        ks.append(k[i])
        ls.append(j)
    return np.concatenate(ks), np.concatenate(ls)
