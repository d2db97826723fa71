"""Linear identification: the problem (tau = Y theta), OLS and WLS, physical consistency and the log-Cholesky map.

References are independent of the code under test: pinocchio's RNEA for the torques, pinocchio's
Inertia algebra for the pseudo-inertia, :meth:`RigidBodyInertia.validate` for consistency, Monte Carlo
for the Cramér-Rao bound, the chi-square distribution for the estimation error.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from scipy.stats import chi2

from estimators.arm.consistency import (
    PhysicalConsistency,
    is_physically_consistent,
    log_cholesky_to_params10,
    params10_from_pseudo_inertia,
    params10_to_log_cholesky,
    pseudo_inertia,
)
from estimators.arm.linear_ls import OrdinaryLeastSquares, WeightedLeastSquares
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.synthetic import (
    FRICTION_TRUE,
    N_JOINTS,
    NOISE_STD,
    ArmBenchmark,
    arm_base_parameters,
    arm_benchmark,
    arm_regressor,
    fourier_trajectory,
    full_box,
    last_link_problem,
    sample_model,
    true_full_parameters,
)
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia


@pytest.fixture(scope="module")
def bench() -> ArmBenchmark:
    """The documented 50-base-parameter arm problem (2400 rows), noise estimated per joint."""
    return arm_benchmark(seed=0)


def _problem(y: np.ndarray, tau: np.ndarray, **kwargs: object) -> LinearIdentificationProblem:
    k = y.shape[1]
    return LinearIdentificationProblem(y, tau, [f"p{i}" for i in range(k)], -10 * np.ones(k), 10 * np.ones(k), **kwargs)


# ---------------------------------------------------------------------- the regressor and base parameters
def test_regressor_matches_rnea_with_friction() -> None:
    """Y(q, dq, ddq) theta_full equals pinocchio's inverse dynamics plus fc sign(dq) + fv dq (independent reference)."""
    model = sample_model()
    data = model.createData()
    q, dq, ddq = fourier_trajectory(np.random.default_rng(3), 15)
    predicted = arm_regressor(model, q, dq, ddq) @ true_full_parameters(model)
    rnea = np.array([pin.rnea(model, data, q[t], dq[t], ddq[t]) for t in range(len(q))])
    friction = FRICTION_TRUE[:, 0] * np.sign(dq) + FRICTION_TRUE[:, 1] * dq
    np.testing.assert_allclose(predicted, rnea + friction, rtol=0, atol=1e-10 * np.abs(rnea).max())


def test_fourier_trajectory_derivatives_are_consistent() -> None:
    """dq and ddq are the time derivatives of q (central differences)."""
    dt = 1e-4
    q, dq, ddq = fourier_trajectory(np.random.default_rng(1), 3, dt_s=dt)
    np.testing.assert_allclose((q[2] - q[0]) / (2 * dt), dq[1], atol=1e-6)
    np.testing.assert_allclose((dq[2] - dq[0]) / (2 * dt), ddq[1], atol=1e-5)


def test_base_map_reproduces_the_full_regressor_on_new_states() -> None:
    """Y[:, independent] K = Y on states not used to find K; 50 base parameters for this arm."""
    model = sample_model()
    base = arm_base_parameters(model)
    k_map, independent = base.K, base.independent
    assert k_map.shape == (50, 12 * N_JOINTS)
    q, dq, ddq = fourier_trajectory(np.random.default_rng(8), 30)
    y = arm_regressor(model, q, dq, ddq).reshape(-1, 12 * N_JOINTS)
    np.testing.assert_allclose(y[:, independent] @ k_map, y, rtol=0, atol=1e-9 * np.abs(y).max())


# ---------------------------------------------------------------------- the problem
def test_problem_rejects_bad_input() -> None:
    y, tau = np.ones((6, 2)), np.ones(6)
    with pytest.raises(SpaceIdInputError, match="Y"):
        _problem(np.full((6, 2), np.nan), tau)
    with pytest.raises(SpaceIdInputError, match="tau"):
        _problem(y, np.ones(5))
    with pytest.raises(SpaceIdInputError, match="names"):
        LinearIdentificationProblem(y, tau, ["a"], [0, 0], [1, 1])
    with pytest.raises(SpaceIdInputError, match="row_std"):
        _problem(y, tau, row_std=np.zeros(6))
    with pytest.raises(SpaceIdInputError, match="row_group"):
        _problem(y, tau, row_group=-np.ones(6, dtype=int))
    with pytest.raises(SpaceIdInputError, match="lower bound not below upper"):
        LinearIdentificationProblem(y, tau, ["a", "b"], [0, 1], [1, 1])
    with pytest.raises(SpaceIdInputError, match="consistency"):
        _problem(y, tau, consistency=PhysicalConsistency.per_joint(1, mass_range_kg=(0.1, 1), size_m=1.0))


