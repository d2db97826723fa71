"""The analytic Jacobians of the prediction with effect terms against central differences of the prediction itself."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.problem as problem_module
from estimators.least_squares import interior_start
from estimators.models.slosh_dynamics import N_INPUTS, N_LANE_ROWS, integrate_slosh, slosh_momentum
from estimators.models.tangents import slosh_tangents, twist_tangents
from estimators.problem import IdentificationModel

#: each case's effects and their unknowns, all switched on (a pendulum's rod off the base's axes, a scale matrix with
#: every entry non-zero, a momentum, torque and torque rate together)
CASES = {
    "initial_momentum,gyro_bias": [0.8, -0.5, 0.3, 1e-3, -2e-3, 5e-4],
    "external_torque[drift=true]": [0.8, -0.5, 0.3, 0.01, -0.02, 0.005, 1e-4, 2e-4, -1e-4],
    "delay,gyro_scale": [0.05, 0.02, -0.01, 0.015, 0.01, -0.02, 0.005, -0.012, 0.018, 0.01],
    "payload": [20.0, 2.0, -1.0, 0.5, 0.4, 0.02, 0.35, -0.01, 0.03, 0.3],
    "slosh": [15.0, 0.25, 0.08],
    "slosh[model=pendulum]": [15.0, 0.25, 0.08, 0.4, 0.7, 4.0],
    "payload,slosh,external_torque,delay,gyro_bias": [
        *[20.0, 2.0, -1.0, 0.5, 0.4, 0.02, 0.35, -0.01, 0.03, 0.3],
        *[15.0, 0.4, 0.1],
        *[0.8, -0.5, 0.3, 0.01, -0.02, 0.005],
        0.03,
        *[1e-3, -2e-3, 5e-4],
    ],
}

#: the central differences' steps (fractions of each search width) the analytic Jacobian is compared with: rounding
#: dominates the smaller, truncation the larger (the slosh frequency's column); each column must agree with one (the
#: pendulum rod's curvature, whose column is 1e-4 of the others on this short log, only with the largest)
STEPS = (1e-6, 1e-5, 1e-3)

#: the largest difference allowed, relative to the column's largest entry (central differences reach 1e-8 to 5e-8
#: with the better of the two steps; the analytic columns agree with them that far)
TOLERANCE = 3e-7


@pytest.mark.parametrize("effects", list(CASES))
def test_analytic_jacobians_match_central_differences(short_fuel_episode, monkeypatch, effects: str) -> None:
    ep = short_fuel_episode
    problem = IdentificationModel(ep.robot, "fuel", effects=effects).problem(ep.log)
    params = problem.parameters
    theta = np.concatenate((interior_start(params)[:4], CASES[effects]))
    assert theta.shape == (params.n_params,) and np.all((params.lower <= theta) & (theta <= params.upper))
    analytic = {"predict": problem.jacobian(theta, count=False), "base_rate": problem.base_rate_jacobian(theta, count=False)}
    errors = {kind: np.full(params.n_params, np.inf) for kind in analytic}
    for step in STEPS:
        monkeypatch.setattr(problem_module, "DIFFERENCE_STEP", step)
        for kind, jac in analytic.items():
            numeric = problem.difference_jacobian(theta, getattr(problem, kind))
            scale = np.abs(numeric).max(axis=0)
            error = np.abs(jac - numeric).max(axis=0) / np.where(scale > 0.0, scale, 1.0)
            errors[kind] = np.minimum(errors[kind], error)
    for kind, error in errors.items():
        worst = int(np.argmax(error))
        assert error[worst] < TOLERANCE, f"{kind}: {params.names[worst]} differs by {error[worst]:.2g} of its column"
    # the measurement effects do not move the base, only the gyro's reading
    measurement = [i for i, name in enumerate(params.names) if name.startswith(("bias_", "scale_", "delay_"))]
    assert np.all(analytic["base_rate"][:, measurement] == 0.0)


@pytest.mark.parametrize("rod", [False, True])
def test_slosh_tangents_match_complex_steps_through_the_integration(rod: bool) -> None:
    """The slosh's written-out tangents (every RK4 stage of the spring, the frame's terms and the rod's tension)
    against the same integration run in complex numbers along each direction (the complex step: exact derivatives,
    an independent reference), to 1e-10 of each output's scale; some directions move the forcing and the coupling,
    the others only the oscillator and the rod, as a fit's do."""
    rng = np.random.default_rng(7)
    n_t, n_k, h = 400, 6, 1e-30
    t_s = np.arange(n_t) * 0.05
    phases = rng.uniform(0.0, 2.0 * np.pi, 6)
    twist = 0.05 * np.sin(2.0 * np.pi * np.outer(t_s, [0.05, 0.11, 0.07, 0.13, 0.09, 0.17]) + phases)
    d_twist = 0.01 * rng.standard_normal((n_k, n_t, 6)) * np.sin(2.0 * np.pi * 0.1 * t_s)[None, :, None]
    coupling = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    axis = rng.standard_normal(3)
    inputs = np.concatenate(
        ([0.3, -0.1, 0.2], [20.0, 2.0 * np.pi * 0.3, 0.05, 4.0], coupling.ravel(), axis / np.linalg.norm(axis))
    )
    d_inputs = 0.1 * rng.standard_normal((n_k, N_INPUTS))
    d_twist[3:], d_inputs[3:, :4], d_inputs[3:, 7:16] = 0.0, 0.0, 0.0  # the oscillator's own unknowns
    out, d_out, moved, d_moved = slosh_tangents(twist, d_twist, t_s, inputs, d_inputs, rod)
    c_out, c_moved = np.zeros((1, n_t, 6), dtype=complex), np.zeros((1, n_t, 10), dtype=complex)
    for q in range(n_k):
        lanes = np.zeros((N_LANE_ROWS, 1), dtype=complex)
        integrate_slosh(
            (twist + 1j * h * d_twist[q])[None], t_s, (inputs + 1j * h * d_inputs[q])[None], rod, c_out, c_moved, lanes
        )
        for value, reference, d_value, d_reference in (
            (out, c_out[0], d_out[q], c_out[0]),
            (moved, c_moved[0], d_moved[q], c_moved[0]),
        ):
            np.testing.assert_allclose(value, reference.real, rtol=0.0, atol=1e-12 * np.abs(reference.real).max())
            scale = np.abs(d_reference.imag / h).max()
            assert scale > 0.0
            np.testing.assert_allclose(d_value, d_reference.imag / h, rtol=0.0, atol=1e-10 * scale)


