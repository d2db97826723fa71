"""The analytic Jacobians of the prediction with effect terms against central differences of the prediction itself."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.problem as problem_module
from estimators.least_squares import interior_start
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
