"""Export a :class:`~clients.textbook_ekfslam.Run` as a slamrel result bundle (docs/bundle.md).

Two exporters of the same run:

* :func:`write_odometry_bundle` (the reader of today accepts it): the odometry model fed
  with the client's own dead-reckoning poses (``odometry.csv``: forward Euler of the noisy
  controls, so each odometry increment is exactly the client's ``[v Δt, 0, ω Δt]``) and
  ``sigma_x, sigma_y, sigma_theta`` from ``Cx`` — valid because ``Cx`` is isotropic in x-y,
  so the robot-frame ``diag(σ_x², σ_y², σ_θ²)`` rotated into the world is ``Cx`` itself.
  Written with slamrel's own record and writer (``Bundle``, ``write_bundle``).
* :func:`recorder_for` + :func:`write_recorded_bundle`: the client reports to slamrel's
  :class:`~slamrel.formats.recorder.BundleRecorder` as it runs (``run(..., recorder=)``),
  with its values as written (a zero initial covariance, its online covariances, dropout
  ranges of 0, its per-step control covariance, its sensor mount).
* :func:`write_velocity_euler_bundle`: the client's motion model as it is, velocity
  controls integrated by forward Euler, stamped at the end of their interval, pose noise
  added in the world frame (the ``motion_model`` keys being added on branch wt-motion).
  Written by hand (the ``Bundle`` record of today cannot carry these keys).

Both write ``measurements.csv`` with the client's own landmark index as id (empty where it
left a measurement unassociated), ``map.csv`` + ``map_covariance.npy`` from the final state,
the truth with TRUE ids (``TRUE_ID_OFFSET + i``, which differ from the client's), and
``online.csv`` (the client's mean after each step's update).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from clients.textbook_ekfslam import Config, Run
from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from relation_metric.trajectory import Trajectory
from slamrel.formats.bundle import write_bundle
from slamrel.formats.recorder import BundleRecorder
from slamrel.formats.trajectories import write_trajectory

TRUE_ID_OFFSET = 1000


def groundtruth(run: Run) -> Trajectory:
    return Trajectory(run.times, run.truth)


def online(run: Run) -> Trajectory:
    return Trajectory(run.times, run.online)


def sensor_model(run: Run) -> SensorModel:
    """The measurement noise the client used (its R is diagonal)."""
    s = np.sqrt(np.diag(run.config.R))
    return SensorModel(float(s[0]), float(s[1]))


def _measurement_fields(run: Run) -> dict[str, np.ndarray]:
    a = run.meas_assoc >= 0
    return {
        "measurement_times": run.meas_t,
        "measurements": run.meas_z,
        "measurement_landmarks": np.where(a, run.meas_assoc, 0),
        "measurement_associated": a,
    }


def _truth_fields(run: Run) -> dict[str, object]:
    ids = TRUE_ID_OFFSET + np.arange(run.landmarks.shape[0])
    return {"groundtruth": groundtruth(run), "landmarks_groundtruth": (ids, run.landmarks)}


def odometry_bundle(run: Run) -> Bundle:
    """The run as an odometry-model bundle (in memory)."""
    cx = run.config.cx
    xy, marg, joint = run.client_map()
    return Bundle(
        motion=MotionModel("odometry", sigma=(cx[0], cx[1], cx[2])),
        sensor=sensor_model(run),
        odometry=Trajectory(run.times, run.dead_reckoning),
        map_ids=np.arange(xy.shape[0]),
        map_xy=xy,
        map_marginals=marg,
        map_covariance=joint,
        map_source="log",  # the client's final map, estimated from this very log
        initial_pose=np.zeros(3),
        initial_covariance=run.initial_covariance,
        description=(
            "textbook EKF-SLAM client (tests/clients/textbook_ekfslam.py), exported as the "
            "odometry model on its own dead reckoning; sigma from Cx "
            f"(init={run.config.init}, reuse_cx_as_r={run.config.reuse_cx_as_r})"
        ),
        **_measurement_fields(run),  # type: ignore[arg-type]
        **_truth_fields(run),  # type: ignore[arg-type]
    )


def _write_online(run: Run):  # type: ignore[no-untyped-def]
    def extra(root: Path) -> None:
        write_trajectory(root / "online.csv", online(run), format="csv")

    return extra


def write_odometry_bundle(run: Run, directory: Path) -> Path:
    write_bundle(directory, odometry_bundle(run), extra=_write_online(run))
    return Path(directory)


def true_map_bundle(bundle: Bundle, run: Run) -> Bundle:
    """Localisation in the true map: map = the true landmarks (exact), each association
    mapped to the true landmark of the client's landmark (wrong ones stay wrong)."""
    from dataclasses import replace

    truth_of = run.truth_of_client_landmark()
    a = bundle.measurement_associated
    ids = np.where(a, TRUE_ID_OFFSET + truth_of[bundle.measurement_landmarks], 0)
    n = run.landmarks.shape[0]
    return replace(
        bundle,
        measurement_landmarks=ids,
        map_ids=TRUE_ID_OFFSET + np.arange(n),
        map_xy=run.landmarks,
        map_marginals=np.zeros((n, 2, 2)),
        map_covariance=None,
        map_source="independent",  # the true landmarks, not the client's estimate
        path=None,
    )