def test_cost_gram_form_equals_direct_residuals_and_counts(bench: ArmBenchmark) -> None:
    """The whole-data cost (Gram form) equals the mean weighted squared residual; each theta counts N rows."""
    problem = arm_benchmark(seed=0, known_noise=True).problem
    rng = np.random.default_rng(0)
    theta = problem.parameters.from_unit(rng.random((4, problem.n_params)))
    theta[0] = bench.theta_true
    direct = np.mean(problem.weights * (theta @ problem.Y.T - problem.tau) ** 2, axis=1)
    problem.n_model_samples = 0
    np.testing.assert_allclose(problem.cost(theta), direct, rtol=1e-9)
    assert problem.n_evaluations == 4
    rows = np.arange(0, problem.n_samples, 7)
    np.testing.assert_allclose(
        problem.cost(theta, rows), np.mean(problem.weights[rows] * (theta @ problem.Y[rows].T - problem.tau[rows]) ** 2, axis=1)
    )
    assert problem.n_model_samples == 4 * problem.n_samples + 4 * len(rows)
    np.testing.assert_allclose(problem.cost(theta, count=False)[0], problem.cost(theta[0])[0])
    assert np.mean(problem.weights) == pytest.approx(1.0)
    subsets = problem.subsets(3)
    assert sum(len(s) for s in subsets) == problem.n_samples


# ---------------------------------------------------------------------- least squares
def test_ols_is_exact_on_noise_free_data() -> None:
    """Noise-free torques from pinocchio's RNEA: OLS recovers the true base parameters to 1e-10 (relative)."""
    model = sample_model()
    data = model.createData()
    base = arm_base_parameters(model)
    k_map, independent = base.K, base.independent
    rng = np.random.default_rng(5)
    q, dq, ddq = fourier_trajectory(rng, 100)
    y = arm_regressor(model, q, dq, ddq).reshape(-1, 12 * N_JOINTS)[:, independent]
    tau = np.array([pin.rnea(model, data, q[t], dq[t], ddq[t]) for t in range(len(q))])
    tau = (tau + FRICTION_TRUE[:, 0] * np.sign(dq) + FRICTION_TRUE[:, 1] * dq).ravel()
    truth = k_map @ true_full_parameters(model)
    problem = _problem(y, tau)
    estimate = OrdinaryLeastSquares().fit_problem(problem)
    np.testing.assert_allclose(estimate.theta, truth, rtol=0, atol=1e-10 * np.abs(truth).max())
    assert estimate.n_evaluations == 1
    assert estimate.extra["rank"] == 50


def test_wls_recovers_the_per_joint_noise(bench: ArmBenchmark) -> None:
    """The per-joint std from the OLS residuals matches the simulated one within 4 standard errors."""
    estimate = WeightedLeastSquares().fit_problem(bench.problem)
    used = np.asarray(estimate.extra["group_noise_std_used"])
    rows_per_joint = bench.problem.n_samples // N_JOINTS
    standard_error = NOISE_STD / np.sqrt(2 * rows_per_joint)  # of a std estimated from n residuals
    assert np.all(np.abs(used - NOISE_STD) < 4 * standard_error), (used, NOISE_STD)
    # the estimate's own noise figure comes from the WLS residual: the same statistical tolerance
    assert np.all(np.abs(estimate.physical["noise_std_per_group"] - NOISE_STD) < 4 * standard_error)


def test_wls_error_is_chi_square_distributed_and_beats_ols(bench: ArmBenchmark) -> None:
    """(theta - truth)^T F (theta - truth) below the 0.999 chi-square quantile (k = 50); OLS is less efficient here."""
    problem = bench.problem
    wls = WeightedLeastSquares().fit_problem(problem)
    fisher = problem.fisher(bench.theta_true, bench.row_std)
    error = wls.theta - bench.theta_true
    assert error @ fisher @ error < chi2.ppf(0.999, problem.n_params)
    # the reported bound (noise estimated per joint) agrees with the true-noise bound
    np.testing.assert_allclose(wls.theta_std, bench.crlb(), rtol=0.1)
    assert wls.identifiable.all() and not wls.insufficient_excitation
    assert bench.holdout_error(wls.theta) < 1.1
    ols = OrdinaryLeastSquares().fit_problem(problem)
    ols_error = ols.theta - bench.theta_true
    assert ols_error @ fisher @ ols_error > error @ fisher @ error
    json.dumps(wls.to_dict())  # the estimate file is JSON-serialisable