@pytest.mark.parametrize("rod", [False, True])
def test_slosh_tangents_side_by_side_give_each_direction_alone(rod: bool) -> None:
    """The slosh's tangents along several directions in vector lanes (:data:`~estimators.models.tangents.DIRECTION_LANES` at a
    time, the last group padded) give each direction the numbers of its own integration, to the last bit, and the
    same values; a zero divisor of the rod's tension raises, as a division by zero did."""
    rng = np.random.default_rng(5)
    n_t, n_k = 300, 7
    t_s = np.arange(n_t) * 0.02
    twist = 0.05 * np.sin(2.0 * np.pi * t_s[:, None] * rng.uniform(0.05, 0.2, 6))
    d_twist = 0.01 * rng.standard_normal((n_k, n_t, 6))
    axis = rng.standard_normal(3)
    coupling = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    inputs = np.concatenate(([0.2, 0.1, -0.3], [15.0, 2.0, 0.05, 3.0], coupling.ravel(), axis / np.linalg.norm(axis)))
    d_inputs = 0.1 * rng.standard_normal((n_k, N_INPUTS))
    d_twist[4:], d_inputs[4:, :4], d_inputs[4:, 7:16] = 0.0, 0.0, 0.0  # directions of the oscillator's own unknowns
    together = slosh_tangents(twist, d_twist, t_s, inputs, d_inputs, rod)
    for q in range(n_k):
        alone = slosh_tangents(twist, d_twist[q : q + 1], t_s, inputs, d_inputs[q : q + 1], rod)
        assert np.array_equal(together[0], alone[0]) and np.array_equal(together[2], alone[2])
        assert np.array_equal(together[1][q], alone[1][0]) and np.array_equal(together[3][q], alone[3][0])
    if rod:
        inputs[7:16] = 0.0  # no coupling: n.C n = 0
        with pytest.raises(ZeroDivisionError):
            slosh_tangents(twist, d_twist, t_s, inputs, d_inputs, rod)


