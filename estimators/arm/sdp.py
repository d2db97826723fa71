"""Physically consistent weighted least squares as a semidefinite program: the ``sdp`` estimator.

The convex reference of every physically consistent estimator: on a
:class:`~estimators.arm.linear_problem.LinearIdentificationProblem` with a
:class:`~estimators.arm.consistency.PhysicalConsistency` (which columns of the full parameters ``x`` are links,
friction/armature and free coefficients; ``theta = K x``) it finds the global minimum of the problem's weighted
least-squares cost over the physically consistent full parameters.

Program
-------
Over the full parameters ``x`` (n_full,)::

    minimise    cost(K x) + lambda |N^T D^-1 (x - x_prior)|^2
    subject to  J_l(x) >= 0            each link's 4x4 pseudo-inertia positive semidefinite,
                x_c >= 0               every friction and armature coefficient (``friction_columns``),

free columns (a torque offset) unconstrained. ``J_l = [[tr(I)/2 E - I, h], [h^T, m]]`` of the link's params10 (mass
kg, first moment ``h = m c`` kg m, inertia ``I`` about the link frame's origin in its axes, kg m^2): the linear
matrix inequality of Wensing, Kim and Slotine (2017), which holds exactly for the parameters of a mass distribution
of non-negative density (it is the mass's second-moment matrix ``integral [r; 1][r; 1]^T dm``). The set is a convex
cone, the cost convex quadratic, so the optimum is global; the program is solved by cvxpy with the interior-point
solver Clarabel (deterministic: the same problem gives the same estimate).

* **Cost**: the problem's cost, ``cost(theta) = c_ls + |A (theta - theta_ls)|^2`` in the root form of
  :meth:`~estimators.arm.linear_problem.LinearIdentificationProblem.root_form` (``c_ls`` the unconstrained least-squares
  minimum): the same weighted mean squared residual the metaheuristics minimise. Weights: the problem's ``row_std``
  when it has one; otherwise, like :class:`~estimators.arm.linear_ls.WeightedLeastSquares`, Gautier's two-step weights
  (each group's noise std from an OLS fit). Without constraints the program is WLS; when WLS is consistent, its
  estimate is the optimum.
* **Regulariser** (documented weight): base parameters leave ``n_full - rank`` directions of ``x`` that change no
  prediction (link 1's mass on a vertical joint, masses regrouped into first moments). Without a term there the
  optimum is a set, unbounded along some of them. The regulariser acts **only** on those directions: ``N`` is an
  orthonormal basis of the null space of ``A K D`` (singular values below ``NULL_RTOL`` of the largest), ``D`` the
  diagonal of :meth:`~estimators.arm.consistency.PhysicalConsistency.parameter_scale` (kg, kg m, kg m^2, friction
  bounds), ``x_prior`` :meth:`~estimators.arm.consistency.PhysicalConsistency.prior_full` (the URDF's values for the
  arm model). Its weight is ``lambda = regularisation x u`` with ``u = c_ls / (N - rank)`` one chi-square unit of the
  cost (the cost change of one unit of ``sum r^2 / s^2`` when the residuals are the noise): with the default
  ``regularisation = 1e-3`` a null-space move of one prior scale is worth 1e-3 chi-square units. ``N`` leaves every
  prediction unchanged, so the regulariser only picks, among the consistent parameters with the same predictions,
  the ones nearest the prior; it moves the predictions only where the constraints tie a null-space direction to an
  informed one. Then the cost can rise, by less than ``lambda`` times the regulariser's drop. Measured against the
  unregularised program: 0.01 chi-square units on the simulated UR5 (a relative 3e-6 of the cost), 0.004-0.05 on the
  real UR5 logs (2e-7-3e-6), 0.13 on the synthetic arm of :mod:`estimators.arm.synthetic`, whose prior is a
  placeholder (5e-5); what the data gain for it without the regulariser are link masses the torques do not see
  running off to 10^2-10^4 kg. Reported: ``regulariser_cost`` (its value at the estimate). On noise-free data
  (``c_ls`` ~ 0) ``u`` is floored at ``U_FLOOR`` of the largest curvature, to keep the objective finite.
* **Scaling**: the objective is solved in chi-square units (divided by ``u``), so the solver's tolerances are
  fractions of the noise's chi-square whatever the cost's unit; each link's pseudo-inertia is the variable ``J_hat``
  with ``J = T J_hat T``, ``T = sqrt(m) diag(s, s, s, 1)``
  (:meth:`~estimators.arm.consistency.PhysicalConsistency.link_congruence`): a congruence, so ``J_hat >= 0`` exactly when
  ``J >= 0``, with entries of order one.
* **Solver**: Clarabel (gap and feasibility tolerances ``CLARABEL_TOLERANCE``); if it fails (an error or a status
  other than optimal / optimal_inaccurate) the program is solved again by SCS, and the estimate says so
  (``extra["solver"]``, ``extra["fallback_reason"]``; ``extra["solver_status"]`` the final status). After the solve
  each ``J_hat`` is projected onto the PSD cone (eigenvalues below zero set to zero) and friction clipped at zero, so
  the estimate is consistent exactly, not only to the solver's tolerance; the largest correction is reported
  (``projection_correction``, relative to ``J_hat``'s largest eigenvalue), and each link's smallest eigenvalue of
  ``J_hat`` (``min_scaled_pseudo_inertia_eigenvalue``: zero for a link on the boundary, a body without volume).

Reference: P. M. Wensing, S. Kim, J.-J. E. Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification: a statistical perspective on the mass distribution", IEEE RA-L 3(1), 2017.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimators.arm.consistency import PhysicalConsistency, pseudo_inertia
from estimators.arm.linear_ls import _linear, group_weighted
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.base import Estimator, SearchResult
from estimators.options import check_float
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

try:  # an optional dependency until it is in every lock: the registry must load without it
    import cvxpy as cp
except ImportError:  # pragma: no cover - exercised only where cvxpy is missing
    cp = None

#: singular values of ``A K D`` below this fraction of the largest span the unidentified directions
NULL_RTOL = 1e-8
#: floor of the chi-square unit ``u``, as a fraction of the largest curvature of the cost (noise-free data)
U_FLOOR = 1e-10
#: default regulariser weight, chi-square units per squared prior scale along unidentified directions
DEFAULT_REGULARISATION = 1e-3
#: Clarabel's duality-gap and feasibility tolerances, on the objective in chi-square units (so 1e-8 of the noise's
#: chi-square; noise-free data: ~1e-13 relative error of the parameters)
CLARABEL_TOLERANCE = 1e-8
#: statuses of cvxpy that count as a solution
_SOLVED = ("optimal", "optimal_inaccurate")


@dataclass
class ConsistentOptimum:
    """The solution of the program (module docstring) on one problem.

    Attributes:
        theta: (k,) the problem's parameters ``K x``; full: (n_full,) the consistent full parameters ``x``.
        cost: the problem's cost at ``theta`` (its weighted mean squared residual, e.g. (N m)^2).
        unconstrained_cost: ``c_ls``, the least-squares minimum without the constraints (<= ``cost``).
        facts: solver, status, regulariser and projection figures for the estimate's ``extra`` (JSON-ready).
    """

    theta: FloatArray
    full: FloatArray
    cost: float
    unconstrained_cost: float
    facts: dict[str, Any] = field(default_factory=dict)


def require_cvxpy() -> None:
    """:class:`SpaceIdInputError` if cvxpy is not installed (the ``sdp`` estimator needs it)."""
    if cp is None:
        raise SpaceIdInputError("estimator 'sdp': needs cvxpy>=1.5 with the Clarabel solver (pip install 'cvxpy>=1.5')")


def _consistency(problem: LinearIdentificationProblem) -> PhysicalConsistency:
    consistency = problem.consistency
    if consistency is None:
        raise SpaceIdInputError(
            "estimator 'sdp': the problem has no PhysicalConsistency (pass consistency= to LinearIdentificationProblem)"
        )
    return consistency


def _variable_map(consistency: PhysicalConsistency) -> FloatArray:
    """``X`` (n_full, V): ``x = X v`` for the stacked variables ``v`` = [each link's ``J_hat`` flattened row-major (16
    each), friction, free] (:meth:`~estimators.arm.consistency.PhysicalConsistency.scaled_pseudo_inertia_map`)."""
    n_links, n_friction, n_free = consistency.n_links, len(consistency.friction_columns), len(consistency.free_columns)
    out = np.zeros((consistency.n_full, 16 * n_links + n_friction + n_free))
    for link, (columns, block) in enumerate(zip(consistency.link_columns, consistency.scaled_pseudo_inertia_map(), strict=True)):
        out[columns, 16 * link : 16 * link + 16] = block.reshape(10, 16)
    start = 16 * n_links
    out[consistency.friction_columns, start + np.arange(n_friction)] = 1.0
    out[consistency.free_columns, start + n_friction + np.arange(n_free)] = 1.0
    return out


def _solve(program: Any) -> dict[str, Any]:
    """Solve with Clarabel, falling back to SCS only if Clarabel fails; the facts of what happened."""
    facts: dict[str, Any] = {"solver": "CLARABEL", "fallback_reason": None}
    with warnings.catch_warnings():  # cvxpy warns of an inaccurate solution: the estimate reports the status instead
        warnings.simplefilter("ignore", UserWarning)
        try:
            tolerance = CLARABEL_TOLERANCE
            program.solve(solver=cp.CLARABEL, tol_gap_abs=tolerance, tol_gap_rel=tolerance, tol_feas=tolerance)
            status = str(program.status)
        except cp.error.SolverError as exc:
            status = f"error: {exc}"
        if status not in _SOLVED:
            facts.update(solver="SCS", fallback_reason=f"Clarabel: {status}")
            try:
                program.solve(solver=cp.SCS, eps_abs=1e-9, eps_rel=1e-9, max_iters=200_000)
                status = str(program.status)
            except cp.error.SolverError as exc:
                status = f"error: {exc}"
        if status not in _SOLVED:
            raise RuntimeError(
                f"estimator 'sdp': neither Clarabel ({facts['fallback_reason']}) nor SCS ({status}) solved the program"
            )
    facts["solver_status"] = status
    return facts


def _projected(consistency: PhysicalConsistency, values: FloatArray) -> tuple[FloatArray, float]:
    """The stacked variables (V,) with every ``J_hat`` projected onto the PSD cone and friction clipped at zero, and the
    largest eigenvalue correction relative to its ``J_hat``'s largest eigenvalue."""
    out = np.asarray(values, dtype=float).copy()
    corrections = [0.0]
    for link in range(consistency.n_links):
        block = slice(16 * link, 16 * link + 16)
        j_hat = out[block].reshape(4, 4)
        eigenvalues, vectors = np.linalg.eigh(0.5 * (j_hat + j_hat.T))
        clipped = np.clip(eigenvalues, 0.0, None)
        corrections.append(float((clipped - eigenvalues).max() / max(eigenvalues.max(), np.finfo(float).tiny)))
        out[block] = ((vectors * clipped) @ vectors.T).reshape(-1)
    friction = slice(16 * consistency.n_links, 16 * consistency.n_links + len(consistency.friction_columns))
    out[friction] = np.clip(out[friction], 0.0, None)
    return out, max(corrections)


