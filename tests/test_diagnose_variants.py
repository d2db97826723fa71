"""Effects fitted with several models (``CANDIDATE_VARIANTS``): a drifting external torque is named with its drift;
each variant says which simulated effect it made (the bound of the fuel errors is that one's: ``tests/test_diagnose.py``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.diagnostics.diagnose import (
    CANDIDATE_VARIANTS,
    SCAN_SHARES_TOWARD_INTERIOR,
    _fit_candidate,
    candidate_model,
    diagnose,
    simulated_variant,
)
from estimators.diagnostics.model_fit import ModelFit, best_of_grid, fit_model, nuisance_basis
from estimators.diagnostics.power import candidate_spec, effect_dof
from estimators.diagnostics.suite import DIAGNOSTIC_EXCITATION
from estimators.diagnostics.workflow import apply_effect, parameter_errors
from estimators.models.effect_models import make_terms
from estimators.models.mass_effects import Slosh
from estimators.problem import IdentificationModel
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.robots import Robot
from spaceid_gym.sim.sensors import SensorModel

TORQUE_NM = (1e-3, -2e-3, 0.0)
TORQUE_RATE_NM_S = (0.0, 0.0, 2e-4)


def _torque_episode(robot: Robot, rate: tuple[float, float, float]) -> FreeFloatingIDEnv:
    """30 s of ``robot`` with a noise-free attitude and the torque :data:`TORQUE_NM` drifting at ``rate`` (N m/s)."""
    spec = (
        f"external_torque[external_torque_Nm={';'.join(map(str, TORQUE_NM))},"
        f"external_torque_rate_Nm_s={';'.join(map(str, rate))}]"
    )
    excitation = FourierExcitation(robot.n_joints, seed=11, **DIAGNOSTIC_EXCITATION)
    sensors = SensorModel(attitude_source="exact")
    return simulate_episode(robot, 30.0, 30.0, np.zeros(3), excitation, seed=11, sensors=sensors, hidden_effects=spec)


def test_the_torque_and_slosh_terms_say_which_truth_they_made(paper6: Robot) -> None:
    """``describes``: the drifting torque term for a truth with a non-zero drift only, the constant one otherwise;
    each slosh model for its own ``slosh_model`` (unset: the spring). The drift's grid starts from the constant
    torque's fit with no drift, and the constant's from the drift's without it."""
    (constant,), (drifting,) = make_terms("external_torque", paper6), make_terms("external_torque[drift=true]", paper6)
    hidden = {"external_torque_Nm": list(TORQUE_NM), "external_torque_rate_Nm_s": list(TORQUE_RATE_NM_S)}
    assert drifting.describes(hidden) and not constant.describes(hidden)
    still = {**hidden, "external_torque_rate_Nm_s": [0.0, 0.0, 0.0]}
    assert constant.describes(still) and not drifting.describes(still)
    assert constant.describes({"external_torque_Nm": list(TORQUE_NM)})
    (spring,), (pendulum,) = make_terms("slosh", paper6), make_terms("slosh[model=pendulum]", paper6)
    assert spring.describes({"slosh_mass_kg": 5.0}) and not pendulum.describes({"slosh_mass_kg": 5.0})
    assert pendulum.describes({"slosh_model": "pendulum"}) and not spring.describes({"slosh_model": "pendulum"})
    fitted = np.arange(1.0, 7.0)
    (grid,) = drifting.grid_from_variant(fitted)
    np.testing.assert_array_equal(grid, [1, 2, 3, 4, 5, 6, 0, 0, 0])
    (back,) = constant.grid_from_variant(np.arange(1.0, 10.0))
    np.testing.assert_array_equal(back, fitted)
    assert CANDIDATE_VARIANTS["external_torque"] == ("external_torque", "external_torque[drift=true]")


def _slosh_scans(model: IdentificationModel, log, theta: np.ndarray, monkeypatch) -> tuple[ModelFit, list[list[np.ndarray]]]:  # type: ignore[no-untyped-def]
    """The spring-mass and then the pendulum fitted by ``_fit_candidate`` from a baseline at ``theta`` (gyro alone):
    the spring's fit and the two scans (every candidate each scored)."""
    baseline = dataclasses.replace(fit_model(model, log, starts=[theta])[0], theta=theta)
    basis = nuisance_basis(model.problem(log), baseline.theta, None, None)
    scans: list[list[np.ndarray]] = []

    def recorded(problem, grid, *args):  # type: ignore[no-untyped-def]
        scans.append(grid)
        return best_of_grid(problem, grid, *args)

    monkeypatch.setattr("estimators.diagnostics.diagnose.best_of_grid", recorded)
    spring = _fit_candidate(model, log, "slosh", baseline, None, None, basis)
    _fit_candidate(model, log, "slosh[model=pendulum]", baseline, None, None, basis, [spring])
    return spring, scans


