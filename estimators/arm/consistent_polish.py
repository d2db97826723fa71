"""The polish of the physically consistent colonies: a deterministic trust-region Newton descent in factor coordinates.

After the colony (:mod:`estimators.arm.improved_abc` with ``consistent=True, polish=True``), :func:`polished_consistent`
descends from the colony's best point over every physically consistent parameter set to the global consistent optimum
that the convex ``sdp`` estimator (:mod:`estimators.arm.sdp`) computes.

Cost and coordinates
--------------------
The cost is ``|A (K x(y) - theta_ls)|^2`` (the root form of
:meth:`~estimators.arm.linear_problem.LinearIdentificationProblem.root_form`, divided by the unconstrained least-squares
minimum ``c_ls``: relative units) in the factor coordinates ``y`` of
:meth:`~estimators.arm.consistency.PhysicalConsistency.factor_from_search` (``J_hat = Y Y^T`` per link, friction
``scale w^2``). Every local minimum there is the global minimum over the consistent parameters, and the boundary (a
thin body, zero friction) lies at finite ``y``. Gradient ``2 G^T r``, Hessian ``2 (G^T G + sum_c (K^T A^T r)_c d^2 x_c /
dy^2)`` with ``G = A K dx/dy`` (:meth:`~estimators.arm.consistency.PhysicalConsistency.factor_jacobian`,
``factor_curvature``): the second term, the curvature of the map times the residual, is what Gauss-Newton leaves out
and why it crawls where the constraints hold the optimum away from the unconstrained one.

Trust-region steps (Nocedal and Wright 2006, algorithm 4.1 and section 4.3)
---------------------------------------------------------------------------
Each step minimises the quadratic model within the radius exactly, from the eigen-decomposition of the Hessian
(``D`` ~ 100 coordinates: one symmetric eigen-decomposition per step): the Newton step when the Hessian is positive
definite and the step fits; otherwise the step on the boundary ``p(s) = -(H + s I)^-1 g`` with the shift ``s`` found by
Brent's method on ``|p(s)| = radius``; in the "hard case" (the gradient has no component along the lowest eigenvector)
the shifted step plus the lowest eigenvector, with a positive coefficient. Negative curvature is followed, so the
descent leaves the saddles where a factor coordinate is exactly zero (a friction coefficient on its bound: zero
gradient and no coupling to the other coordinates); friction roots still start at least ``POLISH_ROOT_FLOOR``.

Why not ``scipy.optimize.minimize(method="trust-krylov")`` (used before): its subproblem solver, trlib, starts the
inverse iteration of its hard case from a random vector seeded with the wall clock (``srand(time(NULL))`` in
``trlib_eigen_inverse.c``), so the same fit ended at different points depending on the second it ran (measured on the
real UR5 fold of ``Movement_No8``: same seed, same process, different bits; with ``time()`` held constant through
``LD_PRELOAD``, 14 211 logged evaluations identical in four fits and across processes). ``trust-exact`` is
deterministic but took 4-14 s per polish (500 steps) against 0.2-3 s.

Stopping rule: the descent stops (``polish_converged``) when no step within the trust region is predicted to lower the
cost by more than the rounding error of the cost itself, ``ROUNDING_FACTOR`` times the first-order bound
``eps (2 |r| . (|A K| |x| + |A theta_ls|) + m |r|^2) / c_ls`` of its evaluation at the current point (``m`` rows of
``A``): a decrease below it cannot be told from rounding, so the end point does not depend on which rounding noise
the later steps would follow. ``POLISH_ITERATIONS`` caps the steps.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import brentq
from threadpoolctl import threadpool_limits

from estimators.arm.consistency import PhysicalConsistency
from estimators.arm.linear_problem import LinearIdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: the most trust-region Newton steps of the polish
POLISH_ITERATIONS = 500
#: friction roots of the polish's start are at least this (coefficient ``scale w^2`` >= 0.0025 of its search bound)
POLISH_ROOT_FLOOR = 0.05
#: the stopping floor in units of the first-order rounding bound of the cost's evaluation (module docstring)
ROUNDING_FACTOR = 1.0
#: trust region: first and largest radius (factor coordinates), acceptance threshold of the actual/predicted decrease
INITIAL_RADIUS = 1.0
MAX_RADIUS = 1000.0
ACCEPT_RATIO = 0.15


def trust_region_step(eigenvalues: FloatArray, vectors: FloatArray, gradient: FloatArray, radius: float) -> FloatArray:
    """The minimiser (D,) of ``g . p + p . H p / 2`` over ``|p| <= radius``, ``H = V diag(eigenvalues) V^T`` (eigenvalues
    ascending, as :func:`numpy.linalg.eigh` gives them), ``g`` = ``gradient`` (D,) (module docstring)."""
    along = vectors.T @ gradient
    lowest = float(eigenvalues[0])
    if lowest > 0.0:
        newton = -along / eigenvalues
        if np.linalg.norm(newton) <= radius:
            return vectors @ newton
    tiny = np.finfo(float).eps * max(1.0, float(np.abs(eigenvalues).max()))
    low = max(0.0, -lowest) + tiny

    def excess_length(shift: float) -> float:
        return float(np.linalg.norm(along / (eigenvalues + shift))) - radius

    if excess_length(low) > 0.0:
        high = low + float(np.linalg.norm(gradient)) / radius + tiny  # |p(high)| <= |g| / (high - low + tiny) <= radius
        shift = brentq(excess_length, low, high, xtol=tiny, rtol=4 * np.finfo(float).eps)
        return vectors @ (-along / (eigenvalues + shift))
    # hard case: the gradient (nearly) misses the lowest eigenvector; shifted step plus that eigenvector to the boundary
    shifted = eigenvalues - lowest
    partial = np.where(shifted > tiny, -along / np.where(shifted > tiny, shifted, 1.0), 0.0)
    tail = np.sqrt(max(radius**2 - float(partial @ partial), 0.0))
    return vectors @ partial + tail * vectors[:, 0]


def trust_region_newton(
    cost: Callable[[FloatArray], float],
    gradient: Callable[[FloatArray], FloatArray],
    hessian: Callable[[FloatArray], FloatArray],
    rounding: Callable[[FloatArray], float],
    start: FloatArray,
    max_iterations: int,
) -> tuple[FloatArray, dict[str, Any]]:
    """Minimise ``cost`` from ``start`` (D,) by exact trust-region Newton steps (module docstring); ``rounding(y)`` the
    rounding error of ``cost(y)``. Returns the end point and its facts (``polish_iterations``, ``polish_converged``)."""
    y = np.array(start, dtype=float)
    value = cost(y)
    radius = INITIAL_RADIUS
    converged = False
    iterations = 0
    g, eigenvalues, vectors = gradient(y), *np.linalg.eigh(hessian(y))
    while iterations < max_iterations:
        step = trust_region_step(eigenvalues, vectors, g, radius)
        along = vectors.T @ step
        predicted = -float(g @ step + 0.5 * along @ (eigenvalues * along))
        if predicted <= ROUNDING_FACTOR * rounding(y):
            converged = True
            break
        iterations += 1
        trial = y + step
        trial_value = cost(trial)
        ratio = (value - trial_value) / predicted if np.isfinite(trial_value) else -np.inf
        length = float(np.linalg.norm(step))
        if ratio < 0.25:
            radius = 0.25 * length
        elif ratio > 0.75 and length >= 0.99 * radius:
            radius = min(2.0 * radius, MAX_RADIUS)
        if ratio > ACCEPT_RATIO:
            y, value = trial, trial_value
            g, eigenvalues, vectors = gradient(y), *np.linalg.eigh(hessian(y))
    return y, {"polish_iterations": iterations, "polish_converged": converged}


def polished_consistent(problem: Any, consistency: PhysicalConsistency, start: FloatArray) -> tuple[FloatArray, dict[str, Any]]:
    """Consistent full parameters (n_full,) after the trust-region Newton descent (module docstring) from the search
    point ``start`` (n_full,), and its facts; each cost counts one evaluation, each gradient D."""
    if not isinstance(problem, LinearIdentificationProblem):
        raise SpaceIdInputError(
            "polish=True: needs a linear problem (LinearIdentificationProblem); use 'hybrid' for nonlinear ones"
        )
    matrix, minimiser = problem.root_form()
    data = matrix if consistency.base_map is None else matrix @ consistency.base_map
    target = matrix @ minimiser
    abs_data, abs_target = np.abs(data), np.abs(target)
    scale = max(float(problem.cost(minimiser, count=False)[0]), 1e-300)
    eps = float(np.finfo(float).eps)

    def residual(y: FloatArray) -> FloatArray:
        return data @ consistency.full_from_factor(y) - target

    def cost(y: FloatArray) -> float:
        problem.n_model_samples += problem.n_samples
        r = residual(y)
        return float(r @ r) / scale

    def gradient(y: FloatArray) -> FloatArray:
        problem.n_model_samples += len(y) * problem.n_samples
        return 2.0 * (data @ consistency.factor_jacobian(y)).T @ residual(y) / scale

    def hessian(y: FloatArray) -> FloatArray:
        jacobian = data @ consistency.factor_jacobian(y)
        return 2.0 * (jacobian.T @ jacobian + consistency.factor_curvature(data.T @ residual(y))) / scale

    def rounding(y: FloatArray) -> float:
        full = consistency.full_from_factor(y)
        r = np.abs(data @ full - target)
        return eps * (2.0 * float(r @ (abs_data @ np.abs(full) + abs_target)) + len(r) * float(r @ r)) / scale

    # ~100-dimensional algebra: BLAS threads only contend on a busy machine; a wild trial step may overflow (rejected)
    with threadpool_limits(limits=1), np.errstate(over="ignore", invalid="ignore"):
        start_factor = consistency.factor_from_search(start, root_floor=POLISH_ROOT_FLOOR)
        end, facts = trust_region_newton(cost, gradient, hessian, rounding, start_factor, POLISH_ITERATIONS)
    return consistency.full_from_factor(end), facts