def consistent_optimum(problem: LinearIdentificationProblem, regularisation: float = DEFAULT_REGULARISATION) -> ConsistentOptimum:
    """The global minimum of ``problem.cost`` (with the problem's own row weights) over physically consistent
    parameters, with the null-space regulariser of the module docstring. Evaluations are not counted."""
    require_cvxpy()
    consistency = _consistency(problem)
    regularisation = check_float("regularisation", regularisation, 0.0, np.inf)
    start = time.perf_counter()
    root, theta_ls = problem.root_form()
    unconstrained = float(problem.cost(theta_ls, count=False)[0])
    base_map = np.eye(consistency.n_full) if consistency.base_map is None else consistency.base_map
    scale = consistency.parameter_scale()
    data = root @ base_map  # cost - c_ls = |data x - root theta_ls|^2
    singular, right = np.linalg.svd(data * scale, full_matrices=True)[1:]
    curvature = float(singular[0] ** 2) if singular.size else 1.0
    rank = int(np.count_nonzero(singular > NULL_RTOL * singular[0])) if singular.size else 0
    null = right[rank:].T  # (n_full, q), orthonormal in the scaled coordinates
    unit = max(unconstrained / max(problem.n_samples - rank, 1), U_FLOOR * curvature)
    weight = regularisation * unit  # cost units per squared prior scale

    mapping = _variable_map(consistency)
    pseudo = [cp.Variable((4, 4), PSD=True) for _ in range(consistency.n_links)]
    friction = cp.Variable(len(consistency.friction_columns), nonneg=True) if len(consistency.friction_columns) else None
    free = cp.Variable(len(consistency.free_columns)) if len(consistency.free_columns) else None
    stacked = cp.hstack([cp.vec(j, order="C") for j in pseudo] + [v for v in (friction, free) if v is not None])
    x = mapping @ stacked
    # objective in chi-square units: the solver's tolerances then bound the error in units of the noise
    objective = cp.sum_squares(data @ x - root @ theta_ls) / unit
    prior = consistency.prior_full()
    if null.shape[1] and weight > 0.0:
        objective += regularisation * cp.sum_squares(null.T @ cp.multiply(1.0 / scale, x - prior))
    facts = _solve(cp.Problem(cp.Minimize(objective)))

    values, correction = _projected(consistency, np.asarray(stacked.value, dtype=float))
    full = mapping @ values
    theta = consistency.theta_from_full(full)
    cost = float(problem.cost(theta, count=False)[0])
    null_move = null.T @ ((full - prior) / scale)
    congruence = consistency.link_congruence()
    facts.update(
        solve_time_s=time.perf_counter() - start,
        regularisation=regularisation,
        regulariser_weight=weight,
        chi_square_unit=unit,
        n_unidentified_directions=int(null.shape[1]),
        regulariser_cost=float(weight * null_move @ null_move),
        unconstrained_cost=unconstrained,
        consistency_cost_increase=cost - unconstrained,
        projection_correction=correction,
        min_scaled_pseudo_inertia_eigenvalue=[
            float(np.linalg.eigvalsh(pseudo_inertia(full[columns]) / np.outer(t, t))[0])
            for t, columns in zip(congruence, consistency.link_columns, strict=True)
        ],
    )
    return ConsistentOptimum(theta, full, cost, unconstrained, facts)