def test_the_pendulum_scans_its_own_grid_and_the_spring_masss_fit(short_fuel_episode, monkeypatch) -> None:
    """The pendulum scans its own grid (every mass and frequency of the spring-mass's, each with a straight rod along
    seven axes), not only the spring's best scanned points (which ranked a tilted 37 s pendulum's frequencies wrong on
    fresh log 10755), and adds its candidates from the spring's fit (thirteen axes)."""
    ep = short_fuel_episode
    model = IdentificationModel(ep.robot, "fuel")
    start = model.problem(ep.log).parameters.nominal
    baseline_theta = fit_model(model, ep.log, starts=[start])[0].theta
    spring, scans = _slosh_scans(model, ep.log, baseline_theta, monkeypatch)
    (spring_term,) = make_terms("slosh", ep.robot)
    pendulum_term = candidate_model(model, "slosh[model=pendulum]").parameters.terms[-1]  # type: ignore[attr-defined]
    k0 = len(baseline_theta)
    own = [np.concatenate((baseline_theta, s)) for s in pendulum_term.grid(baseline_theta)]
    assert len(own) == len(Slosh.GRID_FREQUENCIES_HZ) * len(Slosh.GRID_MASS_FRACTIONS) * len(Slosh.GRID_AXES)
    expected = own + [np.concatenate((spring.theta[:k0], spring.theta[k0:], axis, [0.0])) for axis in Slosh.FINE_AXES]
    np.testing.assert_allclose(np.array(scans[1]), np.array(expected), rtol=1e-9, atol=0.0)
    n_axes = len(Slosh.GRID_AXES)
    np.testing.assert_allclose(np.array([p[: k0 + 3] for p in own[::n_axes]]), np.array(scans[0]), rtol=1e-9, atol=0.0)
    assert spring_term.grid_from_variant(spring.theta[k0:]) == []


def test_with_no_liquid_left_the_pendulum_scans_where_the_spring_mass_did(short_fuel_episode, monkeypatch) -> None:
    """A baseline with all the usable fuel consumed leaves no liquid to slosh: both models scan at points on the way
    to the interior start instead, the same points, at those points' own base unknowns, not at the baseline's."""
    ep = short_fuel_episode
    model = IdentificationModel(ep.robot, "fuel")
    problem = model.problem(ep.log)
    empty = problem.parameters.nominal.copy()
    empty[0] = problem.parameters.upper[0]  # the fuel consumed at its bound: the usable fuel
    _, scans = _slosh_scans(model, ep.log, empty, monkeypatch)
    spring_term = candidate_model(model, "slosh").parameters.terms[-1]  # type: ignore[attr-defined]
    assert spring_term.grid(empty) == [] and len(scans[0]) == len(SCAN_SHARES_TOWARD_INTERIOR) * len(spring_term.grid())
    k0 = len(empty)
    assert all(not np.array_equal(p[:k0], empty) for p in scans[0])
    n_axes = len(Slosh.GRID_AXES)
    pendulum_own = scans[1][: len(scans[0]) * n_axes]
    np.testing.assert_allclose(np.array([p[: k0 + 3] for p in pendulum_own[::n_axes]]), np.array(scans[0]), rtol=1e-9, atol=0.0)


def test_the_power_tests_the_model_that_made_the_effect(paper6: Robot) -> None:
    """The expected power and the separation test a drifting torque with the drifting term (nine unknowns), a constant
    one with the constant term (six), as they test a pendulum slosh with the pendulum."""
    model = IdentificationModel(paper6, "fuel")
    drifting = {"hidden_effects": {"external_torque_Nm": list(TORQUE_NM), "external_torque_rate_Nm_s": list(TORQUE_RATE_NM_S)}}
    constant = {"hidden_effects": {"external_torque_Nm": list(TORQUE_NM)}}
    assert candidate_spec(paper6, "external_torque", drifting) == "external_torque[drift=true]"
    assert candidate_spec(paper6, "external_torque", constant) == "external_torque"
    assert effect_dof(model, "external_torque", drifting) == 9 and effect_dof(model, "external_torque", constant) == 6
    assert candidate_spec(paper6, "slosh", {"hidden_effects": {"slosh_model": "pendulum", "slosh_mass_kg": 5.0}}) == (
        "slosh[model=pendulum]"
    )
    assert simulated_variant(paper6, "external_torque", {"initial_momentum_Nms": [0.1, 0.0, 0.0]}) is None


def test_a_drifting_torque_is_named_with_its_drift_and_leaves_the_noise(quick3: Robot) -> None:
    """A torque that drifts (2e-4 N m/s, as a gravity gradient turning with the orbit, larger) over 30 s with a
    noise-free attitude: the constant torque alone leaves 1.54 x the gyro noise (design run), the drifting variant the
    noise; the verdict is the torque with its drift, whose fitted rate is the simulated one within 5 %, and the fuel
    errors after adding it are within 3 Cramér-Rao std (0.15 on the design run)."""
    env = _torque_episode(quick3, TORQUE_RATE_NM_S)
    log, truth = env.measurement_log(), env.truth()
    noise = env.sensors.gyro_std_rad_s(env.control_period_s)
    model = IdentificationModel(quick3, "fuel")
    d = diagnose(model, log)
    assert d.verdict == "external_torque", d.reason
    assert d.best is not None and d.best.spec == "external_torque[drift=true]"
    assert d.best.residual_rms_rad_s / noise < 1.02
    rate = np.asarray(d.best.physical["external_torque_rate_Nm_s"])
    np.testing.assert_allclose(rate, TORQUE_RATE_NM_S, atol=0.05 * max(TORQUE_RATE_NM_S))
    extended, estimate = apply_effect(model, log, d.verdict, d)
    assert extended.effects == ("external_torque[drift=true]",)
    errors = parameter_errors(extended, log, estimate, truth)
    assert errors is not None and np.all(np.abs(errors.z) < 3.0), errors.z


def test_a_constant_torque_keeps_the_constant_model(quick3: Robot) -> None:
    """The same torque without drift: the drift's three unknowns do not pay their BIC, the constant torque is named."""
    env = _torque_episode(quick3, (0.0, 0.0, 0.0))
    d = diagnose(IdentificationModel(quick3, "fuel"), env.measurement_log())
    assert d.verdict == "external_torque", d.reason
    assert d.best is not None and d.best.spec == "external_torque"
