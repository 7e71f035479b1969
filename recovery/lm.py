"""One Levenberg–Marquardt for the estimation layer.

Every least squares of the package runs through :func:`levenberg_marquardt`: full SLAM and
pose-only least squares (:func:`slamrel.backends.least_squares.solve_graph`,
:func:`~slamrel.backends.least_squares.solve_graph_incremental`) and batch trajectory recovery
(:func:`recovery.batch_refinement.refine`). What differs between them is the *problem*: how
residuals and the Gauss–Newton matrix are computed and stored (a fixed sparse pattern, a
band) and how the damped normal equations are solved (sparse LU in a fill-reducing order,
banded Cholesky). The loop — damping, acceptance, stopping — is this one.

The problem is to minimise ``c(x) = ½ Σ rᵀ W r`` over a state ``x`` (poses ``[x, y, θ]`` and
Euclidean variables such as landmarks). One iteration at ``x``:

1. *linearise*: the cost ``c``, the gradient ``g = Jᵀ W r`` (n,), the Gauss–Newton matrix
   ``H = Jᵀ W J`` in the problem's own storage, and ``diag(H)`` (n,);
2. *damped step*: solve ``(H + λ D) δ = −g`` with ``D = diag(max(diag H, 1e-12))``
   (Marquardt's scaling: the damping is invariant to the units of each variable);
3. *trial*: ``x' = x ⊞ δ`` (:meth:`Problem.retract`; for poses :func:`retract_poses`: add,
   then wrap θ into ``[−π, π)`` with :func:`relation_metric.se2.wrap_angle`), evaluating the
   cost only (no Jacobian);
4. *accept* when ``c(x') < c(x)``: ``λ ← max(λ / ν, λ_min)`` and linearise at ``x'``;
   otherwise *reject*: ``λ ← ν λ`` and back to 2.

Damping rule: Marquardt's multiplicative update with ``ν = 10`` (``λ`` falls on an accepted
step, rises on a rejected one), the rule both earlier loops used, so their results stay the
same. Nielsen's gain-ratio rule (``λ ← λ max(⅓, 1 − (2ρ − 1)³)``, ``ρ`` the actual over the
predicted decrease; ``ν`` doubling on rejections) was tried on batch recovery and took more
steps to the same minimum (here the steps are nearly Gauss–Newton, ``λ`` ends at ``λ_min``,
and Nielsen's rule lowers it more slowly; measured when batch recovery started at
``λ = 1e-6``, before it started nearly undamped, see :mod:`recovery.batch_refinement`; the
iteration counts are in benchmarks/README.md).

Stopping rules, checked in this order after each iteration:

* *no decrease*: ``max_tries`` damped steps in a row (or ``λ > lambda_max``) fail to lower
  the cost — the state is a minimum to working precision (``converged``);
* the caller's ``stop(c, c')`` returns True after an accepted step (``stopped``; e.g. the
  stall check of :func:`~slamrel.backends.least_squares.solve_graph_incremental`);
* *relative decrease* ``(c − c') / c < ftol``, *absolute decrease* ``c − c' < atol`` or
  *step* ``max |δ| < xtol`` (``converged``);
* ``max_iterations`` (not converged).

The state the loop ends at is not linearised again (nothing would read that linearisation):
the last entry of ``costs`` is the accepted trial's :meth:`Problem.cost`.

A non-finite step (singular normal equations) or cost raises
:class:`~relation_metric.errors.DivergenceError`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, NamedTuple, Protocol, TypeVar

import numpy as np

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError

__all__ = [
    "Linearisation",
    "Problem",
    "LMOptions",
    "LMResult",
    "levenberg_marquardt",
    "retract_poses",
]

State = TypeVar("State")

_DIAG_FLOOR = 1e-12  # floor on diag(H) in the damping (a variable with no information)


class Linearisation(NamedTuple):
    """A problem linearised at one state.

    Attributes
    ----------
    cost : float
        ``½ Σ rᵀ W r`` at the state.
    gradient : ndarray, shape (n,)
        ``Jᵀ W r``, in the problem's variable order.
    diagonal : ndarray, shape (n,)
        ``diag(Jᵀ W J)``, same order.
    system : object
        ``Jᵀ W J`` in the problem's own storage (passed back to :meth:`Problem.solve`).
    """

    cost: float
    gradient: Array
    diagonal: Array
    system: Any


class Problem(Protocol[State]):
    """What :func:`levenberg_marquardt` needs of a least-squares problem."""

    def linearise(self, x: State) -> Linearisation:
        """Cost, gradient, Gauss–Newton matrix and its diagonal at ``x``."""
        ...

    def cost(self, x: State) -> float:
        """``½ Σ rᵀ W r`` at ``x`` (residuals only)."""
        ...

    def solve(self, lin: Linearisation, damping: Array) -> Array:
        """``δ = −(H + diag(damping))⁻¹ g``, shape (n,), in the order of :meth:`retract`."""
        ...

    def retract(self, x: State, delta: Array) -> State:
        """``x ⊞ δ``."""
        ...


@dataclass(frozen=True)
class LMOptions:
    """Damping and stopping parameters of :func:`levenberg_marquardt` (see module doc).

    Attributes
    ----------
    lambda_initial : float
        First ``λ``.
    lambda_min, lambda_max : float
        ``λ`` is not lowered below ``lambda_min``; a rejected step that raises it above
        ``lambda_max`` ends the search (no decrease).
    factor : float
        ``ν``: ``λ`` is divided by it on an accepted step, multiplied on a rejected one.
    max_tries : int
        Damped steps per iteration before giving up (no decrease).
    max_iterations : int
    ftol : float
        Stop when the relative cost decrease of an accepted step is below it.
    xtol : float
        Stop when the largest component of an accepted step is below it (0: never).
    atol : float
        Stop when an accepted step lowers the cost by less than this, in the cost's own units
        (0: never; GTSAM's ``absoluteErrorTol``): a cost already at the level of rounding,
        where the relative decrease ``ftol`` compares noise with noise, has converged.
    """

    lambda_initial: float = 1e-4
    lambda_min: float = 1e-12
    lambda_max: float = float("inf")
    factor: float = 10.0
    max_tries: int = 20
    max_iterations: int = 100
    ftol: float = 1e-9
    xtol: float = 0.0
    atol: float = 0.0


@dataclass(frozen=True)
class LMResult(Generic[State]):
    """Result of :func:`levenberg_marquardt`.

    Attributes
    ----------
    x : State
        The last accepted state.
    costs : ndarray, shape (accepted steps + 1,)
        The cost at the start and after each accepted step.
    iterations : int
        Iterations run (the last one may have found no decrease).
    converged : bool
        Stopped by no decrease, ``ftol`` or ``xtol``.
    stopped : bool
        Stopped by the caller's ``stop``.
    """

    x: State
    costs: Array
    iterations: int
    converged: bool
    stopped: bool


def levenberg_marquardt(
    problem: Problem[State],
    x0: State,
    options: LMOptions = LMOptions(),
    *,
    stop: Callable[[float, float], bool] | None = None,
) -> LMResult[State]:
    """Minimise ``problem``'s cost from ``x0`` (damping and stopping rules: module doc).

    Parameters
    ----------
    problem : Problem
    x0 : State
        Initial state (not modified).
    options : LMOptions
    stop : callable ``(cost, new_cost) -> bool``, optional
        Called after each accepted step; True ends the iterations (``stopped``).

    Returns
    -------
    LMResult

    Raises
    ------
    DivergenceError
        A non-finite step (singular normal equations) or a non-finite cost.
    """
    x = x0
    lin = problem.linearise(x)
    cost = lin.cost
    costs = [cost]
    lam = options.lambda_initial
    converged = stopped = False
    it = 0
    for it in range(1, options.max_iterations + 1):
        damping_scale = np.maximum(lin.diagonal, _DIAG_FLOOR)
        for _ in range(options.max_tries):
            delta = problem.solve(lin, lam * damping_scale)
            if not np.isfinite(delta).all():
                raise DivergenceError("the normal equations are singular (unobserved states?)")
            trial = problem.retract(x, delta)
            new_cost = problem.cost(trial)
            if not np.isfinite(new_cost):
                raise DivergenceError(f"non-finite cost at iteration {it}")
            if new_cost < cost:
                break
            lam *= options.factor
            if lam > options.lambda_max:
                break
        if not new_cost < cost:
            converged = True  # no descent possible: at a minimum to working precision
            break
        rel = (cost - new_cost) / max(cost, 1e-300)
        stopped = stop is not None and stop(cost, new_cost)
        converged = (
            rel < options.ftol
            or cost - new_cost < options.atol
            or float(np.abs(delta).max(initial=0.0)) < options.xtol
        )
        x = trial
        if stopped or converged or it == options.max_iterations:
            # the last state is not linearised (nothing reads it): its cost is the trial's
            costs.append(new_cost)
            break
        lin = problem.linearise(x)
        cost = lin.cost
        costs.append(cost)
        lam = max(lam / options.factor, options.lambda_min)
    return LMResult(x, np.asarray(costs), it, converged and not stopped, stopped)


def retract_poses(poses: Array, delta: Array) -> Array:
    """``x ⊞ δ`` for planar poses in coordinates: ``x + δ`` with θ wrapped.

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
    delta : ndarray, shape (3N,)
        Pose-major ``[δx_0, δy_0, δθ_0, δx_1, …]``.

    Returns
    -------
    ndarray, shape (N, 3)
        A new array; ``θ`` in ``[−π, π)`` (:func:`relation_metric.se2.wrap_angle`).
    """
    out = poses + delta.reshape(poses.shape)
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out