def excess_over_optimum(problem: LinearIdentificationProblem, cost: float) -> dict[str, Any]:
    """How far a consistent estimate's ``cost`` on ``problem`` lies above :func:`consistent_optimum` of the same cost,
    for the estimate's ``extra``: ``sdp_cost``, ``cost_excess_over_sdp`` (``(cost - sdp) / sdp``; slightly negative
    is possible, by the regulariser's trade of the module docstring), ``sdp_solver``, ``sdp_solve_time_s``; without
    cvxpy, or if no solver solves the program, ``None`` and the reason (``sdp_unavailable``)."""
    if cp is None:
        return {"sdp_cost": None, "cost_excess_over_sdp": None, "sdp_unavailable": "cvxpy is not installed"}
    try:
        optimum = consistent_optimum(problem)
    except RuntimeError as exc:  # neither solver solved it: the fit stands, without its reference
        return {"sdp_cost": None, "cost_excess_over_sdp": None, "sdp_unavailable": str(exc)}
    return {
        "sdp_cost": optimum.cost,
        "cost_excess_over_sdp": (cost - optimum.cost) / max(optimum.cost, np.finfo(float).tiny),
        "sdp_solver": optimum.facts["solver"],
        "sdp_solve_time_s": optimum.facts["solve_time_s"],
    }