# ------------------------------------------------------------- the client's own motion model


def _g(v: float) -> str:
    return f"{v:.17g}"


def write_velocity_euler_bundle(run: Run, directory: Path) -> Path:
    """The run with its own motion model, by hand after docs/bundle.md (+ the wt-motion keys).

    ``controls.csv`` under ``control_stamp: "end"``: row k (k ≥ 1) is the control of
    ``(t_{k-1}, t_k]``; row 0 only opens the log (its v, ω are zero and never used).
    """
    root = Path(directory)
    root.mkdir(parents=True, exist_ok=True)
    s = sensor_model(run)
    meta = {
        "format": "slamrel-bundle/1",
        "motion_model": {
            "type": "velocity",
            "integration": "euler",
            "control_stamp": "end",
            "pose_noise": {"frame": "world", "covariance": run.config.Cx.tolist()},
        },
        "sensor_model": {
            "type": "range_bearing",
            "sigma_range": s.sigma_range,
            "sigma_bearing": s.sigma_bearing,
        },
        "initial_pose": [0.0, 0.0, 0.0],
        "initial_covariance": run.initial_covariance.tolist(),
        "description": "textbook EKF-SLAM client, its own motion model (Euler, stamp end, "
        "world-frame pose noise)",
        "map_source": "log",
    }
    (root / "bundle.json").write_text(json.dumps(meta, indent=2) + "\n")
    c = np.column_stack((run.times, run.controls))
    (root / "controls.csv").write_text(
        "t,v,omega\n" + "".join(f"{_g(t)},{_g(v)},{_g(w)}\n" for t, v, w in c)
    )
    f = _measurement_fields(run)
    rows = [
        f"{_g(t)},{_g(r)},{_g(b)},{int(j) if ok else ''}\n"
        for t, (r, b), j, ok in zip(
            f["measurement_times"],
            f["measurements"],
            f["measurement_landmarks"],
            f["measurement_associated"],
        )
    ]
    (root / "measurements.csv").write_text("t,range,bearing,landmark\n" + "".join(rows))
    xy, marg, joint = run.client_map()
    (root / "map.csv").write_text(
        "landmark,x,y,cxx,cxy,cyy\n"
        + "".join(
            f"{j},{_g(p[0])},{_g(p[1])},{_g(m[0, 0])},{_g(m[0, 1])},{_g(m[1, 1])}\n"
            for j, (p, m) in enumerate(zip(xy, marg))
        )
    )
    np.save(root / "map_covariance.npy", joint, allow_pickle=False)
    for name, traj in (("groundtruth.csv", run.truth), ("online.csv", run.online)):
        (root / name).write_text(
            "t,x,y,theta\n"
            + "".join(
                f"{_g(t)},{_g(p[0])},{_g(p[1])},{_g(p[2])}\n" for t, p in zip(run.times, traj)
            )
        )
    (root / "landmarks_groundtruth.csv").write_text(
        "landmark,x,y\n"
        + "".join(
            f"{TRUE_ID_OFFSET + i},{_g(p[0])},{_g(p[1])}\n" for i, p in enumerate(run.landmarks)
        )
    )
    return root


