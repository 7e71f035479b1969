"""Simulated worlds as SLAM result bundles, and EKF-SLAM runs that fill in the map.

``world_bundle`` turns a :class:`slamrel.worlds.World` into a bundle whose log (odometry or
controls, measurements with their true landmark ids) is the world's and whose map is the true
one (zero covariance): the input of ``slamrel slam``, and a perfect-map test case for the
recovery. ``slam_bundle`` runs the reference EKF-SLAM on a bundle's log and returns the bundle
a filter-based SLAM system would leave behind: its final map, joint map covariance and its
data associations.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

import numpy as np

from recovery.bundle import Bundle
from recovery.estimation.ekfslam import EkfSlamResult, ekf_slam
from recovery.models import MotionModel, SensorModel
from recovery.steps import build_steps
from slamrel.worlds import World

__all__ = ["world_bundle", "slam_bundle"]


def world_bundle(world: World) -> Bundle:
    """The world's log and true map as a bundle (ground truth included)."""
    nt = world.noise_params
    o = world.observations
    if world.controls is None:
        motion = MotionModel("odometry", sigma=(nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta))
        extra = {"odometry": world.odometry}
    else:
        rate = world.rate
        dt = (
            float(world.controls[1, 0] - world.controls[0, 0])
            if world.controls.shape[0] > 1
            else 1.0
        )
        # the per-row control noise the world drew (see slamrel.worlds.make_world)
        sv = nt.sigma_dx * np.sqrt(rate) / (dt * rate)
        sw = nt.sigma_dtheta * np.sqrt(rate) / (dt * rate)
        motion = MotionModel("velocity", sigma=(float(sv), float(sw)))
        extra = {"controls": world.controls}
    ids = np.arange(world.landmarks.shape[0], dtype=np.int64)
    return Bundle(
        motion=motion,
        sensor=SensorModel(nt.sigma_range, nt.sigma_bearing),
        measurement_times=o.t,
        measurements=np.column_stack((o.range, o.bearing)),
        measurement_landmarks=o.landmark,
        measurement_associated=np.ones(o.t.shape[0], dtype=bool),
        map_ids=ids,
        map_xy=world.landmarks,
        map_marginals=np.zeros((ids.size, 2, 2)),
        initial_pose=world.truth.poses[0],
        initial_covariance=1e-9 * np.eye(3),
        groundtruth=world.truth,
        landmarks_groundtruth=(ids, world.landmarks),
        description=(
            f"slamrel simulated world {world.name}, noise type {world.noise}, seed "
            f"{world.seed}, rate {world.rate}; map = true landmarks (perfect map)"
        ),
        **extra,  # type: ignore[arg-type]
    )


def slam_bundle(
    bundle: Bundle,
    *,
    association: Literal["known", "nn"] = "known",
    corrupt_fraction: float = 0.0,
    noise_scale: float = 1.0,
    outlier_gate: float | None = None,
    seed: int = 0,
    process_noise_scale: float = 1.0,
) -> tuple[Bundle, EkfSlamResult]:
    """Run the reference EKF-SLAM on ``bundle``'s log; return the SLAM result bundle.

    The returned bundle keeps the log (and ground truth) and replaces the map by the filter's
    final map with its marginals and joint covariance, and the measurements' landmark ids by
    the associations the filter made (empty where it rejected a measurement). The filter's
    assumed noise is the bundle's models scaled by ``noise_scale``; the bundle records the
    models it used. ``outlier_gate`` is the χ² validation gate on known-association updates
    (:func:`recovery.estimation.ekfslam.ekf_slam`); rejected measurements are left
    unassociated in the result bundle and counted in its description.
    ``process_noise_scale`` scales the motion model's standard deviations only (a filter
    mis-tuned in its process noise; ``noise_scale`` scales motion and sensor alike, which
    leaves the filter's gains, and so its online estimate, unchanged).
    """
    if process_noise_scale != 1.0:
        m0 = bundle.motion
        k = process_noise_scale
        bundle = replace(
            bundle,
            motion=replace(
                m0,
                sigma=None if m0.sigma is None else tuple(k * s for s in m0.sigma),
                alpha=None if m0.alpha is None else tuple(k**2 * a for a in m0.alpha),
            ),
        )
    steps = build_steps(bundle)
    true_ids = np.where(bundle.measurement_associated, bundle.measurement_landmarks, -1)
    res = ekf_slam(
        steps,
        bundle.measurements,
        np.where(bundle.measurement_associated, bundle.measurement_landmarks, np.nan),
        sensor=bundle.sensor,
        initial_pose=bundle.initial_pose,
        initial_covariance=bundle.initial_covariance,
        association=association,
        true_ids=true_ids,
        corrupt_fraction=corrupt_fraction,
        noise_scale=noise_scale,
        outlier_gate=outlier_gate,
        seed=seed,
    )
    m = res.landmark_ids.size
    marg = (
        np.stack([res.map_covariance[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] for k in range(m)])
        if m
        else np.zeros((0, 2, 2))
    )
    motion = bundle.motion
    sensor = bundle.sensor
    if noise_scale != 1.0:
        motion = replace(
            motion,
            sigma=None if motion.sigma is None else tuple(noise_scale * s for s in motion.sigma),
            alpha=None if motion.alpha is None else tuple(noise_scale**2 * a for a in motion.alpha),
        )
        sensor = SensorModel(noise_scale * sensor.sigma_range, noise_scale * sensor.sigma_bearing)
    out = replace(
        bundle,
        motion=motion,
        sensor=sensor,
        measurement_landmarks=np.where(res.association >= 0, res.association, 0),
        measurement_associated=res.association >= 0,
        map_ids=res.landmark_ids,
        map_xy=res.map_xy,
        map_marginals=marg,
        map_covariance=res.map_covariance,
        description=(bundle.description + "; " if bundle.description else "")
        + f"EKF-SLAM ({association} association, corrupted {corrupt_fraction:g}, "
        f"noise scale {noise_scale:g}"
        + ("" if process_noise_scale == 1.0 else f", process noise scale {process_noise_scale:g}")
        + (
            ""
            if outlier_gate is None
            else f", outlier gate {outlier_gate:g}: "
            f"{int(((res.association < 0) & bundle.measurement_associated).sum())} rejected"
        )
        + ")",
        path=None,
    )
    return out, res