def test_wls_covariance_matches_the_cramer_rao_bound() -> None:
    """Monte Carlo: 300 noise draws on one regressor; the spread of the WLS estimates matches the bound (known noise)."""
    bench = arm_benchmark(seed=2, known_noise=True)
    problem = bench.problem
    rng = np.random.default_rng(11)
    clean = problem.Y @ bench.theta_true
    whitened = problem.Y / bench.row_std[:, None]
    draws = clean + rng.normal(size=(300, problem.n_samples)) * bench.row_std
    estimates = np.linalg.lstsq(whitened, (draws / bench.row_std).T, rcond=None)[0].T
    ratio = estimates.std(axis=0) / problem.crlb_std(bench.theta_true)
    # a std from 300 draws has a relative standard error of 1 / sqrt(600) ~ 4 %: 4 standard errors
    assert np.all(np.abs(ratio - 1.0) < 4 / np.sqrt(600)), ratio


def test_rank_deficient_full_parameters_are_reported_not_identifiable() -> None:
    """Posed in the 72 full parameters, the unidentifiable ones get an unbounded bound and a message."""
    model = sample_model()
    q, dq, ddq = fourier_trajectory(np.random.default_rng(0), 100)
    y = arm_regressor(model, q, dq, ddq).reshape(-1, 12 * N_JOINTS)
    tau = y @ true_full_parameters(model) + np.random.default_rng(1).normal(size=len(y)) * 0.1
    lower, upper = full_box()
    problem = LinearIdentificationProblem(y, tau, [f"x{i}" for i in range(72)], lower, upper)
    estimate = OrdinaryLeastSquares().fit_problem(problem)
    assert estimate.extra["rank"] == 50
    assert 0 < estimate.identifiable.sum() < 72
    assert np.all(np.isinf(estimate.theta_std[~estimate.identifiable]) | (estimate.theta_std[~estimate.identifiable] > 0))
    assert len(estimate.insufficient_excitation) == (~estimate.identifiable).sum()
    assert "x0 is not identifiable" in " ".join(estimate.insufficient_excitation)  # link 1's mass never matters


def test_with_row_std_weights_the_cost_like_wls(bench: ArmBenchmark) -> None:
    """The reweighted problem's minimum is the WLS estimate; its bound uses the given std; the data are shared."""
    wls = WeightedLeastSquares().fit_problem(bench.problem)
    weighted = bench.problem.with_row_std(np.asarray(wls.extra["group_noise_std_used"])[bench.problem.row_group])
    assert weighted.Y is bench.problem.Y and weighted.parameters.names == bench.problem.parameters.names
    np.testing.assert_array_equal(weighted.row_group, bench.problem.row_group)
    gradient = weighted.Y.T @ (weighted.weights * weighted.residuals(wls.theta, count=False))
    assert np.abs(gradient).max() < 1e-9 * np.abs(weighted.Y.T @ (weighted.weights * weighted.tau)).max()
    assert weighted.noise_std(wls.theta)[1] == "given"


def test_least_squares_needs_a_linear_problem() -> None:
    nonlinear = SimpleNamespace(n_params=4, n_samples=100, n_model_samples=0)
    for estimator in (OrdinaryLeastSquares(), WeightedLeastSquares()):
        with pytest.raises(SpaceIdInputError, match="needs a linear problem"):
            estimator.fit_problem(nonlinear)  # type: ignore[arg-type]


# ---------------------------------------------------------------------- pseudo-inertia and log-Cholesky
def test_pseudo_inertia_is_the_second_moment_of_point_masses() -> None:
    """For a cloud of point masses, J = sum m [r; 1][r; 1]^T, with params10 summed by pinocchio's Inertia algebra."""
    rng = np.random.default_rng(4)
    masses, points = rng.uniform(0.1, 2.0, 7), rng.normal(size=(7, 3))
    body = pin.Inertia.Zero()
    for m, r in zip(masses, points, strict=True):
        body += pin.Inertia(m, r, np.zeros((3, 3)))
    homogeneous = np.hstack((points, np.ones((7, 1))))
    expected = np.einsum("k,ki,kj->ij", masses, homogeneous, homogeneous)
    params = body.toDynamicParameters()
    np.testing.assert_allclose(pseudo_inertia(params), expected, atol=1e-12)
    np.testing.assert_allclose(params10_from_pseudo_inertia(expected), params, atol=1e-12)