# ------------------------------------------------- what a user could write with today's keys


def velocity_bundle(run: Run, *, shift: bool = True) -> Bundle:
    """The run as today's ``velocity`` model (exact arc, row held from its ``t``), in memory.

    ``Cx`` has no exact counterpart there (the velocity noise has no sideways slip): σ_v and
    σ_ω are Cx's x and θ standard deviations over Δt. ``shift=True`` stamps the control of
    ``(t_{k-1}, t_k]`` at ``t_{k-1}`` (today's convention); ``shift=False`` writes the
    client's own stamps (``t_k``), the one-step lag a user gets by not converting them.
    """
    cx, dt = run.config.cx, run.config.dt
    u = run.controls[1:]
    rows = np.vstack((u, np.zeros((1, 2)))) if shift else run.controls
    xy, marg, joint = run.client_map()
    return Bundle(
        motion=MotionModel("velocity", sigma=(cx[0] / dt, cx[2] / dt)),
        sensor=sensor_model(run),
        controls=np.column_stack((run.times, rows)),
        map_ids=np.arange(xy.shape[0]),
        map_xy=xy,
        map_marginals=marg,
        map_covariance=joint,
        map_source="log",  # the client's final map, estimated from this very log
        initial_pose=np.zeros(3),
        initial_covariance=run.initial_covariance,
        description=f"textbook EKF-SLAM client as today's velocity model (shift={shift})",
        **_measurement_fields(run),  # type: ignore[arg-type]
        **_truth_fields(run),  # type: ignore[arg-type]
    )


# ------------------------------------------------------------ the recorder (issue 38)


def recorder_for(cfg: Config) -> BundleRecorder:
    """A recorder stating the client's own models: forward Euler, controls stamped at the
    end of their step, world-frame ``Cx`` or (``motion_noise="control"``) the per-step
    body-frame covariance ``J M Jᵀ``; its R, its reach and its sensor mount."""
    if cfg.motion_noise == "control":
        motion = MotionModel(
            "velocity", step_covariance_frame="body", integration="euler", control_stamp="end"
        )
    else:
        motion = MotionModel(
            "velocity",
            pose_noise_frame="world",
            pose_noise=tuple(map(tuple, cfg.Cx)),
            integration="euler",
            control_stamp="end",
        )
    s = np.sqrt(np.diag(cfg.R))
    sensor = SensorModel(
        float(s[0]),
        float(s[1]),
        max_range=cfg.max_range,
        mount=cfg.mount if any(cfg.mount) else None,
    )
    return BundleRecorder(
        motion,
        sensor,
        initial_covariance=cfg.initial_variance * np.eye(3),
        description="textbook EKF-SLAM client, recorded as it ran (BundleRecorder)",
    )


def write_recorded_bundle(run: Run, recorder: BundleRecorder, directory: Path) -> Path:
    """The recorded run with its final map and joint covariance, and the truth."""
    xy, _, joint = run.client_map()
    truth = _truth_fields(run)
    return recorder.write(
        directory,
        np.arange(xy.shape[0]),
        xy,
        map_covariance=joint,
        groundtruth=truth["groundtruth"],
        landmarks_groundtruth=truth["landmarks_groundtruth"],
    )
