"""Full and pose-only least-squares SLAM from a landmark log (Hu, Huang & Dissanayake 2010).

*Full* least squares estimates all poses and landmarks from odometry and every landmark
observation (:mod:`slamrel.backends.least_squares`).

*Pose-only* least squares first turns the landmark observations into relative-pose
constraints and then optimises the pose graph of those constraints (plus the odometry). For
a pose pair ``(i, j)`` the constraint ``δ̂_ij ≈ x_i⁻¹ ∘ x_j`` and its covariance come from a
small least squares over ``δ_ij`` and the landmarks both poses observe, in the frame of
``x_i`` (:func:`pair_constraints`; the landmarks are eliminated by a Schur complement, so
the covariance is the marginal of ``δ_ij``). One observation enters every constraint whose
pair contains its pose and shares its landmark; the pose graph treats constraints as
independent, so information is reused unless the observation's covariance is inflated.
Hu et al. compare two ways of choosing pairs, each with its own inflation rule:

* **Method 1** — adjacent pairs ``0-1, 1-2, …, (n-1)-n`` (and ``n-0`` closing the loop),
  every observation covariance multiplied by 2 (each observation is used in at most two
  constraints).
* **Method 2** — every pair of poses that shares at least ``k`` landmarks (the paper uses
  ``k = 5`` for the DLR data; :data:`METHOD2_MIN_COMMON`), each observation's covariance
  multiplied by the number of constraints that use it.

Both add the odometry as separate constraints on adjacent poses.

What the paper reports (and what this module reproduces on :mod:`slamrel.simulation`): full LS
and pose-only LS with Method 2 are both consistent (whole-trajectory NEES under the
one-sided χ² gate in most runs, :func:`relation_metric.consistency.nees1`); Method 2 is far
more accurate than Method 1, which throws away the information between non-adjacent poses;
pose-only LS is somewhat less accurate than full LS; and the map fitted to the pose-only
trajectory (NEES3) is about as consistent as full LS's map (NEES2). Without the inflation
(``inflate=False``) Method 2 reuses information and is over-confident: its whole-trajectory
NEES lies far beyond the χ² gate (``docs/design.md``, measured pitfalls; the figures in
benchmarks/README.md).

Where the per-pair least squares starts (``start``): the paper starts it at the ground
truth (``"truth"``, pass ``truth=``), which a reader with real data does not have. The default
is ``"odometry"`` (the odometry's relative pose): on the simulated worlds every pair reached
the same minimum from it as from the truth. ``"align"`` (the closed-form 2-D rigid alignment
of the shared landmarks' observations, needing neither) reached another minimum on a rare
pair whose few, noisy shared landmarks make the alignment ambiguous (the problems measured:
benchmarks/README.md).

Observations are relative positions ``z = r [cos b, sin b]``: with a Cartesian covariance
(``LandmarkLog.observation_covariance``, the paper's sensor model) as given, otherwise the
range-bearing covariance linearised, ``J diag(σ_r², σ_b²) Jᵀ``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.covisibility import SharedObservations, covisible_pairs, shared_observations
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.consistency import JointNees, nees2
from relation_metric.errors import DivergenceError, InputError
from relation_metric.trajectory import Trajectory, readonly
from slamrel.backends.graph import PoseGraph, initial_landmarks
from slamrel.backends.least_squares import GraphSolution, joint_covariance, solve_graph

__all__ = [
    "LandmarkLog",
    "SimulatedLog",
    "cartesian_observations",
    "full_least_squares",
    "pose_only_least_squares",
    "pose_only_graph",
    "ChiSquare",
    "relative_pose_chi2",
    "odometry_graph",
    "data_chi2",
    "pose_only_from_landmark_graph",
    "LandmarkGraphPoseOnly",
    "PoseOnlyResult",
    "PairConstraints",
    "pair_constraints",
    "method1_pairs",
    "method2_pairs",
    "observation_uses",
    "landmarks_given_poses",
    "nees3",
    "chained_start",
    "METHOD1_INFLATION",
    "METHOD2_MIN_COMMON",
]

Start = Literal["align", "odometry", "truth"]


class _NoiseSigmas(Protocol):
    """The standard deviations of a simulated noise type (``simulation.worlds.NoiseType``)."""

    @property
    def sigma_dx(self) -> float: ...
    @property
    def sigma_dy(self) -> float: ...
    @property
    def sigma_dtheta(self) -> float: ...
    @property
    def sigma_range(self) -> float: ...
    @property
    def sigma_bearing(self) -> float: ...


class _Sightings(Protocol):
    """Range-bearing observations, one row each (``simulation.worlds.Observations``)."""

    @property
    def pose(self) -> NDArray[np.int64]: ...
    @property
    def range(self) -> NDArray[np.float64]: ...
    @property
    def bearing(self) -> NDArray[np.float64]: ...
    @property
    def landmark(self) -> NDArray[np.int64]: ...


class SimulatedLog(Protocol):
    """What :meth:`LandmarkLog.from_world` reads of a simulated world
    (``slamrel.simulation.worlds.World`` has it): stated here, so that the back-ends need not
    import the simulator, which sits beside them."""

    @property
    def odometry(self) -> Trajectory: ...
    @property
    def observations(self) -> _Sightings: ...
    @property
    def noise_params(self) -> _NoiseSigmas: ...
    @property
    def observation_covariance(self) -> NDArray[np.float64] | None: ...


METHOD1_INFLATION = 2.0  # Hu et al.: each observation is used by two adjacent-pair constraints
METHOD2_MIN_COMMON = 5  # Hu et al.: pairs sharing at least 5 landmarks (DLR data)
_MIN_OBSERVABLE = 2  # two shared points fix a planar relative pose


@dataclass(frozen=True)
class LandmarkLog:
    """Odometry poses and landmark observations taken at those poses.

    Attributes
    ----------
    odometry : Trajectory
    pose : ndarray of int, shape (K,)
        Index of the observing odometry pose of each measurement.
    range, bearing : ndarray, shape (K,)
    landmark : ndarray of int, shape (K,)
        Known data association.
    sigma_odometry : tuple of 3 floats
        Per-step standard deviations of ``[dx, dy, dθ]``.
    sigma_range, sigma_bearing : float
        Range-bearing noise (used when ``observation_covariance`` is None).
    observation_covariance : ndarray, shape (2, 2) or (K, 2, 2), optional
        Covariance of the Cartesian observation ``r [cos b, sin b]`` in the sensor frame
        (the paper's sensor model), one for all or one per measurement; overrides the
        range-bearing noise.
    odometry_information : ndarray, shape (N − 1, 3, 3), optional
        Information of each odometry step; overrides ``sigma_odometry`` (a graph's own
        factors, :meth:`from_graph`).
    """

    odometry: Trajectory
    pose: NDArray[np.int64]
    range: Array
    bearing: Array
    landmark: NDArray[np.int64]
    sigma_odometry: tuple[float, float, float]
    sigma_range: float
    sigma_bearing: float
    observation_covariance: Array | None = None
    odometry_information: Array | None = None

    @classmethod
    def from_graph(cls, graph: PoseGraph) -> tuple[LandmarkLog, NDArray[np.int64]]:
        """A landmark graph (e.g. an iSAM or g2o file) as a log: the odometry is the
        initial guess's poses, the odometry information that of the factors ``k → k+1``
        (the first of each, in input order), the observations its pose–landmark factors
        with their own covariances.

        Returns
        -------
        log : LandmarkLog
        other : ndarray of int
            The pose–pose factors that are not an odometry step (loop closures, repeated
            steps): a pose-only graph keeps them as they are (none are dropped).

        Raises
        ------
        InputError
            When a step ``k → k+1`` has no factor, or there are no landmark factors.
        """
        n = graph.n_poses
        if graph.pl_k.size == 0:
            raise InputError("the graph has no pose-landmark factors: nothing to extract")
        step = np.full(max(n - 1, 0), -1, dtype=np.int64)
        chain = np.flatnonzero(graph.pp_j == graph.pp_i + 1)[::-1]  # first in input order wins
        step[graph.pp_i[chain]] = chain
        gap = np.flatnonzero(step < 0)
        if gap.size:
            raise InputError(
                f"no pose-pose factor from pose {int(gap[0])} to pose {int(gap[0]) + 1}: "
                "a log needs an odometry step between consecutive poses"
            )
        other = np.setdiff1d(np.arange(graph.pp_i.size), step)
        odo = se2.cumulative_compose(graph.pp_z[step], graph.poses[0]) if n > 1 else graph.poses
        z = np.asarray(graph.pl_z)
        order = np.argsort(graph.pl_k, kind="stable")  # observations in pose order
        log = cls(
            Trajectory.from_poses(odo),
            graph.pl_k[order],
            np.hypot(z[order, 0], z[order, 1]),
            np.arctan2(z[order, 1], z[order, 0]),
            graph.pl_l[order],
            (float("nan"),) * 3,  # type: ignore[arg-type]
            float("nan"),
            float("nan"),
            readonly(np.linalg.inv(graph.pl_info[order])),
            readonly(np.asarray(graph.pp_info[step])),
        )
        return log, readonly(other, np.int64)

    @classmethod
    def from_world(cls, world: SimulatedLog) -> LandmarkLog:
        """The odometry and observations of a simulated world, with its noise model."""
        nt = world.noise_params
        o = world.observations
        return cls(
            world.odometry,
            o.pose,
            o.range,
            o.bearing,
            o.landmark,
            (nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta),
            nt.sigma_range,
            nt.sigma_bearing,
            world.observation_covariance,
        )


def cartesian_observations(log: LandmarkLog) -> tuple[Array, Array]:
    """Relative positions ``(K, 2)`` and their information matrices ``(K, 2, 2)``."""
    c, s = np.cos(log.bearing), np.sin(log.bearing)
    z = np.column_stack((log.range * c, log.range * s))
    if log.observation_covariance is not None:
        cov0 = np.asarray(log.observation_covariance, dtype=np.float64)
        if cov0.ndim == 3:
            return z, np.asarray(np.linalg.inv(cov0), dtype=np.float64)
        return z, np.broadcast_to(np.linalg.inv(cov0.reshape(2, 2)), (z.shape[0], 2, 2)).copy()
    j = np.empty((z.shape[0], 2, 2))
    j[:, 0, 0], j[:, 0, 1] = c, -log.range * s
    j[:, 1, 0], j[:, 1, 1] = s, log.range * c
    r = np.diag([log.sigma_range**2, log.sigma_bearing**2])
    cov = j @ r @ np.swapaxes(j, 1, 2)
    return z, np.asarray(np.linalg.inv(cov), dtype=np.float64)


def _odometry_factors(log: LandmarkLog) -> tuple[NDArray[np.int64], Array, Array]:
    p = log.odometry.poses
    i = np.arange(p.shape[0] - 1)
    if log.odometry_information is not None:
        return i, se2.between(p[:-1], p[1:]), np.array(log.odometry_information)
    info = np.diag(1.0 / np.square(log.sigma_odometry))
    return i, se2.between(p[:-1], p[1:]), np.broadcast_to(info, (i.size, 3, 3)).copy()


def full_graph(log: LandmarkLog) -> tuple[PoseGraph, NDArray[np.int64]]:
    """The full SLAM graph (odometry + every observation) started at odometry; and the ids."""
    z, info = cartesian_observations(log)
    ids, lm_index = np.unique(log.landmark, return_inverse=True)
    i, u, oinfo = _odometry_factors(log)
    poses0 = log.odometry.poses
    graph = PoseGraph(
        poses=poses0,
        landmarks=initial_landmarks(poses0, log.pose, lm_index, z, ids.size),
        pp_i=i,
        pp_j=i + 1,
        pp_z=u,
        pp_info=oinfo,
        pl_k=log.pose,
        pl_l=lm_index,
        pl_z=z,
        pl_info=info,
    )
    return graph, ids


def full_least_squares(log: LandmarkLog) -> tuple[GraphSolution, NDArray[np.int64]]:
    """All poses and landmarks from odometry + observations; returns the solution and ids."""
    graph, ids = full_graph(log)
    return solve_graph(graph), ids


def _shared(log: LandmarkLog, pairs: NDArray[np.int64]) -> SharedObservations:
    """The landmarks each pair shares and their observations (sparse join, sorted by pair)."""
    return shared_observations(log.pose, log.landmark, len(log.odometry), pairs)


def method1_pairs(log: LandmarkLog, *, close_loop: bool = True) -> NDArray[np.int64]:
    """Method 1 pairs ``(i, i+1)`` (and ``(n-1, 0)`` with ``close_loop``), shape (E, 2).

    Only pairs sharing at least two landmarks (enough to fix a planar relative pose) are kept.
    """
    n = len(log.odometry)
    a = np.arange(n - 1)
    pairs = np.column_stack((a, a + 1))
    if close_loop and n > 2:
        pairs = np.vstack((pairs, [[n - 1, 0]]))
    common = np.bincount(_shared(log, pairs).pair, minlength=pairs.shape[0])
    return pairs[common >= _MIN_OBSERVABLE]


def method2_pairs(log: LandmarkLog, *, min_common: int = METHOD2_MIN_COMMON) -> NDArray[np.int64]:
    """Method 2 pairs: every ``i < j`` sharing at least ``min_common`` landmarks, shape (E, 2).

    Sorted by ``i``, then ``j`` (:func:`landmark_graph.covisibility.covisible_pairs`).
    """
    if min_common < _MIN_OBSERVABLE:
        raise InputError(f"min_common must be >= {_MIN_OBSERVABLE}, got {min_common}")
    i, j, _ = covisible_pairs(log.pose, log.landmark, len(log.odometry), min_common=min_common)
    return np.column_stack((i, j)).astype(np.int64)


def observation_uses(log: LandmarkLog, pairs: ArrayLike) -> NDArray[np.int64]:
    """How many of the pair constraints use each observation, shape (K,).

    Observation ``(p, l)`` is used by pair ``(p, q)`` or ``(q, p)`` when ``q`` also observes
    ``l``. A repeated observation (the same landmark twice at one pose) gets the count of
    its pose and landmark.
    """
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    sh = _shared(log, pr)
    k = log.pose.size
    uses = np.bincount(sh.first, minlength=k) + np.bincount(sh.second, minlength=k)
    key = np.unique(np.column_stack((log.pose, log.landmark)), axis=0, return_inverse=True)[1]
    per_key = np.zeros(int(key.max(initial=-1)) + 1, dtype=np.int64)
    np.maximum.at(per_key, key.ravel(), uses)
    return per_key[key.ravel()]


@dataclass(frozen=True)
class PairConstraints:
    """Relative-pose constraints extracted from shared landmark observations.

    Attributes
    ----------
    pairs : ndarray of int, shape (E, 2)
    delta : ndarray, shape (E, 3)
        ``δ̂_ij``, pose ``j`` in the frame of pose ``i``.
    covariance : ndarray, shape (E, 3, 3)
        Marginal covariance of ``δ̂_ij`` (landmarks eliminated).
    common : ndarray of int, shape (E,)
        Landmarks each pair shares.
    """

    pairs: NDArray[np.int64]
    delta: Array
    covariance: Array
    common: NDArray[np.int64]


def _rot(theta: Array) -> Array:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack((np.stack((c, -s), -1), np.stack((s, c), -1)), -2)


def _align(p: Array, q: Array, seg: NDArray[np.int64], starts: NDArray[np.int64]) -> Array:
    """Closed-form rigid ``[t, θ]`` per segment with ``p ≈ R q + t`` (least squares)."""
    cnt = np.diff(np.append(starts, seg.size))[:, None]
    pm = np.add.reduceat(p, starts) / cnt
    qm = np.add.reduceat(q, starts) / cnt
    pc, qc = p - pm[seg], q - qm[seg]
    sin = np.add.reduceat(qc[:, 0] * pc[:, 1] - qc[:, 1] * pc[:, 0], starts)
    cos = np.add.reduceat(qc[:, 0] * pc[:, 0] + qc[:, 1] * pc[:, 1], starts)
    th = np.arctan2(sin, cos)
    t = pm - np.einsum("eab,eb->ea", _rot(th), qm)
    return np.column_stack((t, th))


def _pair_cost(r1: Array, r2: Array, w1: Array, w2: Array, starts: NDArray[np.int64]) -> Array:
    """Per-pair ``Σ r1ᵀ W1 r1 + r2ᵀ W2 r2`` of the pair least squares, shape (E,)."""
    q = np.einsum("ra,rab,rb->r", r1, w1, r1) + np.einsum("ra,rab,rb->r", r2, w2, r2)
    return np.add.reduceat(q, starts)


def _relative_start(
    log: LandmarkLog, pr: NDArray[np.int64], start: Start, truth: Trajectory | None
) -> Array:
    """``x_i⁻¹ ∘ x_j`` of the odometry or the truth for each pair (``start``), shape (E, 3)."""
    if start == "odometry":
        p = log.odometry.poses
    elif start == "truth":
        if truth is None:
            raise InputError('start="truth" needs the true trajectory (truth=)')
        p = truth.poses
    else:
        raise InputError(f"unknown start {start!r}; expected align, odometry or truth")
    return se2.between(p[pr[:, 0]], p[pr[:, 1]])


def _pair_step(
    dl: Array,
    m: Array,
    obs: tuple[Array, Array, Array, Array],
    sg: NDArray[np.int64],
    st: NDArray[np.int64],
) -> tuple[Array, Array, Array]:
    """One damped Gauss–Newton step of every pair's least squares, the landmarks eliminated.

    ``dl`` (E, 3) the pairs' ``δ``; per row (one shared landmark of pair ``sg[r]``, rows of a
    pair starting at ``st``): ``m`` (R, 2) the landmark in the frame of pose ``i`` and
    ``obs = (za, zb, wa, wb)``, its observations from ``i`` and ``j`` and their informations.
    Each pair's step is halved until its cost does not increase (an ill-conditioned pair,
    e.g. two close landmarks under large noise, overshoots). Returns the steps of ``δ``
    (E, 3) and ``m`` (R, 2) and the reduced (Schur complement) information of ``δ``
    (E, 3, 3).

    Not :func:`recovery.lm.levenberg_marquardt`: these are thousands of independent
    problems of 3 + 2·(shared landmarks) unknowns solved side by side, each accepting or
    shortening its own step; one shared damping parameter would let one pair's rejected step
    slow all the others.
    """
    za, zb, wa, wb = obs
    r_mat = _rot(dl[sg, 2])  # (R, 2, 2)
    rt = np.swapaxes(r_mat, 1, 2)
    d = m - dl[sg, :2]
    r1 = m - za
    r2 = np.einsum("rab,rb->ra", rt, d) - zb
    # ∂r2/∂δ = [−Rᵀ, ∂Rᵀ/∂θ d];  ∂r2/∂m = Rᵀ;  ∂r1/∂m = I
    jd = np.empty((m.shape[0], 2, 3))
    jd[:, :, :2] = -rt
    c, s = np.cos(dl[sg, 2]), np.sin(dl[sg, 2])
    jd[:, 0, 2] = -s * d[:, 0] + c * d[:, 1]
    jd[:, 1, 2] = -c * d[:, 0] - s * d[:, 1]
    w2_r2 = np.einsum("rab,rb->ra", wb, r2)
    w2_jd = wb @ jd
    h_dd = np.swapaxes(jd, 1, 2) @ w2_jd  # (R, 3, 3)
    h_md = r_mat @ w2_jd  # (R, 2, 3)
    h_mm = wa + r_mat @ wb @ rt  # (R, 2, 2)
    g_d = np.einsum("rba,rb->ra", jd, w2_r2)
    g_m = np.einsum("rab,rb->ra", wa, r1) + np.einsum("rab,rb->ra", r_mat, w2_r2)
    h_mm_inv = np.linalg.inv(h_mm)
    k_dm = np.swapaxes(h_md, 1, 2) @ h_mm_inv  # (R, 3, 2)
    s_red = np.add.reduceat(h_dd - k_dm @ h_md, st)
    b_red = np.add.reduceat(g_d - np.einsum("rab,rb->ra", k_dm, g_m), st)
    try:
        step_d = -np.linalg.solve(s_red, b_red[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a degenerate pair: least-norm step for all
        step_d = -np.einsum("eab,eb->ea", np.linalg.pinv(s_red), b_red)
    step_m = -np.einsum("rab,rb->ra", h_mm_inv, g_m + np.einsum("rab,rb->ra", h_md, step_d[sg]))
    cost0 = _pair_cost(r1, r2, wa, wb, st)
    scale = np.ones(dl.shape[0])
    for _ in range(30):
        d_new = dl + scale[:, None] * step_d
        m_new = m + scale[sg, None] * step_m
        rn = np.einsum("rba,rb->ra", _rot(d_new[sg, 2]), m_new - d_new[sg, :2]) - zb
        new = _pair_cost(m_new - za, rn, wa, wb, st)
        worse = ~(new <= cost0 * (1 + 1e-9) + 1e-12)  # increases beyond rounding
        if not worse.any():
            break
        scale[worse] *= 0.5
    return step_d * scale[:, None], step_m * scale[sg, None], s_red


def pair_constraints(
    log: LandmarkLog,
    pairs: ArrayLike,
    inflation: ArrayLike = 1.0,
    *,
    start: Start = "odometry",
    truth: Trajectory | None = None,
    max_iterations: int = 500,
    tolerance: float = 1e-10,
) -> PairConstraints:
    """Relative pose and marginal covariance of each pair from the landmarks both observe.

    For pair ``(i, j)`` with shared landmarks ``l`` (positions ``m_l`` in the frame of ``i``)
    the least squares minimises ``Σ_l ‖m_l − z_il‖²_{W_il} + ‖R_δᵀ (m_l − t_δ) − z_jl‖²_{W_jl}``
    over ``δ = [t_δ, θ_δ]`` and the ``m_l``, by Gauss–Newton on all pairs at once (the
    landmarks eliminated per pair with a Schur complement; vectorised over pairs and rows).

    Parameters
    ----------
    log : LandmarkLog
    pairs : array_like of int, shape (E, 2)
        Each pair must share at least two landmarks.
    inflation : float or array_like, shape (K,)
        Factor on each observation's covariance (2 for Method 1, the use count for Method 2).
    start : {"align", "odometry", "truth"}
        Initial ``δ`` (see the module docstring); ``"truth"`` needs ``truth``.
    truth : Trajectory, optional
        True poses, for ``start="truth"``.
    max_iterations, tolerance :
        Gauss–Newton stops when the largest step component falls below ``tolerance``.

    Returns
    -------
    PairConstraints

    Raises
    ------
    DivergenceError
        When the iterations do not converge (a pair's problem is degenerate).
    """
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    z, info = cartesian_observations(log)
    k = z.shape[0]
    infl = np.broadcast_to(np.asarray(inflation, dtype=np.float64), (k,))
    if np.any(infl <= 0):
        raise InputError("covariance inflation factors must be positive")
    info = info / infl[:, None, None]
    sh = _shared(log, pr)
    common = np.bincount(sh.pair, minlength=pr.shape[0])
    if pr.shape[0] and common.min() < _MIN_OBSERVABLE:
        e_bad = int(np.argmin(common))
        raise InputError(
            f"pose pair {int(pr[e_bad, 0])}-{int(pr[e_bad, 1])} shares {int(common[e_bad])} "
            f"landmark(s); a relative pose needs at least {_MIN_OBSERVABLE}"
        )
    seg, ra, rb = sh.pair, sh.first, sh.second  # rows sorted by pair
    starts = np.searchsorted(seg, np.arange(pr.shape[0]))
    za, zb, wa, wb = z[ra], z[rb], info[ra], info[rb]
    if start == "align":
        delta = _align(za, zb, seg, starts)
    else:
        delta = _relative_start(log, pr, start, truth)
    delta = np.array(delta, dtype=np.float64).reshape(-1, 3)
    m = za.copy()  # landmark guesses: the observation from pose i
    n_pairs = pr.shape[0]
    s_all = np.empty((n_pairs, 3, 3))
    active = np.arange(n_pairs)  # pairs still iterating (large-residual pairs converge slowly)
    rows = np.arange(seg.size)
    for _ in range(max_iterations):
        if active.size == 0:
            break
        sg = np.searchsorted(active, seg[rows])  # active-local pair index of each row
        st = np.searchsorted(sg, np.arange(active.size))
        obs = (za[rows], zb[rows], wa[rows], wb[rows])
        step_d, step_m, s_all[active] = _pair_step(delta[active], m[rows], obs, sg, st)
        delta[active] += step_d
        delta[active, 2] = se2.wrap_angle(delta[active, 2])
        m[rows] += step_m
        if not (np.isfinite(delta).all() and np.isfinite(m).all()):
            raise DivergenceError("pair least squares diverged (non-finite estimate)")
        big = np.abs(step_d).max(axis=1) >= tolerance
        big |= np.maximum.reduceat(np.abs(step_m).max(axis=1), st) >= tolerance
        active = active[big]
        rows = rows[big[sg]]
    if active.size:
        e_bad = int(active[0])
        raise DivergenceError(
            f"pair least squares for poses {int(pr[e_bad, 0])}-{int(pr[e_bad, 1])} did not "
            f"converge in {max_iterations} iterations"
        )
    cov = np.linalg.inv(s_all)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    return PairConstraints(pr, readonly(delta), readonly(cov), readonly(common, np.int64))


@dataclass(frozen=True)
class PoseOnlyResult:
    """Pose-only least squares: the constraints, the pose graph and its solution.

    Attributes
    ----------
    solution : GraphSolution
    graph : PoseGraph
        The pose graph solved (constraints, then odometry when used); for covariances.
    constraints : PairConstraints
    method : int
    """

    solution: GraphSolution
    graph: PoseGraph
    constraints: PairConstraints
    method: int

    @property
    def trajectory(self) -> Trajectory:
        return Trajectory.from_poses(self.solution.poses)

    @property
    def pairs(self) -> NDArray[np.int64]:
        return self.constraints.pairs

    @property
    def delta(self) -> Array:
        return self.constraints.delta

    @property
    def covariance(self) -> Array:
        return self.constraints.covariance


def chained_start(log: LandmarkLog, constraints: PairConstraints) -> Array:
    """Initial poses chained from each step's odometry fused with its landmark constraint.

    For each step ``i → i+1`` with a landmark constraint of the pair ``(i, i+1)`` the two
    estimates of the step are fused by their information (``(Ω_o + Ω_c)⁻¹ (Ω_o u + Ω_c δ)``,
    angles taken relative to the odometry's); steps without one keep the odometry. The
    chain starts at odometry pose 0.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    oi, ou, oinfo = _odometry_factors(log)
    pr = constraints.pairs
    adj = pr[:, 1] == pr[:, 0] + 1
    step = ou.copy()
    if adj.any():
        i = pr[adj, 0]
        ci = np.linalg.inv(constraints.covariance[adj])
        d = se2.minus(constraints.delta[adj], ou[i])
        fused = np.linalg.solve(oinfo[i] + ci, np.einsum("eab,eb->ea", ci, d)[..., None])[..., 0]
        step[i] = ou[i] + fused
    return se2.cumulative_compose(step, log.odometry.poses[0])


def pose_only_least_squares(
    log: LandmarkLog,
    *,
    method: Literal[1, 2] = 2,
    min_common: int = METHOD2_MIN_COMMON,
    close_loop: bool = True,
    inflate: bool = True,
    odometry: bool = True,
    start: Start = "odometry",
    truth: Trajectory | None = None,
    initial: Literal["chained", "odometry"] = "chained",
) -> PoseOnlyResult:
    """Pose-only SLAM after Hu et al.: pair constraints from shared landmarks, then a pose graph.

    Parameters
    ----------
    log : LandmarkLog
    method : {1, 2}
        1: adjacent pairs, covariance × :data:`METHOD1_INFLATION`; 2: pairs sharing
        ``≥ min_common`` landmarks, covariance × number of constraints using the observation.
    min_common : int
        Method 2's ``k`` (paper: 5).
    close_loop : bool
        Method 1 also links the last pose to the first.
    inflate : bool
        Apply the method's covariance inflation (False reuses information: for comparison).
    odometry : bool
        Add the odometry as constraints on adjacent poses.
    start, truth :
        Where each pair's least squares starts (see :func:`pair_constraints`).
    initial : {"chained", "odometry"}
        Start of the pose graph: :func:`chained_start` (default) or the raw odometry. Under
        noise b (0.2 rad a step) the odometry is far enough off that Levenberg–Marquardt
        stops in a poor minimum in some runs of the study, for Method 1 and Method 2 but not
        for full LS (the runs and errors: benchmarks/README.md).

    Returns
    -------
    PoseOnlyResult
        Pose 0 is held at odometry pose 0.
    """
    graph, cons = pose_only_graph(
        log,
        method=method,
        min_common=min_common,
        close_loop=close_loop,
        inflate=inflate,
        odometry=odometry,
        start=start,
        truth=truth,
        initial=initial,
    )
    return PoseOnlyResult(solve_graph(graph), graph, cons, int(method))


def pose_only_graph(
    log: LandmarkLog,
    *,
    method: Literal[1, 2] = 2,
    min_common: int = METHOD2_MIN_COMMON,
    close_loop: bool = True,
    inflate: bool = True,
    odometry: bool = True,
    start: Start = "odometry",
    truth: Trajectory | None = None,
    initial: Literal["chained", "odometry"] = "chained",
) -> tuple[PoseGraph, PairConstraints]:
    """The pose graph of :func:`pose_only_least_squares` (same parameters), not solved:
    the Method 1/2 constraints, then the odometry when used; and the constraints."""
    n = len(log.odometry)
    if n < 2:
        raise InputError("pose-only least squares needs at least 2 poses")
    if method == 1:
        pairs = method1_pairs(log, close_loop=close_loop)
        inflation: ArrayLike = METHOD1_INFLATION if inflate else 1.0
    elif method == 2:
        pairs = method2_pairs(log, min_common=min_common)
        inflation = np.maximum(observation_uses(log, pairs), 1) if inflate else 1.0
    else:
        raise InputError(f"method must be 1 or 2, got {method!r}")
    cons = pair_constraints(log, pairs, inflation, start=start, truth=truth)
    pp_i, pp_j = pairs[:, 0], pairs[:, 1]
    pp_z, pp_info = cons.delta, np.asarray(np.linalg.inv(cons.covariance), dtype=np.float64)
    if odometry:
        oi, ou, oinfo = _odometry_factors(log)
        pp_i, pp_j = np.concatenate((pp_i, oi)), np.concatenate((pp_j, oi + 1))
        pp_z, pp_info = np.concatenate((pp_z, ou)), np.concatenate((pp_info, oinfo))
    if initial == "chained":
        poses0 = chained_start(log, cons)
    elif initial == "odometry":
        poses0 = np.asarray(log.odometry.poses)
    else:
        raise InputError(f"unknown initial {initial!r}; expected chained or odometry")
    graph = PoseGraph(
        poses=poses0,
        landmarks=np.empty((0, 2)),
        pp_i=pp_i,
        pp_j=pp_j,
        pp_z=pp_z,
        pp_info=pp_info,
    )
    return graph, cons


@dataclass(frozen=True)
class LandmarkGraphPoseOnly:
    """A landmark graph's pose-only problem (:func:`pose_only_from_landmark_graph`).

    Attributes
    ----------
    graph : PoseGraph
        The Method 1/2 constraints, the odometry steps, then the landmark graph's other
        pose–pose factors (unchanged); started at the chained guess.
    log : LandmarkLog
        The landmark graph as a log (:meth:`LandmarkLog.from_graph`).
    constraints : PairConstraints
    kept : int
        Pose–pose factors of the landmark graph other than the odometry steps, carried over.
    """

    graph: PoseGraph
    log: LandmarkLog
    constraints: PairConstraints
    kept: int


def pose_only_from_landmark_graph(
    graph: PoseGraph,
    *,
    method: Literal[1, 2] = 2,
    min_common: int = METHOD2_MIN_COMMON,
    start: Start = "align",
) -> LandmarkGraphPoseOnly:
    """Hu et al.'s pose-only extraction on a user's landmark graph (e.g. Victoria Park):
    the graph as a log, the Method 1/2 pair constraints from its observations (each pair's
    least squares started at ``start``: by default the rigid alignment of the shared
    landmarks' observations, since on a long run the odometry's relative pose of two
    revisits can be too far off to converge from, as on Victoria Park: benchmarks/README.md),
    plus its odometry and any other pose–pose factors. Optimise the result with least
    squares or TORO; fit the landmarks to
    the poses afterwards with :func:`landmarks_given_poses`."""
    log, other = LandmarkLog.from_graph(graph)
    pg, cons = pose_only_graph(log, method=method, min_common=min_common, start=start)
    merged = PoseGraph(
        poses=pg.poses,
        landmarks=np.empty((0, 2)),
        pp_i=np.concatenate((pg.pp_i, graph.pp_i[other])),
        pp_j=np.concatenate((pg.pp_j, graph.pp_j[other])),
        pp_z=np.concatenate((pg.pp_z, graph.pp_z[other])),
        pp_info=np.concatenate((pg.pp_info, graph.pp_info[other])),
    )
    return LandmarkGraphPoseOnly(merged, log, cons, int(other.size))


def landmarks_given_poses(
    log: LandmarkLog,
    poses: ArrayLike,
    pose_covariance: ArrayLike | None = None,
) -> tuple[Array, Array, NDArray[np.int64]]:
    """Least-squares landmarks with the poses held fixed, and their joint covariance.

    With the poses fixed the observation residual ``R_kᵀ (l − t_k) − z`` is linear in ``l``,
    so each landmark is the information-weighted mean of its sightings ``t_k + R_k z``:
    ``l̂ = A⁻¹ Σ R_k W R_kᵀ (t_k + R_k z)`` with ``A = Σ R_k W R_kᵀ``.

    Parameters
    ----------
    log : LandmarkLog
    poses : array_like, shape (N, 3)
        The fixed poses (e.g. a pose-only solution).
    pose_covariance : array_like, shape (3N, 3N), optional
        Joint covariance of ``poses``. When given it is propagated into the landmarks
        (``Σ_L = A⁻¹ + G Σ_x Gᵀ`` with ``G = ∂l̂/∂x``), which NEES3 needs; otherwise the
        covariance is conditional on the poses (``A⁻¹``, block-diagonal).

    Returns
    -------
    landmarks : ndarray, shape (L, 2)
    covariance : ndarray, shape (2L, 2L)
    ids : ndarray of int, shape (L,)
    """
    x = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    n = x.shape[0]
    z, info = cartesian_observations(log)
    ids, li = np.unique(log.landmark, return_inverse=True)
    nl = ids.size
    rk = _rot(x[log.pose, 2])
    w_world = rk @ info @ np.swapaxes(rk, 1, 2)  # R W Rᵀ
    world = x[log.pose, :2] + np.einsum("kab,kb->ka", rk, z)
    a = np.zeros((nl, 2, 2))
    np.add.at(a, li, w_world)
    b = np.zeros((nl, 2))
    np.add.at(b, li, np.einsum("kab,kb->ka", w_world, world))
    a_inv = np.linalg.inv(a)
    lm = np.einsum("lab,lb->la", a_inv, b)
    cov = np.zeros((2 * nl, 2 * nl))
    idx = 2 * np.arange(nl)[:, None] + np.arange(2)
    cov[idx[:, :, None], idx[:, None, :]] = a_inv
    if pose_covariance is not None:
        px = np.asarray(pose_covariance, dtype=np.float64)
        if px.shape != (3 * n, 3 * n):
            raise InputError(f"pose covariance must have shape {(3 * n, 3 * n)}, got {px.shape}")
        # exact ∂l̂/∂x_k of l̂ = A⁻¹ Σ M_k w_k (M_k = R_k W R_kᵀ, w_k = t_k + R_k z):
        # ∂/∂t_k = A⁻¹ M_k;  ∂/∂θ_k = A⁻¹ ((S M_k − M_k S)(w_k − l̂) + M_k S R_k z), S = ∂R/∂θ R⁻¹
        sk = np.array([[0.0, -1.0], [1.0, 0.0]])
        dm = sk @ w_world - w_world @ sk
        dth = np.einsum("kab,kb->ka", dm, world - lm[li]) + np.einsum(
            "kab,kb->ka", w_world, np.einsum("ab,kb->ka", sk, world - x[log.pose, :2])
        )
        blocks = np.concatenate((w_world, dth[:, :, None]), axis=2)
        blocks = a_inv[li] @ blocks  # (K, 2, 3)
        g = np.zeros((2 * nl, 3 * n))
        rows = (2 * li)[:, None, None] + np.arange(2)[None, :, None]
        cols = (3 * log.pose)[:, None, None] + np.arange(3)[None, None, :]
        np.add.at(g, (np.broadcast_to(rows, blocks.shape), np.broadcast_to(cols, blocks.shape)),
                  blocks)  # fmt: skip
        cov = cov + g @ px @ g.T
        cov = 0.5 * (cov + cov.T)
    return readonly(lm), readonly(cov), ids


@dataclass(frozen=True)
class ChiSquare:
    """A χ² statistic of measurements at an estimate and its degrees of freedom.

    Attributes
    ----------
    value : float
        ``Σ eᵀ Ω e`` over the measurements.
    dof : int
        Measurement dimensions minus estimated dimensions (its expected value for a
        consistent least-squares estimate).
    measurements : int
        Measurement dimensions.
    """

    value: float
    dof: int
    measurements: int


def relative_pose_chi2(graph: PoseGraph, poses: ArrayLike) -> ChiSquare:
    """Hu et al.'s NEES2: the χ² of a pose graph's relative-pose constraints at ``poses``,
    ``Σ_c e_cᵀ Ω_c e_c`` with ``e_c = [R_iᵀ (t_j − t_i) − δ_t, wrap(θ_j − θ_i − δ_θ)]``.
    No ground truth. Degrees of freedom ``3 E − 3 (N − 1)`` (pose 0 fixed).

    For pose-only SLAM the graph is the one solved (pair constraints and odometry); for full
    least squares, whose only relative-pose constraints are the odometry steps, the
    odometry graph."""
    x = np.asarray(poses, dtype=np.float64)
    e = se2.between(x[graph.pp_i], x[graph.pp_j]) - graph.pp_z
    e[:, 2] = se2.wrap_angle(e[:, 2])
    value = float(np.einsum("ea,eab,eb->", e, graph.pp_info, e))
    m = 3 * int(graph.pp_i.size)
    return ChiSquare(value, m - 3 * (graph.n_poses - 1), m)


def odometry_graph(log: LandmarkLog) -> PoseGraph:
    """The log's odometry steps as a pose graph (full least squares' relative-pose
    constraints, for :func:`relative_pose_chi2`)."""
    i, u, info = _odometry_factors(log)
    return PoseGraph(log.odometry.poses, np.empty((0, 2)), i, i + 1, u, info)


def data_chi2(log: LandmarkLog, poses: ArrayLike) -> ChiSquare:
    """Hu et al.'s NEES3: the χ² of *all* the original measurements — every odometry step
    and every landmark observation — with the poses fixed at ``poses`` and the landmarks at
    their least-squares fit to them (:func:`landmarks_given_poses`). No ground truth.

    Degrees of freedom ``3 (N − 1) + 2 K − 3 (N − 1) − 2 L = 2 (K − L)`` (K observations, L
    landmarks; the poses and landmarks estimated): full least squares minimises exactly this
    χ², so its value is its final cost × 2 and ≈ the dof when its noise model is right; any
    other estimate of the poses gives more."""
    x = np.asarray(poses, dtype=np.float64)
    lm, _, ids = landmarks_given_poses(log, x)
    lookup = np.empty(int(ids.max()) + 1 if ids.size else 0, dtype=np.int64)
    lookup[ids] = np.arange(ids.size)
    z, info = cartesian_observations(log)
    k = log.pose
    pred = se2.inverse_transform_points(x[k], lm[lookup[log.landmark]])
    e_o = pred - z
    odo = relative_pose_chi2(odometry_graph(log), x)
    value = odo.value + float(np.einsum("ka,kab,kb->", e_o, info, e_o))
    m = odo.measurements + 2 * int(k.size)
    return ChiSquare(value, m - 3 * (x.shape[0] - 1) - 2 * int(ids.size), m)


def nees3(
    log: LandmarkLog,
    result: PoseOnlyResult,
    true_landmarks: ArrayLike,
    *,
    probability: float = 0.95,
) -> JointNees:
    """NEES3 of Hu et al.: the map fitted to the pose-only trajectory, poses held fixed.

    The landmarks are :func:`landmarks_given_poses` of the pose-only solution with its joint
    pose covariance propagated; the test is :func:`relation_metric.consistency.nees2`.

    Parameters
    ----------
    log : LandmarkLog
    result : PoseOnlyResult
    true_landmarks : array_like, shape (M, 2)
        True positions indexed by landmark id (ids in ``log.landmark`` index its rows).
    """
    px = joint_covariance(result.graph, result.solution)
    lm, cov, ids = landmarks_given_poses(log, result.solution.poses, px)
    truth = np.asarray(true_landmarks, dtype=np.float64).reshape(-1, 2)
    if ids.size and (ids.min() < 0 or ids.max() >= truth.shape[0]):
        raise InputError(f"landmark ids must index the {truth.shape[0]} true landmarks")
    return nees2(lm, truth[ids], cov, probability=probability)
