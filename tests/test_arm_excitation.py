"""Fourier excitation trajectories and their optimisation for the base regressor.

Independent references: finite differences of the closed-form trajectory, a dense-grid check of
the limits, the criterion's gradient against central differences, the condition number from a
singular-value decomposition of the stacked regressor.
"""

from __future__ import annotations

import numpy as np
import pytest

from spaceid_gym.arm import ArmRegressor, BaseParameterSet, load_arm
from spaceid_gym.arm.excitation_design import (
    FourierTrajectory,
    _Criterion,
    optimise_excitation,
    random_fourier_trajectory,
    regressor_condition,
)
from spaceid_gym.errors import SpaceIdInputError


@pytest.fixture(scope="module")
def ur5():
    return load_arm("ur5")


@pytest.fixture(scope="module")
def model(ur5):
    regressor = ArmRegressor(ur5)
    return regressor, BaseParameterSet.from_regressor(regressor, np.random.default_rng(0))


def test_closed_form_derivatives_and_period() -> None:
    rng = np.random.default_rng(0)
    trajectory = FourierTrajectory(3, 4, 0.2, rng.normal(size=(3, 2, 4)), rng.normal(size=3))
    t = np.linspace(0.3, 9.7, 50)
    h = 1e-5
    q, dq, ddq = trajectory.state(t)
    np.testing.assert_allclose((trajectory.state(t + h)[0] - trajectory.state(t - h)[0]) / (2 * h), dq, atol=1e-8)
    np.testing.assert_allclose((trajectory.state(t + h)[1] - trajectory.state(t - h)[1]) / (2 * h), ddq, atol=1e-7)
    np.testing.assert_allclose(trajectory.state(t + trajectory.period_s)[0], q, atol=1e-12)
    np.testing.assert_allclose(
        trajectory.state(np.linspace(0, 5, 1000, endpoint=False))[0].mean(axis=0), trajectory.q0, atol=1e-12
    )
    single = trajectory.state(1.25)
    np.testing.assert_allclose(single[2], trajectory.state(np.array([1.25]))[2][0])
    assert single[0].shape == (3,)
    again = FourierTrajectory.from_dict(trajectory.to_dict())
    np.testing.assert_array_equal(again.state(t)[1], dq)


def test_bad_trajectory_inputs_are_named() -> None:
    with pytest.raises(SpaceIdInputError, match=r"coefficients must be finite with shape \(n, 2, H\) = \(2, 2, 3\)"):
        FourierTrajectory(2, 3, 0.1, np.zeros((2, 6)), np.zeros(2))
    with pytest.raises(SpaceIdInputError, match="base_frequency_hz"):
        FourierTrajectory(2, 3, 0.0, np.zeros((2, 2, 3)), np.zeros(2))
    with pytest.raises(SpaceIdInputError, match="q0"):
        FourierTrajectory(2, 3, 0.1, np.zeros((2, 2, 3)), np.zeros(3))


def test_random_trajectory_fills_the_limits_it_is_given(ur5) -> None:
    full, half = (random_fourier_trajectory(ur5, np.random.default_rng(1), fill=fill, limit_fraction=0.9) for fill in (1.0, 0.5))
    assert max(full.peak_ratios(ur5, n_points=20000).values()) == pytest.approx(0.9, rel=1e-4)  # one limit is reached
    np.testing.assert_allclose(half.coefficients, 0.5 * full.coefficients)
    np.testing.assert_array_equal(half.q0, full.q0)
    lower, upper = np.full(6, -1.0), np.full(6, 1.0)
    narrow = random_fourier_trajectory(ur5, np.random.default_rng(2), fill=1.0, q_bounds_rad=(lower, upper))
    q = narrow.state(np.linspace(0.0, narrow.period_s, 4000))[0]
    assert np.abs(q).max() <= 0.9 + 1e-6


@pytest.mark.parametrize("kind", ["condition", "d-optimal"])
def test_criterion_gradient_matches_central_differences(ur5, model, kind: str) -> None:
    regressor, base = model
    criterion = _Criterion(regressor, base, kind, 3, 0.1, np.linspace(0.0, 10.0, 16, endpoint=False))
    trajectory = random_fourier_trajectory(ur5, np.random.default_rng(2), n_harmonics=3)
    x = np.concatenate((trajectory.coefficients.ravel(), trajectory.q0))
    value, gradient = criterion.value_and_gradient(x)
    assert value == pytest.approx(criterion.value(x))
    for i in (0, 5, 17, 35, x.size - 6, x.size - 1):  # a, b of several joints and q0
        step = np.zeros_like(x)
        step[i] = 1e-5
        central = (criterion.value(x + step) - criterion.value(x - step)) / 2e-5
        assert gradient[i] == pytest.approx(central, rel=2e-3, abs=1e-4 * np.abs(gradient).max())
    if kind == "condition":  # the criterion is log cond of the stacked base regressor
        rows = base.base_regressor(regressor.regressor(*trajectory.state(np.linspace(0, 10, 16, endpoint=False))))
        singular = np.linalg.svd(rows.reshape(-1, base.rank), compute_uv=False)
        assert value == pytest.approx(np.log(singular[0] / singular[-1]), rel=1e-9)


def test_optimised_excitation_beats_random_starts_within_limits(ur5, model) -> None:
    regressor, base = model
    result = optimise_excitation(regressor, base, rng=np.random.default_rng(3), n_starts=1, max_iterations=25, n_grid=30)
    assert result.condition_optimised < 0.6 * result.condition_start
    peaks = result.trajectory.peak_ratios(ur5, n_points=20000)
    assert max(peaks.values()) <= 0.9 + 1e-6
    # the figure reported is the SVD condition number of the dense stacked base regressor
    t = np.linspace(0.0, 10.0, 250, endpoint=False)
    singular = np.linalg.svd(
        base.base_regressor(regressor.regressor(*result.trajectory.state(t))).reshape(-1, base.rank), compute_uv=False
    )
    assert result.condition_optimised == pytest.approx(singular[0] / singular[-1], rel=1e-6)
    assert result.wall_time_s < 30.0 and result.summary()["criterion"] == "condition"


def test_d_optimal_excitation_increases_the_information(ur5, model) -> None:
    regressor, base = model
    result = optimise_excitation(
        regressor, base, rng=np.random.default_rng(4), criterion="d-optimal", n_starts=1, max_iterations=15, n_grid=30
    )
    assert result.log_det_optimised > result.log_det_start + 1.0
    assert regressor_condition(result.trajectory, regressor, base)[1] == pytest.approx(result.log_det_optimised)


def test_bad_optimiser_inputs_are_named(model) -> None:
    regressor, base = model
    with pytest.raises(SpaceIdInputError, match="criterion"):
        optimise_excitation(regressor, base, rng=np.random.default_rng(0), criterion="a-optimal")
    with pytest.raises(SpaceIdInputError, match="n_grid"):
        optimise_excitation(regressor, base, rng=np.random.default_rng(0), n_grid=2)
    with pytest.raises(SpaceIdInputError, match="limit_fraction"):
        optimise_excitation(regressor, base, rng=np.random.default_rng(0), limit_fraction=1.5)