class SemidefiniteLeastSquares(Estimator):
    """Physically consistent weighted least squares by semidefinite programming (module docstring).

    Args:
        regularisation: weight of the pull toward the prior along unidentified directions, in chi-square units per
            squared prior scale (>= 0, default ``DEFAULT_REGULARISATION``; 0 leaves those directions to the solver).
        seed: unused (the fit is deterministic), kept for the protocol.
    """

    name = "sdp"

    def __init__(self, *, regularisation: float = DEFAULT_REGULARISATION, seed: int | None = 0) -> None:
        super().__init__(seed=seed)
        require_cvxpy()
        self.regularisation = check_float("regularisation", regularisation, 0.0, np.inf)

    def min_samples(self, problem: Any) -> int:
        """Enough rows for a noise estimate in every group: more rows than unknowns."""
        return problem.n_params + 1

    def _search(self, problem: LinearIdentificationProblem, rng: np.random.Generator) -> SearchResult:
        problem = _linear(problem, self.name)
        _consistency(problem)
        weighted = problem if problem.row_std is not None else group_weighted(problem)
        optimum = consistent_optimum(weighted, self.regularisation)
        cost = float(problem.cost(optimum.theta)[0])  # one evaluation, like wls
        extra = {
            **optimum.facts,
            "weights": "given" if weighted is problem else "two-step (per-group noise std of an OLS fit)",
            "weighted_cost": optimum.cost,
            "full_params": optimum.full.tolist(),
        }
        return SearchResult(theta=optimum.theta, cost_history=[cost], extra=extra)
