"""The ``sdp`` estimator: physically consistent weighted least squares as a semidefinite program.

References independent of the code under test: the simulator's exact torques (noise-free recovery), WLS's closed form
(the equal-cost case), the textbook checks of a body (principal moments about the CoM, triangle inequalities:
:func:`~estimators.arm.consistency.satisfies_triangle_inequalities`, :meth:`RigidBodyInertia.validate`) for the matrix
inequality, and a point-mass construction of the pseudo-inertia.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest

from estimators.arm.consistency import (
    PhysicalConsistency,
    is_physically_consistent,
    principal_moments_about_com,
    pseudo_inertia,
    satisfies_triangle_inequalities,
)
from estimators.arm.linear_ls import WeightedLeastSquares, group_weighted
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.arm.sdp import SemidefiniteLeastSquares, consistent_optimum
from estimators.arm.synthetic import arm_benchmark, last_link_problem
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.simulated_arm_datasets import simulate_arm_dataset
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia

FRICTION = ("coulomb", "viscous")


def test_cvxpy_has_clarabel() -> None:
    assert "CLARABEL" in cp.installed_solvers()


def test_noise_free_ur5_recovers_the_true_base_parameters_and_is_consistent(tmp_path) -> None:
    """Noise-free simulated UR5 (10 s random Fourier excitation, the simulator's exact torques and states): the true base
    parameters to 1e-6 relative, every pseudo-inertia PSD to the solver's tolerance, friction >= 0."""
    ur5 = load_arm("ur5")
    dataset = simulate_arm_dataset(ur5, 10.0, FRICTION, 5, "fourier", tmp_path / "clean", sensors=ArmSensorModel.noise_free())
    p_true = np.array(list(dataset.truth["parameters"].values()))
    model = ArmIdentificationModel.build(ur5, FRICTION)
    log = dataset.simulation.clean
    problem = model.problem([IdentificationRows(log, model.log_regressor(log))])
    beta_true = model.base.to_base(p_true)
    estimate = estimator_from_spec("sdp").fit_problem(problem)
    assert np.linalg.norm(estimate.theta - beta_true) <= 1e-6 * np.linalg.norm(beta_true)
    assert np.max(np.abs(estimate.theta - beta_true)) <= 1e-6 * np.max(np.abs(beta_true))
    assert estimate.extra["solver"] == "CLARABEL" and estimate.extra["fallback_reason"] is None
    full = np.asarray(estimate.extra["full_params"])
    np.testing.assert_allclose(model.base.to_base(full), estimate.theta, rtol=0, atol=1e-12)
    consistency = model.consistency()
    for columns, t in zip(consistency.link_columns, consistency.link_congruence(), strict=True):
        scaled = pseudo_inertia(full[columns]) / np.outer(t, t)
        assert np.linalg.eigvalsh(scaled)[0] >= -1e-9
    assert estimate.physical["links_physically_consistent"] == [True] * 6 and estimate.physical["friction_non_negative"]


def test_equals_wls_where_wls_is_consistent_and_costs_more_where_it_is_not() -> None:
    """The thin last link alone, full rank (its params10 directly): where the WLS body passes the textbook checks, sdp
    is WLS; where it does not, sdp is consistent and its cost is above WLS's (the unconstrained minimum)."""
    outcomes = set()
    for seed, noise_scale in [(0, 0.001), (1, 0.001), (0, 1.0), (1, 1.0)]:
        problem, _ = last_link_problem(seed, n_samples=200, noise_scale=noise_scale)
        weighted = group_weighted(problem)  # the cost both minimise (Gautier's two-step weights)
        rows = np.arange(problem.n_samples)  # residuals summed directly: the Gram form loses digits at tiny costs
        wls = WeightedLeastSquares().fit_problem(problem)
        sdp = SemidefiniteLeastSquares().fit_problem(problem)
        wls_cost, sdp_cost = (float(weighted.cost(e.theta, rows, count=False)[0]) for e in (wls, sdp))
        assert is_physically_consistent(sdp.theta) and satisfies_triangle_inequalities(sdp.theta, rtol=1e-9)
        if satisfies_triangle_inequalities(wls.theta):
            outcomes.add("consistent")
            np.testing.assert_allclose(sdp.theta, wls.theta, rtol=1e-8, atol=1e-10)
            assert sdp_cost == pytest.approx(wls_cost, rel=1e-9)
        else:
            outcomes.add("inconsistent")
            assert sdp_cost > wls_cost and sdp.extra["consistency_cost_increase"] > 0
    assert outcomes == {"consistent", "inconsistent"}


def _body(mass: float, com: list[float], moments: list[float], rotation_seed: int = 0) -> np.ndarray:
    """params10 of a body with principal moments ``moments`` about its CoM (rotated by a random rotation), by the
    parallel-axis theorem written out here (not through the module under test)."""
    q, _ = np.linalg.qr(np.random.default_rng(rotation_seed).normal(size=(3, 3)))
    inertia_com = q @ np.diag(moments) @ q.T
    c = np.asarray(com)
    inertia = inertia_com + mass * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([mass, *(mass * c), inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]])


def _nearest_consistent(params10: np.ndarray) -> tuple[float, np.ndarray]:
    """The sdp's optimum on ``tau = params10`` with an identity regressor (one link): its cost (0 iff the body is
    consistent) and body."""
    y = np.vstack([np.eye(10), np.eye(10)])
    consistency = PhysicalConsistency(
        link_columns=np.arange(10)[None, :],
        friction_columns=np.zeros(0, dtype=np.intp),
        mass_range_kg=[(0.1, 10.0)],
        size_m=[0.5],
        friction_upper=np.zeros(0),
    )
    problem = LinearIdentificationProblem(
        y, np.tile(params10, 2), [f"p{i}" for i in range(10)], -10 * np.ones(10), 10 * np.ones(10), consistency=consistency
    )
    optimum = consistent_optimum(problem)
    return optimum.cost, optimum.theta


