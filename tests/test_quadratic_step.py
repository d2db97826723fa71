"""The quadratic-approximation step: a second-order model fitted to costs measured on different subsets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import NonlinearConstraint, minimize

from estimators.quadratic_step import POINTS_PER_COEFFICIENT, n_coefficients, quadratic_step, trust_region_minimum


def _subset_quadratics(rng: np.random.Generator, k: int, n_subsets: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A shared positive-definite curvature (k, k), a gradient per subset (K, k) and subset weights (K,)."""
    a = rng.standard_normal((k, k))
    curvature = a @ a.T + 0.5 * np.eye(k)
    gradients = rng.standard_normal((n_subsets, k))
    weights = rng.random(n_subsets) + 0.5
    return curvature, gradients, weights / weights.sum()


def _measured(offsets: np.ndarray, subset: np.ndarray, curvature: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """Excess costs of ``offsets`` (m, k) on their subsets under the exact second-order model."""
    return np.einsum("ij,ij->i", gradients[subset], offsets) + 0.5 * np.einsum("ij,jk,ik->i", offsets, curvature, offsets)


def test_exact_quadratics_on_different_subsets_give_the_whole_log_minimum() -> None:
    rng = np.random.default_rng(0)
    k, n_subsets = 4, 5
    curvature, gradients, weights = _subset_quadratics(rng, k, n_subsets)
    minimum = -np.linalg.solve(curvature, weights @ gradients)  # of sum_s w_s (g_s . d) + 1/2 d' H d
    # points in a thin, tilted cloud around the minimum (as a converged swarm in a valley), in mixed units
    tilt = np.diag([3.0, 1.0, 0.1, 0.01]) @ np.linalg.qr(rng.standard_normal((k, k)))[0]
    offsets = minimum + 2.0 * rng.standard_normal((200, k)) @ tilt
    subset = np.arange(200) % n_subsets
    step = quadratic_step(offsets, subset, _measured(offsets, subset, curvature, gradients), weights)
    assert step is not None
    np.testing.assert_allclose(step, minimum, rtol=1e-8, atol=1e-10)


def test_a_single_shared_gradient_would_mislead_the_subsets_own_gradients_do_not() -> None:
    """Ignoring which subset a cost came from (one gradient for all) lands elsewhere: the subsets differ."""
    rng = np.random.default_rng(1)
    k, n_subsets = 3, 4
    curvature, gradients, weights = _subset_quadratics(rng, k, n_subsets)
    gradients *= 5.0
    minimum = -np.linalg.solve(curvature, weights @ gradients)
    offsets = minimum + rng.standard_normal((120, k))
    subset = rng.integers(0, n_subsets, 120)
    excess = _measured(offsets, subset, curvature, gradients)
    one_gradient = quadratic_step(offsets, np.zeros(120, dtype=np.intp), excess, np.ones(1))
    assert one_gradient is not None
    assert np.linalg.norm(one_gradient - minimum) > 0.1 * np.linalg.norm(minimum)
    np.testing.assert_allclose(quadratic_step(offsets, subset, excess, weights), minimum, rtol=1e-8, atol=1e-10)


def test_the_step_stays_within_the_points_and_leaves_an_unspread_direction_alone() -> None:
    rng = np.random.default_rng(2)
    k = 3
    curvature, gradients, weights = _subset_quadratics(rng, k, 1)
    offsets = 0.01 * rng.standard_normal((60, k))
    offsets[:, 2] = 0.0  # every point on a face of the box: nothing is known across it
    excess = _measured(offsets, np.zeros(60, dtype=np.intp), curvature, 100.0 * gradients)  # minimum far outside the cloud
    step = quadratic_step(offsets, np.zeros(60, dtype=np.intp), excess, weights)
    assert step is not None
    assert step[2] == 0.0
    moment = offsets[:, :2].T @ offsets[:, :2] / 60
    reach = np.max(np.sqrt(np.einsum("ij,jk,ik->i", offsets[:, :2], np.linalg.inv(moment), offsets[:, :2])))
    length = np.sqrt(step[:2] @ np.linalg.solve(moment, step[:2]))
    assert length == pytest.approx(reach, rel=1e-6)  # as far as the farthest fitted point, no further


def test_too_few_points_or_no_spread_gives_no_step() -> None:
    k, n_subsets = 4, 5
    needed = POINTS_PER_COEFFICIENT * n_coefficients(k, n_subsets)
    assert n_coefficients(k, n_subsets) == 5 * 4 + 10
    rng = np.random.default_rng(3)
    offsets = rng.standard_normal((needed - 1, k))
    subset = np.arange(needed - 1) % n_subsets
    assert quadratic_step(offsets, subset, rng.standard_normal(needed - 1), np.full(n_subsets, 0.2)) is None
    assert quadratic_step(np.zeros((needed, k)), np.arange(needed) % n_subsets, np.zeros(needed), np.full(n_subsets, 0.2)) is None


@pytest.mark.parametrize("seed", range(6))
def test_trust_region_minimum_matches_a_constrained_optimiser(seed: int) -> None:
    """Definite, indefinite and step-outside cases against scipy's SLSQP on the same subproblem."""
    rng = np.random.default_rng(seed)
    k = 4
    a = rng.standard_normal((k, k))
    curvature = a + a.T if seed % 2 else a @ a.T + 0.1 * np.eye(k)  # odd seeds: indefinite
    gradient = rng.standard_normal(k)
    radius = 0.5 if seed < 4 else 50.0
    z = trust_region_minimum(gradient, curvature, radius)
    model = lambda x: gradient @ x + 0.5 * x @ curvature @ x  # noqa: E731
    best = min(
        (
            minimize(model, start, constraints=[NonlinearConstraint(lambda x: x @ x, 0.0, radius**2)], method="SLSQP", tol=1e-12)
            for start in rng.standard_normal((8, k)) * radius / 4
        ),
        key=lambda r: r.fun,
    )
    assert np.linalg.norm(z) <= radius * (1 + 1e-9)
    assert model(z) <= best.fun + 1e-7 * max(1.0, abs(best.fun))


def test_trust_region_hard_case_goes_to_the_boundary_along_the_lowest_eigenvector() -> None:
    """Gradient without a component along the negative-curvature direction: ``|z(lam)|`` never reaches the radius."""
    curvature = np.diag([-1.0, 2.0])
    z = trust_region_minimum(np.array([0.0, 1.0]), curvature, 10.0)
    np.testing.assert_allclose(z, [np.sqrt(100.0 - 1.0 / 9.0), -1.0 / 3.0], rtol=1e-12)  # model -50.17
    np.testing.assert_allclose(np.abs(trust_region_minimum(np.zeros(2), curvature, 1.0)), [1.0, 0.0], atol=1e-15)


def test_non_finite_costs_give_no_step() -> None:
    rng = np.random.default_rng(4)
    offsets = rng.standard_normal((60, 2))
    excess = np.einsum("ij,ij->i", offsets, offsets)
    excess[7] = np.nan
    assert quadratic_step(offsets, np.zeros(60, dtype=np.intp), excess, np.ones(1)) is None