def test_the_slosh_kernels_refuse_times_that_do_not_increase() -> None:
    """The tank's forcing divides by the time steps, and both slosh kernels run with numpy's error model (a division
    by zero gives inf): a repeated time raises instead of returning non-finite numbers."""
    n_t = 50
    t_s = np.arange(n_t) * 0.02
    t_s[1] = t_s[0]
    twist = np.full((n_t, 6), 0.01)
    inputs = np.concatenate(([0.2, 0.1, -0.3], [15.0, 2.0, 0.05, 0.0], np.eye(3).ravel(), [0.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="increase strictly"):
        slosh_momentum(twist[None], t_s, inputs[None], False)
    with pytest.raises(ValueError, match="increase strictly"):
        slosh_tangents(twist, np.zeros((2, n_t, 6)), t_s, inputs, np.zeros((2, N_INPUTS)), False)


def test_the_twist_kernel_refuses_maps_of_other_sizes() -> None:
    """The twist's tangents loop over the 10 inertial parameters, the 6 momentum rows and the log's samples: a payload
    map, an extra momentum or a parameter set of another size raises instead of reading past an array's end."""
    n_t, n_k = 4, 2
    ten, d_ten = np.ones((1, 10)), np.zeros((n_k, 10))
    args = (np.zeros((1, 1, 6)), np.zeros((n_k, 1, 6)), False, np.zeros((1, 1, 10)), np.zeros((n_k, 1, 10)), False, 1.0)
    arm = (np.zeros((n_t, 3)), np.zeros((n_t, 6)), np.zeros((n_t, 6)))
    with pytest.raises(ValueError, match="momentum_map"):
        twist_tangents(ten, d_ten, ten, d_ten, True, *args, *arm, np.zeros((n_t, 10, 10)), np.zeros((n_t, 6, 9)))
    extra = (np.zeros((1, n_t, 6)), np.zeros((n_k, n_t - 1, 6)), True, *args[3:])
    with pytest.raises(ValueError, match="extra momentum"):
        twist_tangents(ten, d_ten, ten, d_ten, False, *extra, *arm, np.zeros((1, 10, 10)), np.zeros((1, 6, 10)))
    with pytest.raises(ValueError, match="10 inertial"):
        twist_tangents(ten, np.zeros((n_k, 9)), ten, d_ten, False, *args, *arm, np.zeros((n_t, 10, 10)), np.zeros((n_t, 6, 10)))


@pytest.mark.parametrize("rod", [False, True])
def test_slosh_sets_side_by_side_give_each_set_alone(rod: bool) -> None:
    """The slosh integration of several parameter sets in vector lanes (:func:`slosh_momentum`) gives each set the
    numbers of its integration alone, to the last bit; a zero divisor of the rod's tension raises, as a division by
    zero did."""
    rng = np.random.default_rng(11)
    n_p, n_t = 11, 300
    t_s = np.arange(n_t) * 0.02
    twist = 0.05 * np.sin(2.0 * np.pi * t_s[None, :, None] * rng.uniform(0.05, 0.2, (n_p, 1, 6)))
    axis = rng.standard_normal((n_p, 3))
    inputs = np.hstack(
        (
            rng.uniform(-0.3, 0.3, (n_p, 3)),
            rng.uniform(5.0, 30.0, (n_p, 1)),
            rng.uniform(1.0, 3.0, (n_p, 1)),
            rng.uniform(0.01, 0.2, (n_p, 1)),
            rng.uniform(1.0, 5.0, (n_p, 1)),
            (np.eye(3)[None] + 0.1 * rng.standard_normal((n_p, 3, 3))).reshape(n_p, 9),
            axis / np.linalg.norm(axis, axis=1, keepdims=True),
        )
    )
    out, moved = slosh_momentum(twist, t_s, inputs, rod)
    for p in range(n_p):
        alone = slosh_momentum(twist[p : p + 1], t_s, inputs[p : p + 1], rod)
        assert np.array_equal(out[p], alone[0][0]) and np.array_equal(moved[p], alone[1][0])
    if rod:
        inputs[3, 7:16] = 0.0  # no coupling: n.C n = 0
        with pytest.raises(ZeroDivisionError):
            slosh_momentum(twist, t_s, inputs, rod)
