"""Least squares for linear identification problems: ordinary (``ols``) and weighted (``wls``).

Both solve ``tau = Y theta`` exactly (no search, no bounds) on a
:class:`~estimators.arm.linear_problem.LinearIdentificationProblem` and are the standard the metaheuristics
are measured against.

* :class:`OrdinaryLeastSquares` minimises ``sum_i (Y_i theta - tau_i)^2`` with
  :func:`numpy.linalg.lstsq` (SVD; the minimum-norm solution when ``Y`` is rank deficient, e.g. full
  rather than base parameters).
* :class:`WeightedLeastSquares` is Gautier's standard two-step weighted least squares (Gautier and
  Poignet 2001): an OLS fit, the noise variance of each row group (joint) from its OLS residuals,
  ``s_g^2 = RSS_g / (N_g - k N_g / N)``, then the OLS of the rows divided by their group's std. With the
  problem's ``row_std`` given, those weights are used directly (one step). ``n_iterations > 1`` re-estimates
  the variances from the previous weighted fit.

Cost and bound: a fit counts one whole-objective evaluation (the final residual); the estimate's
Cramér-Rao std is ``sqrt(diag((Y^T W Y)^-1))`` with ``W = diag(1 / s^2)`` from the final residual per group
(or ``row_std``), which for WLS is the covariance of the estimate itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.base import Estimator, SearchResult
from estimators.options import check_int
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


def _linear(problem: Any, name: str) -> LinearIdentificationProblem:
    """``problem`` if it is linear in its parameters, else :class:`SpaceIdInputError` (least squares needs ``Y``)."""
    if not isinstance(problem, LinearIdentificationProblem):
        raise SpaceIdInputError(
            f"estimator {name!r}: needs a linear problem (LinearIdentificationProblem, tau = Y theta), got "
            f"{type(problem).__name__}; for the nonlinear free-floating problem use 'lm'"
        )
    return problem


def weighted_lstsq(problem: LinearIdentificationProblem, row_std: FloatArray | None) -> tuple[FloatArray, dict[str, Any]]:
    """Least-squares ``theta`` (k,) of the rows divided by ``row_std`` (N,) (``None``: unweighted), and solver facts.

    The facts: numerical ``rank`` of the (weighted) regressor and its ``condition_number`` (inf if rank deficient).
    """
    scale = np.ones(problem.n_samples) if row_std is None else 1.0 / np.asarray(row_std, dtype=float)
    theta, _, rank, singular = np.linalg.lstsq(problem.Y * scale[:, None], problem.tau * scale, rcond=None)
    condition = float(singular[0] / singular[-1]) if rank == problem.n_params and singular[-1] > 0.0 else float("inf")
    return theta, {"rank": int(rank), "condition_number": condition}


def group_weighted(problem: LinearIdentificationProblem) -> LinearIdentificationProblem:
    """``problem`` with each row weighted by its group's noise std from an OLS fit (Gautier's two-step weights, the
    ones :class:`WeightedLeastSquares` uses): ``s_g^2 = RSS_g / (N_g - k N_g / N)``."""
    theta, _ = weighted_lstsq(problem, None)
    return problem.with_row_std(problem.group_noise_std(theta)[problem.row_group])


class OrdinaryLeastSquares(Estimator):
    """Ordinary least squares (module docstring); no options besides the (unused) seed."""

    name = "ols"

    def min_samples(self, problem: Any) -> int:
        """At least as many rows as unknowns."""
        return problem.n_params

    def _search(self, problem: LinearIdentificationProblem, rng: np.random.Generator) -> SearchResult:
        problem = _linear(problem, self.name)
        theta, facts = weighted_lstsq(problem, None)
        cost = float(problem.cost(theta)[0])
        return SearchResult(theta=theta, cost_history=[cost], extra=facts)


class WeightedLeastSquares(Estimator):
    """Two-step weighted least squares with per-group noise variances (module docstring).

    Args:
        n_iterations: re-weighting steps after the OLS fit (default 1, Gautier's two-step).
        seed: unused (the fit is deterministic), kept for the protocol.
    """

    name = "wls"

    def __init__(self, *, n_iterations: int = 1, seed: int | None = 0) -> None:
        super().__init__(seed=seed)
        self.n_iterations = check_int("n_iterations", n_iterations, 1)

    def min_samples(self, problem: Any) -> int:
        """Enough rows for a noise estimate in every group: more rows than unknowns."""
        return problem.n_params + 1

    def _search(self, problem: LinearIdentificationProblem, rng: np.random.Generator) -> SearchResult:
        problem = _linear(problem, self.name)
        if problem.row_std is not None:
            theta, facts = weighted_lstsq(problem, problem.row_std)
            group_std = None
        else:
            theta, facts = weighted_lstsq(problem, None)
            for _ in range(self.n_iterations):
                group_std = problem.group_noise_std(theta)
                theta, facts = weighted_lstsq(problem, group_std[problem.row_group])
        cost = float(problem.cost(theta)[0])
        if group_std is not None:
            facts["group_noise_std_used"] = group_std.tolist()
        return SearchResult(theta=theta, cost_history=[cost], extra=facts)