def test_log_cholesky_round_trip_and_always_consistent() -> None:
    rng = np.random.default_rng(7)
    z = rng.uniform(-1.0, 1.0, size=(200, 10))  # masses 0.14-7.4 kg, lengths 0.37-2.7 m
    params = log_cholesky_to_params10(z)
    np.testing.assert_allclose(params10_to_log_cholesky(params), z, rtol=0, atol=1e-12)
    # wider spreads lose digits as the CoM spread matrix's condition number (exp(2 |d_i - d_j|)) grows
    z = rng.normal(size=(200, 10))
    params = log_cholesky_to_params10(z)
    np.testing.assert_allclose(params10_to_log_cholesky(params), z, rtol=0, atol=1e-10)
    for p in params:
        assert is_physically_consistent(p)
        RigidBodyInertia.from_params10(p).validate("log-Cholesky body")  # independent check: m > 0, PD, triangle
    # physical reading: m = exp(2 alpha), CoM = t
    np.testing.assert_allclose(params[:, 0], np.exp(2 * z[:, 0]))
    np.testing.assert_allclose(params[:, 1:4] / params[:, :1], z[:, 7:10])
    # and from a consistent body to its coordinates and back
    rotation = pin.exp3(rng.normal(size=3))
    body = RigidBodyInertia(1.7, np.array([0.1, -0.2, 0.3]), rotation @ np.diag([0.02, 0.05, 0.06]) @ rotation.T).to_params10()
    np.testing.assert_allclose(log_cholesky_to_params10(params10_to_log_cholesky(body)), body, rtol=0, atol=1e-14)


def test_inconsistent_bodies_are_flagged() -> None:
    def body(mass: float, com: list[float], moments: list[float]) -> np.ndarray:
        return RigidBodyInertia(mass, np.array(com), np.diag(moments)).to_params10()

    assert is_physically_consistent(body(1.0, [0.1, 0.0, 0.3], [0.1, 0.2, 0.25]))
    assert is_physically_consistent(body(1.0, [0.0, 0.0, 0.0], [0.0, 0.5, 0.5]))  # a rod along x: singular J, allowed
    assert not is_physically_consistent(body(1.0, [0.0, 0.0, 0.0], [0.1, 0.1, 0.3]))  # I1 + I2 < I3
    assert not is_physically_consistent(body(1.0, [0.0, 0.0, 0.0], [-0.1, 0.2, 0.2]))
    assert not is_physically_consistent(body(-1.0, [0.0, 0.0, 0.0], [0.1, 0.1, 0.1]))
    assert not is_physically_consistent(np.full(10, np.nan))
    with pytest.raises(SpaceIdInputError, match="not physically consistent"):
        params10_to_log_cholesky(body(1.0, [0.0, 0.0, 0.0], [0.1, 0.1, 0.3]))
    with pytest.raises(SpaceIdInputError, match="params10"):
        is_physically_consistent(np.ones(9))


def test_physical_consistency_layout_and_box() -> None:
    model = sample_model()
    truth = true_full_parameters(model)
    k_map = arm_base_parameters(model).K
    consistency = PhysicalConsistency.per_joint(
        N_JOINTS, mass_range_kg=(0.01, 2.0), size_m=1.0, friction_upper=(2.0, 1.0), base_map=k_map
    )
    assert consistency.n_full == 72 and consistency.n_theta == 50
    np.testing.assert_array_equal(consistency.link_columns[1], np.arange(12, 22))
    np.testing.assert_array_equal(consistency.friction_columns[:4], [10, 11, 22, 23])
    search = consistency.search_from_full(truth)
    lower, upper = consistency.search_box()
    assert np.all((search >= lower) & (search <= upper))
    np.testing.assert_allclose(consistency.full_from_search(search), truth, atol=1e-12)
    np.testing.assert_allclose(consistency.theta_from_full(truth), k_map @ truth)
    assert all(consistency.links_consistent(truth)) and consistency.friction_consistent(truth)
    with pytest.raises(SpaceIdInputError, match="exactly once"):
        PhysicalConsistency(np.arange(10)[None], np.array([11]), [(0.1, 1.0)], [1.0], [1.0])
    with pytest.raises(SpaceIdInputError, match="mass_range_kg"):
        PhysicalConsistency.per_joint(2, mass_range_kg=(1.0, 0.5), size_m=1.0)


def test_ols_on_a_poorly_excited_thin_link_is_not_physically_consistent() -> None:
    """The last link alone (a thin rod), 1 s of data: OLS gives an inconsistent body, and the estimate says so."""
    flagged = 0
    for seed in range(5):
        problem, truth = last_link_problem(seed)
        assert is_physically_consistent(truth)
        estimate = OrdinaryLeastSquares().fit_problem(problem)
        consistent = estimate.physical["links_physically_consistent"][0]
        assert consistent == is_physically_consistent(estimate.theta)
        flagged += not consistent
    assert flagged == 5