def test_the_matrix_inequality_is_the_textbook_consistency() -> None:
    """A negative principal moment, a violated triangle inequality or a negative mass: the sdp's constraint set does not
    contain the body (its nearest consistent body is elsewhere), and the pseudo-inertia test, the textbook checks
    and :meth:`RigidBodyInertia.validate` agree; consistent bodies (a thin rod on the boundary too) are reproduced."""
    consistent = [
        _body(2.0, [0.1, -0.05, 0.2], [0.02, 0.03, 0.04], 1),
        _body(1.0, [0.0, 0.0, 0.25], [0.02, 0.02, 0.0], 2),  # a rod: I1 + I2 = I3, on the boundary
        _body(0.5, [0.3, 0.1, 0.0], [0.01, 0.01, 0.015], 3),
    ]
    inconsistent = [
        _body(2.0, [0.1, -0.05, 0.2], [-0.01, 0.03, 0.04], 4),  # negative principal moment
        _body(1.0, [0.0, 0.1, 0.0], [0.01, 0.01, 0.03], 5),  # I1 + I2 < I3
        np.array([-1.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.1, 0.0, 0.0, 0.1]),  # negative mass
    ]
    for body in consistent:
        assert satisfies_triangle_inequalities(body, rtol=1e-9) and is_physically_consistent(body, rtol=1e-9)
        cost, nearest = _nearest_consistent(body)
        assert cost <= 1e-12 * (body @ body)
        np.testing.assert_allclose(nearest, body, rtol=0, atol=1e-6 * np.abs(body).max())
    for body in inconsistent:
        assert not satisfies_triangle_inequalities(body) and not is_physically_consistent(body)
        if body[0] > 0:
            with pytest.raises(SpaceIdInputError):
                RigidBodyInertia.from_params10(body).validate("body")
        cost, nearest = _nearest_consistent(body)
        assert cost > 1e-6 * (body @ body)
        eigenvalues = np.linalg.eigvalsh(pseudo_inertia(nearest))
        assert eigenvalues[0] >= -1e-9 * eigenvalues[-1]  # in the (closed) cone: a massless limit for the negative mass
    # random bodies: the 4x4 test and the textbook test give the same verdict
    rng = np.random.default_rng(0)
    verdicts = set()
    for seed in range(200):
        moments = rng.uniform(-0.02, 0.1, 3)
        body = _body(rng.uniform(0.1, 3.0), list(rng.normal(scale=0.2, size=3)), list(moments), seed)
        verdict = satisfies_triangle_inequalities(body)
        assert is_physically_consistent(body) == verdict
        np.testing.assert_allclose(np.sort(principal_moments_about_com(body)), np.sort(moments), atol=1e-12)
        verdicts.add(verdict)
    assert verdicts == {True, False}


def test_the_regulariser_acts_only_where_the_data_are_silent() -> None:
    """The synthetic arm (50 base parameters, 72 full): 22 unidentified directions; without the regulariser the masses
    the torques do not see run off; with it the cost is within 1e-4 of the unregularised optimum (0.2 chi-square units)."""
    problem = group_weighted(arm_benchmark(seed=0).problem)
    free = consistent_optimum(problem, regularisation=0.0)
    default = consistent_optimum(problem)
    assert default.facts["n_unidentified_directions"] == 22
    assert default.cost == pytest.approx(free.cost, rel=1e-4)
    assert default.cost - free.cost <= 0.2 * default.facts["chi_square_unit"]
    consistency = problem.consistency
    assert consistency is not None
    masses = default.full[consistency.link_columns[:, 0]]
    assert np.all(masses < 5.0) and np.max(free.full[consistency.link_columns[:, 0]]) > 10 * np.max(masses)


def test_clarabel_failure_falls_back_to_scs_and_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    problem, _ = last_link_problem(0, n_samples=200)
    solve = cp.Problem.solve

    def failing_clarabel(self: cp.Problem, *args: object, **kwargs: object) -> object:
        if kwargs.get("solver") == cp.CLARABEL:
            raise cp.error.SolverError("simulated failure")
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(cp.Problem, "solve", failing_clarabel)
    estimate = SemidefiniteLeastSquares().fit_problem(problem)
    assert estimate.extra["solver"] == "SCS" and "simulated failure" in estimate.extra["fallback_reason"]
    assert estimate.physical["links_physically_consistent"] == [True]


def test_registry_determinism_and_bad_input() -> None:
    problem, _ = last_link_problem(2, n_samples=60)
    first, second = (estimator_from_spec("sdp[regularisation=0.01]").fit_problem(problem) for _ in range(2))
    np.testing.assert_array_equal(first.theta, second.theta)
    assert first.options == {"regularisation": 0.01}
    with pytest.raises(SpaceIdInputError, match="regularisation"):
        estimator_from_spec("sdp[regularisation=-1]")
    plain = LinearIdentificationProblem(
        problem.Y, problem.tau, problem.parameters.names, problem.parameters.lower, problem.parameters.upper
    )
    with pytest.raises(SpaceIdInputError, match="no PhysicalConsistency"):
        SemidefiniteLeastSquares().fit_problem(plain)
    with pytest.raises(SpaceIdInputError, match="needs a linear problem"):
        SemidefiniteLeastSquares().search(object(), np.random.default_rng(0))  # type: ignore[arg-type]
