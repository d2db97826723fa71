"""Hidden physical effects on the truth side: settings, spec strings and the simulator's physics.

Independent references: pinocchio's centroidal momentum, kinetic energy, forward kinematics and RNEA
(Newton-Euler) on the simulated motion; the closed-form small oscillations of the base + slosh
two-body problem (spring-mass and pendulum); the fuel-removal model for the slosh mass; a finer time
grid for the gyro delay; pinocchio's own ``Inertia.FromDynamicParameters`` and the eq. 8 map for the
payload.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from scipy import special

from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.effects.draws import (
    DEFAULT_MAGNITUDES,
    ORBITAL_RATE_RAD_S,
    PAYLOAD_BOX_M,
    PAYLOAD_DISTANCE_M,
    SLOSH_PERIOD_RANGE_S,
    draw_effect,
    draw_slosh,
    remaining_liquid_kg,
)
from spaceid_gym.effects.settings import EFFECT_NAMES, HiddenEffects
from spaceid_gym.effects.spec_strings import parse_hidden_effects
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import load_dataset
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.inertia import RigidBodyInertia, skew
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import Robot
from spaceid_gym.sim.simulator import FreeFloatingSimulator
from spaceid_gym.sim.state import FreeFloatingState

DT = 0.02
TANK = np.array([0.1, 0.05, -0.1])  # quick3 tank position bf (m, from the full-tank CoM)
FUEL = 8.0  # kg consumed (quick3)
SLOSH_KG = 5.0
TILTED_AXIS = (2.0 / 3.0, -1.0 / 3.0, 2.0 / 3.0)  # a pendulum axis off the base axes (unit, base frame)
MODELS = ("spring", "pendulum")


def _commands(robot: Robot, steps: int, seed: int, hold: int = 10, scale: float = 1.0) -> np.ndarray:
    """Piecewise-constant random rate commands (rad/s) changing every ``hold`` steps."""
    rng = np.random.default_rng(seed)
    levels = scale * rng.uniform(-1.0, 1.0, size=(steps // hold + 1, robot.n_joints)) * robot.rate_limit_rad_s
    return np.repeat(levels, hold, axis=0)[:steps]


def _slosh(zeta: float = 0.05, frequency_hz: float = 0.3, model: str = "spring", **pendulum: object) -> HiddenEffects:
    """``SLOSH_KG`` of slosh; the spring model leaves ``slosh_model`` unset (the settings before the pendulum)."""
    return HiddenEffects(
        slosh_mass_kg=SLOSH_KG,
        slosh_frequency_hz=frequency_hz,
        slosh_damping_ratio=zeta,
        slosh_model=None if model == "spring" else model,
        **pendulum,
    )


def _displaced(model: str, x_m: np.ndarray) -> dict[str, np.ndarray]:
    """``reset`` keywords displacing the slosh mass: the spring's ``slosh_m = x``, the pendulum's angles ``x[:2] / L``."""
    return {"slosh_m": x_m} if model == "spring" else {"slosh_angles_rad": x_m[:2] / 0.3}


def _mass_point_jacobian(sim: FreeFloatingSimulator, state: FreeFloatingState) -> np.ndarray:
    """pinocchio's Jacobian (3, s) of the slosh mass's position (inertial axes) in the s slosh joint rates."""
    model, data = sim.model, sim.model.createData()
    joint = model.njoints - 1  # the slosh joints come last; the mass is on the last
    pin.computeJointJacobians(model, data, state.pinocchio_configuration())
    jacobian = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
    lever = data.oMi[joint].rotation @ model.inertias[joint].lever
    point = jacobian[:3] - skew(lever) @ jacobian[3:]
    return point[:, model.nv - sim.slosh.n_coordinates :]


def _joint_force(sim: FreeFloatingSimulator, state: FreeFloatingState) -> np.ndarray:
    """The restoring and damping generalized force on the slosh joints (N, or N m for the pendulum), independently:
    the spring's ``-k x - c dx``; for the pendulum the force on the mass, ``k L a`` (the effective acceleration ``k L /
    m`` along the rest axis ``a``) minus ``c`` times its velocity relative to the base, mapped by pinocchio's
    Jacobian of the mass point."""
    body = sim.slosh
    x, v = state.slosh_coordinates
    if not body.is_pendulum:
        return -body.stiffness_n_m * x - body.damping_n_s_m * v
    jacobian = _mass_point_jacobian(sim, state)
    axis_world = state.rot_wb @ body.rot_base_hinge[:, 2]
    return jacobian.T @ (body.stiffness_n_m * body.length_m * axis_world - body.damping_n_s_m * (jacobian @ v))


def _potential(sim: FreeFloatingSimulator, state: FreeFloatingState) -> float:
    """The restoring law's potential energy (J): the spring's ``k |x|^2 / 2``; the pendulum's ``k L^2 (1 - a.n)``
    (``n`` the rod's direction), i.e. ``-k L a.x`` with ``x`` the mass's displacement from rest."""
    body = sim.slosh
    if not body.is_pendulum:
        return 0.5 * body.stiffness_n_m * float(state.slosh_m @ state.slosh_m)
    return -body.stiffness_n_m * body.length_m * float(body.rot_base_hinge[:, 2] @ state.slosh_m)


def _sim(robot: Robot, effects: HiddenEffects | None = None, substeps: int = 1) -> FreeFloatingSimulator:
    base = base_after_fuel(robot.base_full, FUEL, TANK)
    return FreeFloatingSimulator(robot, base, substeps=substeps, effects=effects, tank_point_m=robot.base_full.com_m + TANK)


def _centroidal(sim: FreeFloatingSimulator, state: FreeFloatingState, data: pin.Data) -> np.ndarray:
    """pinocchio's centroidal momentum ``[P; L_G]`` (inertial axes) of the simulated state."""
    h = pin.computeCentroidalMomentum(sim.model, data, state.pinocchio_configuration(), state.pinocchio_velocity())
    return np.concatenate((h.linear, h.angular))


def _arm_momentum(sim: FreeFloatingSimulator, state: FreeFloatingState, data: pin.Data) -> float:
    """Size of the momentum the arm's motion carries with the base held still (the problem's scale)."""
    v = state.pinocchio_velocity()
    v[:6] = 0.0
    h = pin.computeCentroidalMomentum(sim.model, data, state.pinocchio_configuration(), v)
    return float(np.linalg.norm(np.concatenate((h.linear, h.angular))))


# ---------------------------------------------------------------------- settings
SLOSH3 = {"slosh_mass_kg": 3.0, "slosh_frequency_hz": 0.3, "slosh_damping_ratio": 0.05}


def test_draws_have_the_documented_sizes(paper6: Robot) -> None:
    rng = np.random.default_rng(0)
    drawn = {name: draw_effect(name, rng, paper6, 40.0) for name in EFFECT_NAMES}
    for name, effects in drawn.items():
        assert effects.names == (name,)
    assert np.linalg.norm(drawn["initial_momentum"].initial_momentum_Nms) == pytest.approx(0.2)
    assert np.linalg.norm(drawn["gyro_bias"].gyro_bias_rad_s) == pytest.approx(10.0 * math.pi / 180.0 / 3600.0)
    assert np.linalg.norm(drawn["gyro_scale"].gyro_scale_misalignment) == pytest.approx(1e-3)
    assert drawn["delay"].delay_s == 0.02
    torque = drawn["external_torque"]
    assert np.linalg.norm(torque.external_torque_Nm) == pytest.approx(5e-4)
    assert np.linalg.norm(torque.external_torque_rate_Nm_s) == pytest.approx(2.0 * ORBITAL_RATE_RAD_S * 5e-4)
    # slosh: 30 % of the remaining usable fuel (25 % of 550 kg minus 40 kg consumed)
    assert drawn["slosh"].slosh_mass_kg == pytest.approx(0.3 * (0.25 * 550.0 - 40.0))
    assert remaining_liquid_kg(paper6, 40.0) == pytest.approx(97.5)
    # payload: a 10 kg uniform box 0.15 m out, rotated: its principal moments are the box's
    body = RigidBodyInertia.from_params10(drawn["payload"].array("payload_params10"))
    a, b, c = PAYLOAD_BOX_M
    box = 10.0 / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert body.mass_kg == pytest.approx(10.0)
    assert np.linalg.norm(body.com_m) == pytest.approx(PAYLOAD_DISTANCE_M)
    np.testing.assert_allclose(np.linalg.eigvalsh(body.inertia_com_kgm2), np.sort(box), rtol=1e-12)
    # magnitude overrides the size, in the effect's own unit
    assert np.linalg.norm(draw_effect("gyro_bias", rng, paper6, 40.0, magnitude=1e-4).gyro_bias_rad_s) == pytest.approx(1e-4)
    assert draw_effect("slosh", rng, paper6, 40.0, magnitude=12.0).slosh_mass_kg == 12.0
    assert set(DEFAULT_MAGNITUDES) == set(EFFECT_NAMES)


def test_directions_are_uniform_on_the_sphere(quick3: Robot) -> None:
    rng = np.random.default_rng(1)
    n = 4000
    v = np.array([draw_effect("gyro_bias", rng, quick3, 0.0, magnitude=1.0).gyro_bias_rad_s for _ in range(n)])
    # uniform on the sphere: mean 0 (std 1/sqrt(3n) per axis), second moment I/3 (std ~ 0.3/sqrt(n))
    assert np.abs(v.mean(axis=0)).max() < 5.0 / math.sqrt(3 * n)
    np.testing.assert_allclose(v.T @ v / n, np.eye(3) / 3.0, atol=5 * 0.3 / math.sqrt(n))


def test_dict_round_trip_names_and_combine() -> None:
    effects = HiddenEffects(
        gyro_bias_rad_s=[1e-5, 0.0, -2e-5],
        gyro_scale_misalignment=np.eye(3) * 1e-4,
        delay_s=0.03,
        external_torque_Nm=(1e-4, 0.0, 0.0),
    )
    assert effects.names == ("gyro_bias", "delay", "external_torque", "gyro_scale")
    text = json.dumps(effects.to_dict())
    assert HiddenEffects.from_dict(json.loads(text)) == effects
    assert not HiddenEffects() and HiddenEffects().names == ()
    both = effects.combine(HiddenEffects(initial_momentum_Nms=(0.0, 0.1, 0.0)))
    assert both.names == ("initial_momentum", "gyro_bias", "delay", "external_torque", "gyro_scale")
    with pytest.raises(SpaceIdInputError, match="delay set twice"):
        effects.combine(HiddenEffects(delay_s=0.01))
    with pytest.raises(SpaceIdInputError, match="unknown keys"):
        HiddenEffects.from_dict({"delay": 0.1})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gyro_bias_rad_s": (1.0, 2.0)}, "'gyro_bias_rad_s': expected 3 finite numbers"),
        ({"delay_s": -0.01}, "'delay_s': expected >= 0 s"),
        ({"slosh_mass_kg": 3.0}, "slosh_mass_kg, slosh_frequency_hz and slosh_damping_ratio together"),
        ({"slosh_mass_kg": 3.0, "slosh_frequency_hz": 0.0, "slosh_damping_ratio": 0.1}, "'slosh_frequency_hz': expected > 0"),
        ({**SLOSH3, "slosh_frequency_hz": 5.5}, "'slosh_frequency_hz': expected > 0 and <= 5 Hz, got 5.5"),
        ({**SLOSH3, "slosh_damping_ratio": 2.0}, "'slosh_damping_ratio': expected >= 0 and < 2, got 2.0"),
        ({**SLOSH3, "slosh_damping_ratio": -0.1}, "'slosh_damping_ratio': expected >= 0 and < 2"),
        ({**SLOSH3, "slosh_model": "swing"}, "'slosh_model': expected one of 'spring', 'pendulum', got 'swing'"),
        ({**SLOSH3, "slosh_model": "pendulum", "slosh_length_m": 0.0}, "'slosh_length_m': expected > 0 m"),
        ({**SLOSH3, "slosh_model": "pendulum", "slosh_axis": (0, 0, 0)}, "'slosh_axis': expected a unit vector"),
        ({**SLOSH3, "slosh_model": "pendulum", "slosh_axis": (0, 0.1, 1)}, "'slosh_axis': expected a unit vector"),
        ({**SLOSH3, "slosh_model": "pendulum", "slosh_axis": (0, 1)}, "'slosh_axis': expected 3 finite numbers"),
        ({**SLOSH3, "slosh_length_m": 0.3}, "'slosh_length_m': expected no value unless slosh_model is 'pendulum'"),
        ({**SLOSH3, "slosh_model": "spring", "slosh_axis": (0, 0, 1)}, "'slosh_axis': expected no value unless"),
        ({"slosh_model": "pendulum"}, "slosh_model given without slosh_mass_kg"),
        ({"payload_params10": [1.0, 0, 0, 0, 1.0, 0, 0.1, 0, 0, 0.1]}, "triangle inequality"),
        ({"gyro_scale_misalignment": [[0.0] * 3] * 2}, "'gyro_scale_misalignment': expected 3x3"),
    ],
)
def test_bad_settings_are_named(kwargs: dict, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        HiddenEffects(**kwargs)


def test_pendulum_settings_default_round_trip_and_combine() -> None:
    """The pendulum's rod and axis default when unset and are written; the spring's truth keeps its three fields."""
    pendulum = HiddenEffects(**SLOSH3, slosh_model="pendulum")
    assert pendulum.slosh_length_m == 0.3 and pendulum.slosh_axis == (0.0, 0.0, 1.0)
    assert pendulum.names == ("slosh",)
    written = pendulum.to_dict()
    assert written == {**SLOSH3, "slosh_model": "pendulum", "slosh_length_m": 0.3, "slosh_axis": [0.0, 0.0, 1.0]}
    assert HiddenEffects.from_dict(json.loads(json.dumps(written))) == pendulum
    tilted = HiddenEffects(**SLOSH3, slosh_model="pendulum", slosh_length_m=0.5, slosh_axis=np.array(TILTED_AXIS))
    assert HiddenEffects.from_dict(json.loads(json.dumps(tilted.to_dict()))) == tilted
    assert HiddenEffects(delay_s=0.01).combine(tilted) == dataclasses.replace(tilted, delay_s=0.01)
    assert HiddenEffects(**SLOSH3).to_dict() == SLOSH3  # the spring: unchanged truth.json
    with pytest.raises(SpaceIdInputError, match="'slosh_model': expected one of"):
        HiddenEffects.from_dict({**written, "slosh_model": "Pendulum"})


def test_spec_strings(paper6: Robot) -> None:
    spec = "slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"
    effects = parse_hidden_effects(spec, np.random.default_rng(2), paper6, 40.0)
    assert effects.names == ("gyro_bias", "slosh", "delay")
    assert effects.delay_s == 0.03 and np.linalg.norm(effects.gyro_bias_rad_s) == pytest.approx(1e-4)
    assert effects == parse_hidden_effects(spec, np.random.default_rng(2), paper6, 40.0)  # same seed, same draw
    assert effects != parse_hidden_effects(spec, np.random.default_rng(3), paper6, 40.0)
    vector = parse_hidden_effects(
        "external_torque[external_torque_Nm=1e-4;0;-2e-4, external_torque_rate_Nm_s=0;0;0], slosh[slosh_damping_ratio=0.1]",
        np.random.default_rng(0),
        paper6,
        40.0,
    )
    assert vector.external_torque_Nm == (1e-4, 0.0, -2e-4) and vector.external_torque_rate_Nm_s == (0.0, 0.0, 0.0)
    assert vector.slosh_damping_ratio == 0.1 and vector.slosh_frequency_hz == 0.3


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("slosh,wobble", "unknown effect 'wobble'; expected one of initial_momentum, gyro_bias, payload, slosh"),
        ("delay[dt=0.1]", "expected keys magnitude, delay_s"),
        ("delay[delay_s=fast]", "expected a number or numbers separated by ';'"),
        ("gyro_bias[gyro_bias_rad_s=1;2]", "expected 3 numbers"),
        ("delay,delay", "effect 'delay' given twice"),
        ("slosh[magnitude=500]", "exceeds the remaining liquid"),
        ("delay[magnitude=-1]", "magnitude must be a finite number >= 0"),
        ("slosh[slosh_model=swing]", "slosh[slosh_model=...] expected one of spring, pendulum, got 'swing'"),
        ("slosh[slosh_model=pendulum,slosh_axis=1;1;0]", "'slosh_axis': expected a unit vector"),
        ("slosh[slosh_model=pendulum,slosh_axis=0;1]", "slosh[slosh_axis=...] expected 3 numbers separated by ';'"),
        ("slosh[slosh_model=pendulum,slosh_length_m=-0.3]", "'slosh_length_m': expected > 0 m, got -0.3"),
        ("slosh[slosh_model=pendulum,slosh_length_m=short]", "slosh[slosh_length_m=...] expected a number"),
        ("slosh[slosh_frequency_hz=0]", "'slosh_frequency_hz': expected > 0 and <= 5 Hz, got 0.0"),
        ("slosh[slosh_damping_ratio=3]", "'slosh_damping_ratio': expected >= 0 and < 2, got 3.0"),
        ("slosh[slosh_length_m=0.3]", "'slosh_length_m': expected no value unless slosh_model is 'pendulum'"),
        ("", "expected a spec"),
    ],
)
def test_bad_spec_strings_are_named(paper6: Robot, spec: str, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_hidden_effects(spec, np.random.default_rng(0), paper6, 40.0)


def test_draw_slosh_chooses_the_model_and_draws_the_period(paper6: Robot) -> None:
    rng = np.random.default_rng(0)
    spring = draw_slosh(rng, paper6, 40.0)
    assert spring == draw_effect("slosh", rng, paper6, 40.0) and spring.slosh_model is None  # the default, as before
    assert spring.slosh_frequency_hz == 0.3 and spring.slosh_mass_kg == pytest.approx(0.3 * 97.5)
    pendulum = draw_slosh(rng, paper6, 40.0, mass_kg=37.0, model="pendulum", period_s=15.0)
    assert pendulum.slosh_model == "pendulum" and pendulum.slosh_length_m == 0.3 and pendulum.slosh_axis == (0.0, 0.0, 1.0)
    assert pendulum.slosh_mass_kg == 37.0 and pendulum.slosh_frequency_hz == pytest.approx(1.0 / 15.0)
    n = 4000
    drawn = [draw_slosh(rng, paper6, 40.0, model="pendulum", period_s=SLOSH_PERIOD_RANGE_S) for _ in range(n)]
    logs = np.log([1.0 / d.slosh_frequency_hz for d in drawn])
    low, high = np.log(SLOSH_PERIOD_RANGE_S)
    assert SLOSH_PERIOD_RANGE_S == (2.0, 50.0) and low <= logs.min() and logs.max() <= high
    # log-uniform: mean (low + high) / 2 (std (high - low) / sqrt(12 n)), std (high - low) / sqrt(12)
    assert abs(logs.mean() - 0.5 * (low + high)) < 5.0 * (high - low) / math.sqrt(12.0 * n)
    assert logs.std() == pytest.approx((high - low) / math.sqrt(12.0), rel=0.05)
    assert {d.slosh_model for d in drawn} == {"pendulum"}
    for kwargs, message in (
        ({"model": "swing"}, "model 'swing' unknown; expected one of spring, pendulum"),
        ({"period_s": (5.0, 2.0)}, "period range expected 0 < low <= high s"),
        ({"period_s": -1.0}, "period expected > 0 s"),
        ({"period_s": 0.1}, "'slosh_frequency_hz': expected > 0 and <= 5 Hz"),
        ({"mass_kg": 98.0}, "magnitude 98 kg exceeds the remaining liquid 97.5 kg"),
        ({"model": "pendulum", "axis_base": (1.0, 1.0, 0.0)}, "'slosh_axis': expected a unit vector"),
    ):
        with pytest.raises(SpaceIdInputError, match=re.escape(message)):
            draw_slosh(rng, paper6, 40.0, **kwargs)


def test_pendulum_spec_on_the_command_line_and_its_log_conserves_momentum(paper6: Robot, tmp_path: Path) -> None:
    """The other simulator's pendulum (37 kg, 0.3 m, about 15 s) from a spec string: truth.json holds it, and the
    env's log of it conserves the system's linear and angular momentum (no external torque) with the arm moving."""
    spec = "slosh[slosh_model=pendulum,slosh_length_m=0.3,slosh_frequency_hz=0.067,magnitude=37]"
    assert main(["simulate", "--duration", "1", "--seed", "1", "--hidden-effects", spec, "--out", str(tmp_path / "run")]) == 0
    truth = load_dataset(tmp_path / "run").truth["hidden_effects"]
    expected = {"slosh_mass_kg": 37.0, "slosh_frequency_hz": 0.067, "slosh_damping_ratio": 0.05}
    assert truth == {**expected, "slosh_model": "pendulum", "slosh_length_m": 0.3, "slosh_axis": [0.0, 0.0, 1.0]}
    env = FreeFloatingIDEnv(paper6, hidden_effects=spec)
    env.reset(seed=5, options={"fuel_consumed_kg": 40.0})
    sim = env.simulator
    assert sim.slosh is not None and sim.slosh.is_pendulum and env.truth()["hidden_effects"] == truth
    data = sim.model.createData()
    h0 = _centroidal(sim, sim.state, data)
    worst, scale = 0.0, 0.0
    for action in _commands(paper6, 500, seed=9, hold=25) / paper6.rate_limit_rad_s:
        env.step(action.astype(np.float32))
        worst = max(worst, float(np.linalg.norm(_centroidal(sim, sim.state, data) - h0)))
        scale = max(scale, _arm_momentum(sim, sim.state, data))
    assert np.linalg.norm(h0) < 1e-15 and scale > 1.0 and np.abs(sim.state.slosh_angles_rad).max() > 1e-3
    assert worst / scale < 1e-12


# ---------------------------------------------------------------------- initial momentum and external torque
def test_initial_momentum_is_the_systems_momentum(quick3: Robot) -> None:
    momentum = np.array([0.3, -0.2, 0.5])
    sim = _sim(quick3, HiddenEffects(initial_momentum_Nms=momentum))
    data = sim.model.createData()
    state = sim.state
    assert np.linalg.norm(state.omega_base_body) > 1e-3  # the base spins from the start
    for u in _commands(quick3, 300, seed=1):
        state = sim.step(u, DT)
        np.testing.assert_allclose(_centroidal(sim, state, data), np.concatenate((np.zeros(3), momentum)), rtol=0, atol=1e-14)


def test_external_torque_changes_the_momentum_at_its_rate(quick3: Robot) -> None:
    """d/dt of pinocchio's centroidal angular momentum (inertial) equals the torque; linear momentum stays zero."""
    tau0, tau1 = np.array([2e-3, -1e-3, 3e-3]), np.array([-4e-5, 2e-5, 1e-5])
    sim = _sim(
        quick3, HiddenEffects(initial_momentum_Nms=(0.1, 0.0, -0.1), external_torque_Nm=tau0, external_torque_rate_Nm_s=tau1)
    )
    data = sim.model.createData()
    h = [_centroidal(sim, sim.state, data)]
    for u in _commands(quick3, 500, seed=2):
        h.append(_centroidal(sim, sim.step(u, DT), data))
    h = np.array(h)
    t = DT * np.arange(len(h))
    assert np.abs(h[:, :3]).max() < 1e-15
    expected = np.array([0.1, 0.0, -0.1]) + np.outer(t, tau0) + np.outer(0.5 * t * t, tau1)
    np.testing.assert_allclose(h[:, 3:], expected, rtol=0, atol=1e-13)
    rate = (h[2:, 3:] - h[:-2, 3:]) / (2 * DT)  # central differences: exact for a quadratic, up to round-off
    torque = tau0 + np.outer(t[1:-1], tau1)
    assert np.abs(rate - torque).max() < 1e-9 * np.abs(torque).max()


def _newton_euler_residual(
    sim: FreeFloatingSimulator, command: np.ndarray, h: float = 1e-3
) -> tuple[np.ndarray, FreeFloatingState]:
    """Generalized forces (RNEA) of the simulated motion at a state, accelerations by central differences."""
    before = sim.state
    mid = sim.step(command, h)
    after = sim.step(command, h)
    acc = (after.pinocchio_velocity() - before.pinocchio_velocity()) / (2 * h)
    data = sim.model.createData()
    return pin.rnea(sim.model, data, mid.pinocchio_configuration(), mid.pinocchio_velocity(), acc), mid


@pytest.mark.parametrize("slosh", [None, *MODELS])
def test_external_torque_is_the_base_wrench_newton_euler(quick3: Robot, slosh: str | None) -> None:
    """RNEA of the simulated motion: the base wrench is the torque (base axes); with slosh, the restoring and damping
    force on its joints."""
    torque = np.array([0.5, -0.3, 0.8])  # large, so the finite-difference error stays far below it
    effects = HiddenEffects(external_torque_Nm=torque)
    sim = _sim(quick3, effects.combine(_slosh(zeta=0.1, model=slosh)) if slosh else effects)
    sim.reset(rot_wb=pin.exp3(np.array([0.3, -0.5, 0.2])))
    for u in _commands(quick3, 100, seed=3, hold=100):
        sim.step(u, DT)
    tau, mid = _newton_euler_residual(sim, 0.5 * quick3.rate_limit_rad_s)
    expected = np.concatenate((np.zeros(3), mid.rot_wb.T @ torque))  # a pure torque, base axes
    assert np.linalg.norm(tau[6:9]) > 1.0  # the joints do work
    assert np.linalg.norm(tau[:6] - expected) < 1e-4 * np.linalg.norm(torque)
    assert np.linalg.norm(tau[:6]) > 0.9 * np.linalg.norm(torque)
    if slosh:
        spring = _joint_force(sim, mid)
        assert np.linalg.norm(spring) > 1e-3
        assert np.linalg.norm(tau[9:] - spring) < 1e-5 * np.linalg.norm(spring)


def _convergence_ratios(final: list[np.ndarray], reference: np.ndarray) -> list[float]:
    errors = [float(np.linalg.norm(f - reference)) for f in final]
    assert errors[0] > 1e-12  # the test measures something
    return [errors[0] / errors[1], errors[1] / errors[2]]


@pytest.mark.parametrize("slosh", [None, *MODELS])
def test_integrator_stays_fourth_order_with_torque_and_slosh(quick3: Robot, slosh: str | None) -> None:
    """The stages use the momentum (and slosh state) at their own times: the error falls as h^4."""
    effects = HiddenEffects(
        initial_momentum_Nms=(0.5, -0.3, 0.8), external_torque_Nm=(0.05, 0.02, -0.04), external_torque_rate_Nm_s=(0.0, 0.01, 0.0)
    )
    if slosh:
        effects = effects.combine(_slosh(frequency_hz=0.5, model=slosh))
    commands = _commands(quick3, 40, seed=4, hold=4)

    def final(substeps: int) -> np.ndarray:
        sim = _sim(quick3, effects, substeps=substeps)
        sim.reset(**(_displaced(slosh, np.array([0.02, -0.01, 0.01])) if slosh else {}))
        for u in commands:
            state = sim.step(u, 0.1)
        return np.concatenate((state.rot_wb.ravel(), [] if state.slosh_m is None else state.slosh_coordinates[0]))

    # the pendulum is pre-asymptotic at h = 0.1 s (ratios 11.3, 13.8, 15.0 from 1 substep): one halving later
    levels = (2, 4, 8) if slosh == "pendulum" else (1, 2, 4)
    assert min(_convergence_ratios([final(s) for s in levels], final(8 * levels[-1]))) > 12.0  # 2^4 = 16


# ---------------------------------------------------------------------- slosh
@pytest.mark.parametrize("model", MODELS)
def test_slosh_mass_is_taken_from_the_base_at_the_tank(quick3: Robot, model: str) -> None:
    """At rest the mass distribution is the rigid one: rigid base + slosh mass = the base after fuel removal."""
    sim = _sim(quick3, _slosh(model=model))
    rigid = sim.model.inertias[1]
    expected_rigid = base_after_fuel(quick3.base_full, FUEL + SLOSH_KG, TANK)  # more fuel gone from the same tank
    np.testing.assert_allclose(rigid.mass, expected_rigid.mass_kg, rtol=1e-14)
    np.testing.assert_allclose(rigid.lever, expected_rigid.com_m, atol=1e-14)
    np.testing.assert_allclose(rigid.inertia, expected_rigid.inertia_com_kgm2, atol=1e-12)
    point = pin.Inertia(SLOSH_KG, quick3.base_full.com_m + TANK, np.zeros((3, 3)))
    whole, base = rigid + point, base_after_fuel(quick3.base_full, FUEL, TANK)
    np.testing.assert_allclose(whole.lever, base.com_m, atol=1e-14)
    np.testing.assert_allclose(whole.inertia, base.inertia_com_kgm2, atol=1e-12)
    # the same base twist as without slosh while the slosh mass rests
    rigid_sim = _sim(quick3)
    momentum = np.array([0.0, 0.0, 0.0, 0.4, -0.1, 0.2])
    state = sim.reset(momentum_world=momentum)
    np.testing.assert_allclose(state.v_base_body, rigid_sim.reset(momentum_world=momentum).v_base_body, atol=1e-15)
    np.testing.assert_allclose(
        state.composite_inertia.toDynamicParameters(), rigid_sim.state.composite_inertia.toDynamicParameters()
    )
    # an empty tank has nothing to slosh: no extra body
    empty = draw_effect("slosh", np.random.default_rng(0), quick3, 0.25 * quick3.base_full.mass_kg)
    assert empty.slosh_mass_kg == 0.0 and empty.names == ("slosh",)
    assert _sim(quick3, empty).slosh is None and _sim(quick3, empty).model.nq == quick3.model.nq


@pytest.mark.parametrize(("model", "axis"), [("spring", None), ("pendulum", None), ("pendulum", TILTED_AXIS)])
def test_slosh_conserves_momentum_with_the_arm_moving(quick3: Robot, model: str, axis: tuple[float, ...] | None) -> None:
    sim = _sim(quick3, _slosh(model=model, **({} if axis is None else {"slosh_axis": axis})))
    data = sim.model.createData()
    h0 = _centroidal(sim, sim.reset(momentum_world=np.array([0.0, 0.0, 0.0, 0.2, -0.1, 0.3])), data)
    worst, scale = 0.0, 0.0
    for u in _commands(quick3, 1000, seed=5):
        state = sim.step(u, DT)
        worst = max(worst, float(np.linalg.norm(_centroidal(sim, state, data) - h0)))
        scale = max(scale, _arm_momentum(sim, state, data))
    assert scale > 0.5 and np.abs(state.slosh_m).max() > 1e-4  # the arm and the slosh mass really moved
    assert worst / scale < 1e-12


@pytest.mark.parametrize(("model", "angles_rad"), [("spring", None), ("pendulum", None), ("pendulum", (0.9, -0.7))])
def test_slosh_satisfies_newton_euler(quick3: Robot, model: str, angles_rad: tuple[float, float] | None) -> None:
    """RNEA of the simulated motion: no base wrench, the restoring and damping force (pendulum: torque) on the slosh
    joints, also for a pendulum at large angles (0.04 s after its start at 0.9 and -0.7 rad from rest)."""
    sim = _sim(quick3, _slosh(zeta=0.1, model=model, **({"slosh_axis": TILTED_AXIS} if model == "pendulum" else {})))
    steps = 150
    if angles_rad is not None:
        sim.reset(slosh_angles_rad=np.array(angles_rad))
        steps = 2  # still near the start (the damping brings it to 15 deg by 3 s)
    for u in _commands(quick3, steps, seed=6, hold=150):
        sim.step(u, DT)
    tau, mid = _newton_euler_residual(sim, -0.6 * quick3.rate_limit_rad_s)
    spring = _joint_force(sim, mid)
    assert np.linalg.norm(spring) > 1e-3
    assert np.linalg.norm(tau[:6]) < 1e-5 * np.linalg.norm(tau[6:9])
    assert np.linalg.norm(tau[9:] - spring) < 1e-5 * np.linalg.norm(spring)


@pytest.mark.parametrize(("model", "start"), [("spring", None), ("pendulum", None), ("pendulum", (1.1, -0.8))])
def test_slosh_energy_is_conserved_without_damping_at_fourth_order(
    quick3: Robot, model: str, start: tuple[float, float] | None
) -> None:
    """Arm locked, no damping: kinetic (pinocchio) + the restoring law's potential (:func:`_potential`) is constant up
    to the integrator's error; the pendulum also from large angles (1.1 and -0.8 rad; there from four steps a sample)."""
    errors = []
    for substeps in (1, 2, 4) if start is None else (4, 8, 16):
        sim = _sim(quick3, _slosh(zeta=0.0, model=model), substeps=substeps)
        data = sim.model.createData()

        def energy(state: FreeFloatingState, sim: FreeFloatingSimulator = sim, data: pin.Data = data) -> float:
            kinetic = pin.computeKineticEnergy(sim.model, data, state.pinocchio_configuration(), state.pinocchio_velocity())
            return kinetic + _potential(sim, state)

        momentum = np.array([0.0, 0.0, 0.0, 2.0, -1.0, 1.5])
        displaced = _displaced(model, np.array([0.03, -0.02, 0.01])) if start is None else {"slosh_angles_rad": np.array(start)}
        state = sim.reset(momentum_world=momentum, **displaced)
        e0 = energy(state)
        for _ in range(50):
            state = sim.step(np.zeros(3), 0.2)
        assert np.linalg.norm(state.omega_base_body) > 0.1  # the base tumbles while the mass sloshes
        errors.append(abs(energy(state) - e0) / e0)
    assert errors[2] < 1e-6
    assert min(errors[0] / errors[1], errors[1] / errors[2]) > 12.0  # at least fourth order (RK4 energy: ~32)


@pytest.mark.parametrize("zeta", [0.0, 0.05])
def test_slosh_small_oscillations_match_the_two_body_closed_form(quick3: Robot, zeta: float) -> None:
    """Arm locked, zero momentum: each mode's frequency and decay equal the linearised base + slosh problem.

    Linearised momentum balance of the rigid part (mass M, CoM c, inertia J about c) and the slosh
    mass m at r = anchor - c with absolute velocity u: ``M v_c = -m u``, ``J w = -m r x u``, so
    ``dx = u - v_c - w x r = A u`` with ``A = (1 + m/M) E - m [r]x J^-1 [r]x``. With
    ``m du/dt = -k x - c dx``: ``ddx = -(k/m) A x - (c/m) A dx``; mode i (eigenvalue l_i of A):
    ``w_i = sqrt(k l_i / m)``, damping ratio ``zeta sqrt(l_i)``.
    """
    effects = _slosh(zeta=zeta)
    a_matrix, rigid_kg = _two_body_matrix(quick3, FUEL, TANK, SLOSH_KG)
    eigenvalues, modes = np.linalg.eigh(a_matrix)
    stiffness = effects.slosh_stiffness_damping()[0]
    dt = 0.05
    for lam, mode in zip(eigenvalues, modes.T, strict=True):
        sim = _sim(quick3, effects, substeps=4)
        sim.reset(slosh_m=1e-5 * mode)
        x = np.array([sim.state.slosh_m @ mode] + [sim.step(np.zeros(3), dt).slosh_m @ mode for _ in range(200)])
        damped, decay = _damped_sinusoid(x, dt)
        omega = math.sqrt(stiffness * lam / SLOSH_KG)
        zeta_mode = zeta * math.sqrt(lam)
        assert damped == pytest.approx(omega * math.sqrt(1 - zeta_mode**2), rel=1e-7)
        assert decay == pytest.approx(zeta_mode * omega, rel=1e-6, abs=1e-9)
    assert eigenvalues.max() > 1.0 + SLOSH_KG / rigid_kg + 1e-3  # the rotation matters (not the translation alone)


def _two_body_matrix(robot: Robot, fuel_kg: float, tank_m: np.ndarray, slosh_kg: float) -> tuple[np.ndarray, float]:
    """``A`` of the linearised base + slosh problem (see the spring test) with the arm locked at home, and the mass of
    the rigid part (kg): the base with ``slosh_kg`` more fuel taken from the tank, and the arm."""
    rigid = base_after_fuel(robot.base_full, fuel_kg + slosh_kg, tank_m)  # the rigid part, by the fuel model
    model = robot.model_with_base(rigid)
    data = model.createData()
    q_full = pin.neutral(model)
    q_full[7:] = robot.home_configuration()
    pin.crba(model, data, q_full)
    body = data.Ycrb[1]
    r = robot.base_full.com_m + tank_m - body.lever
    a_matrix = (1.0 + slosh_kg / body.mass) * np.eye(3) - slosh_kg * skew(r) @ np.linalg.solve(body.inertia, skew(r))
    return a_matrix, float(body.mass)


def _damped_sinusoid(x: np.ndarray, dt: float) -> tuple[float, float]:
    """Damped angular frequency (rad/s) and decay rate (1/s) of samples ``x`` (every ``dt`` s) of one damped mode."""
    # a damped sinusoid obeys x[k+1] = a x[k] + b x[k-1], a = 2 e^{-s dt} cos(w_d dt), b = -e^{-2 s dt}
    (a, b), *_ = np.linalg.lstsq(np.column_stack((x[1:-1], x[:-2])), x[2:], rcond=None)
    return math.acos(a / (2 * math.sqrt(-b))) / dt, -math.log(-b) / (2 * dt)


PAPER6_TANK = np.array([0.2, -0.1, 0.15])  # a paper6 tank position bf (m, from the full-tank CoM)


@pytest.mark.parametrize(
    ("robot_name", "fuel_kg", "tank_m", "slosh_kg", "period_s", "zeta", "axis"),
    [
        ("quick3", FUEL, TANK, SLOSH_KG, 1.0 / 0.3, 0.0, TILTED_AXIS),
        ("quick3", FUEL, TANK, SLOSH_KG, 1.0 / 0.3, 0.05, TILTED_AXIS),
        ("paper6", 40.0, PAPER6_TANK, 37.0, 15.0, 0.05, (0.0, 0.0, 1.0)),  # the other simulator's 37 kg, 0.3 m, 15 s
    ],
    ids=["quick3-tilted-undamped", "quick3-tilted-damped", "paper6-37kg-15s"],
)
def test_pendulum_small_oscillations_match_the_two_body_closed_form(
    request: pytest.FixtureRequest,
    robot_name: str,
    fuel_kg: float,
    tank_m: np.ndarray,
    slosh_kg: float,
    period_s: float,
    zeta: float,
    axis: tuple[float, ...],
) -> None:
    """Arm locked, zero momentum: each hinge mode's period and damping (logarithmic decrement) are the closed form's.

    Linearised, the mass moves relative to the base by ``dx = L Q da`` (``Q = [-e2 e1]``, ``a`` the hinge angles)
    and ``dx = A u`` as for the spring (``u`` its absolute velocity); the rod carries an axial force ``lambda a``
    and the restoring law, linearised, the lateral force ``-m w0^2 x - 2 zeta m w0 dx``. Projecting
    ``m du/dt = m A^-1 ddx`` on the plane of ``Q`` removes ``lambda``: ``B dd(a) + 2 zeta w0 d(a) + w0^2 a = 0``
    with ``B = Q^T A^-1 Q``; mode i (eigenvalue ``mu_i`` of ``B``): ``w_i = w0 / sqrt(mu_i)``, damping ratio
    ``zeta / sqrt(mu_i)``. ``A > I`` makes ``mu_i < 1``: the base's reaction raises the frequency, by at most
    ``sqrt(max eig A)``.
    """
    robot = request.getfixturevalue(robot_name)
    effects = HiddenEffects(
        slosh_mass_kg=slosh_kg,
        slosh_frequency_hz=1.0 / period_s,
        slosh_damping_ratio=zeta,
        slosh_model="pendulum",
        slosh_axis=axis,
    )
    base = base_after_fuel(robot.base_full, fuel_kg, tank_m)
    sim = FreeFloatingSimulator(robot, base, substeps=4, effects=effects, tank_point_m=robot.base_full.com_m + tank_m)
    a_matrix = _two_body_matrix(robot, fuel_kg, tank_m, slosh_kg)[0]
    lateral = np.column_stack((-sim.slosh.rot_base_hinge[:, 1], sim.slosh.rot_base_hinge[:, 0]))  # Q
    mus, modes = np.linalg.eigh(lateral.T @ np.linalg.solve(a_matrix, lateral))
    omega0, dt = 2.0 * math.pi / period_s, period_s / 60.0  # four periods in 240 samples
    for mu, mode in zip(mus, modes.T, strict=True):
        sim.reset(slosh_angles_rad=1e-5 * mode)
        x = [sim.state.slosh_angles_rad @ mode] + [
            sim.step(np.zeros(robot.n_joints), dt).slosh_angles_rad @ mode for _ in range(240)
        ]
        damped, decay = _damped_sinusoid(np.array(x), dt)
        decrement = decay * 2.0 * math.pi / damped  # ln of the amplitude ratio one damped period apart
        omega, zeta_mode = omega0 / math.sqrt(mu), zeta / math.sqrt(mu)
        assert damped == pytest.approx(omega * math.sqrt(1 - zeta_mode**2), rel=1e-7)
        assert decrement / math.hypot(2.0 * math.pi, decrement) == pytest.approx(zeta_mode, rel=1e-6, abs=1e-9)
        assert omega0 < omega <= omega0 * math.sqrt(np.linalg.eigvalsh(a_matrix).max())
    assert mus.min() < 0.99  # the base's reaction matters


@pytest.mark.parametrize("start_rad", [(1.05, 0.0), (0.0, -1.2), (0.7, 0.7)])
def test_pendulum_large_swings_keep_their_plane_and_the_elliptic_period(quick3: Robot, start_rad: tuple[float, float]) -> None:
    """Arm locked, no damping, a light mass (10 mg: the base's reaction moves the rod out of its plane by 1e-7, in
    proportion to the mass): released from rest at a rod
    angle ``phi0`` from its rest axis (60 and 69 deg about either hinge axis, 54 deg about neither), the pendulum
    swings in the plane of its rest axis and the released rod, with the period of a pendulum in a uniform field,
    ``4 K(sin(phi0 / 2)) / w0`` (the complete elliptic integral; 6-10 % above ``2 pi / w0``): the law is the same at
    any angle whatever the hinge's chart."""
    effects = HiddenEffects(
        slosh_mass_kg=1e-5,
        slosh_frequency_hz=0.5,
        slosh_damping_ratio=0.0,
        slosh_model="pendulum",
        slosh_axis=TILTED_AXIS,
        slosh_length_m=0.3,
    )
    sim = _sim(quick3, effects, substeps=4)
    axis = sim.slosh.rot_base_hinge[:, 2]
    state = sim.reset(slosh_angles_rad=np.array(start_rad))
    rod0 = axis + state.slosh_m / 0.3
    normal = np.cross(axis, rod0) / np.linalg.norm(np.cross(axis, rod0))
    phi0 = math.acos(float(np.clip(axis @ rod0, -1.0, 1.0)))
    omega0 = 2.0 * math.pi * 0.5
    period = 4.0 * float(special.ellipk(math.sin(0.5 * phi0) ** 2)) / omega0
    dt = period / 400.0
    side, crossings, off_plane = [float(normal @ np.cross(axis, rod0))], [], 0.0
    for k in range(1, 1001):  # two and a half periods
        state = sim.step(np.zeros(quick3.n_joints), dt)
        rod = axis + state.slosh_m / 0.3
        off_plane = max(off_plane, abs(float(normal @ rod)))
        side.append(float(normal @ np.cross(axis, rod)))  # sin of the signed angle in the plane
        if side[-2] > 0.0 >= side[-1]:  # through the rest axis, one way: once a period
            crossings.append((k - 1 + side[-2] / (side[-2] - side[-1])) * dt)
    assert len(crossings) == 3  # a quarter period in, then each period
    assert crossings[0] == pytest.approx(0.25 * period, rel=1e-6)
    assert np.diff(crossings) == pytest.approx([period, period], rel=1e-6)
    assert period > 1.05 * 2.0 * math.pi / omega0  # large enough to tell from the small-angle period
    assert off_plane < 1e-6


def test_pendulum_past_its_charts_limit_is_an_error_that_names_it(quick3: Robot) -> None:
    """Near the universal joint's singular chart (the rod along ``e1``, 90 deg about ``e2``) the step stops with an
    error naming the effect and the angle, rather than integrate where turning about ``e1`` moves nothing; a start
    beyond the limit is refused by the reset."""
    sim = _sim(quick3, _slosh(frequency_hz=0.5, model="pendulum", slosh_length_m=0.3))
    sim.reset(slosh_angles_rad=np.array([0.0, 1.466]))  # 84 deg, swinging outward at 2 rad/s (the base's rate follows)
    sim.state = dataclasses.replace(sim.state, slosh_angle_rates_rad_s=np.array([0.0, 2.0]))
    with pytest.raises(SpaceIdInputError, match=r"slosh.*swung to 8[5-9]\.\d deg about its second hinge axis at t = 0\.0"):
        sim.step(np.zeros(quick3.n_joints), DT)
    sim.reset(slosh_angles_rad=np.array([0.0, 1.45]))  # 83 deg at rest: within the chart, and swinging back
    assert sim.step(np.zeros(quick3.n_joints), DT).slosh_angles_rad[1] < 1.45
    with pytest.raises(SpaceIdInputError, match=r"reset: slosh_angles_rad\[1\] expected within \+-1\.4835 rad \(85 deg"):
        sim.reset(slosh_angles_rad=np.array([0.0, 1.5]))


def test_pendulum_rod_keeps_its_length_and_the_state_holds_the_mass_displacement(quick3: Robot) -> None:
    """pinocchio's kinematics of the simulated motion (large angles, arm moving): the mass stays ``L`` from the hinge,
    the hinge is fixed in the base, and ``slosh_m``/``slosh_rate_m_s`` are the mass's displacement and velocity
    relative to the base (base axes)."""
    length = 0.25
    sim = _sim(quick3, _slosh(frequency_hz=0.5, model="pendulum", slosh_axis=TILTED_AXIS, slosh_length_m=length))
    model, data = sim.model, sim.model.createData()
    hinge_joint, mass_joint = model.getJointId("slosh_hinge_e1"), model.getJointId("slosh_hinge_e2")
    lever = model.inertias[mass_joint].lever
    state = sim.reset(slosh_angles_rad=np.array([0.4, -0.3]), momentum_world=np.array([0.0, 0.0, 0.0, 0.3, -0.2, 0.1]))
    worst, largest = 0.0, 0.0
    for u in _commands(quick3, 300, seed=8):
        state = sim.step(u, DT)
        relative = np.zeros(model.nv)
        relative[-2:] = state.slosh_angle_rates_rad_s  # the velocity relative to the base
        pin.forwardKinematics(model, data, state.pinocchio_configuration(), relative)
        hinge, mass = data.oMi[hinge_joint].translation, data.oMi[mass_joint].act(lever)
        worst = max(worst, abs(float(np.linalg.norm(mass - hinge)) - length))
        rot, p = state.rot_wb, state.p_wb_m
        np.testing.assert_allclose(rot.T @ (hinge - p), sim.slosh.hinge_m, rtol=0, atol=1e-15)
        np.testing.assert_allclose(rot.T @ (mass - p) - sim.slosh.anchor_m, state.slosh_m, rtol=0, atol=1e-15)
        v = data.v[mass_joint]
        rate = rot.T @ data.oMi[mass_joint].rotation @ (v.linear + np.cross(v.angular, lever))
        np.testing.assert_allclose(rate, state.slosh_rate_m_s, rtol=0, atol=1e-15)
        largest = max(largest, float(np.abs(state.slosh_angles_rad).max()))
    assert largest > 0.2  # well beyond small angles
    assert worst <= 4.0 * np.finfo(float).eps * length


def test_spring_slosh_is_unchanged_by_the_pendulum(quick3: Robot) -> None:
    """The spring model's trajectory is the one before the pendulum was added (recorded at c49803c, the same bits on the
    machine that added it; the tolerance allows only another LAPACK's round-off), also with ``slosh_model="spring"``."""
    before = [-0.014014064269091735, 0.007132041276093533, -0.008057148238466321, 0.01378295854495406]
    before += [-0.007071624492998533, 0.0007523627265737787, 0.03257348750578811, -0.02178865027260614]
    before += [-0.021065585422707114, -0.05668245049842982, -0.0003920549397734936, -0.039173913244104484]
    finals = []
    for model in (None, "spring"):
        effects = _slosh().combine(HiddenEffects(initial_momentum_Nms=(0.2, -0.1, 0.3)))
        sim = _sim(quick3, dataclasses.replace(effects, slosh_model=model))
        sim.reset(slosh_m=np.array([0.02, -0.01, 0.01]))
        for u in _commands(quick3, 100, seed=5):
            state = sim.step(u, DT)
        finals.append(np.concatenate((state.slosh_m, state.slosh_rate_m_s, state.omega_base_body, state.p_wb_m)))
    np.testing.assert_allclose(finals[0], before, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(finals[1], finals[0])


@pytest.mark.parametrize("model", MODELS)
def test_slosh_changes_the_base_rate_and_starts_from_rest(quick3: Robot, model: str) -> None:
    with_slosh, without = _sim(quick3, _slosh(model=model)), _sim(quick3)
    difference = 0.0
    for u in _commands(quick3, 250, seed=7):
        a, b = with_slosh.step(u, DT), without.step(u, DT)
        difference = max(difference, float(np.abs(a.omega_base_body - b.omega_base_body).max()))
    assert difference > 1e-4  # above the 1.4e-4 rad/s per-sample gyro noise at 50 Hz
    assert np.abs(with_slosh.state.slosh_m).max() > 1e-4


# ---------------------------------------------------------------------- sensors: delay, bias, scale
def _env_log(
    robot: Robot, effects: HiddenEffects | str | None, steps: int = 100, seed: int = 3, **kwargs: object
) -> FreeFloatingIDEnv:
    env = FreeFloatingIDEnv(robot, tank_position_m=TANK, hidden_effects=effects, **kwargs)
    env.reset(seed=seed, options={"fuel_consumed_kg": FUEL})
    for u in _commands(robot, steps, seed=seed, hold=5):
        env.step((u / robot.rate_limit_rad_s).astype(np.float32))
    return env


def test_whole_sample_delay_shifts_the_gyro_log_exactly(quick3: Robot) -> None:
    momentum = HiddenEffects(initial_momentum_Nms=(0.2, -0.1, 0.3))
    plain = _env_log(quick3, momentum, sensors="noise_free").measurement_log()
    delayed = _env_log(quick3, momentum.combine(HiddenEffects(delay_s=2 * DT)), sensors="noise_free").measurement_log()
    np.testing.assert_array_equal(delayed.omega_base_body_rad_s[2:], plain.omega_base_body_rad_s[:-2])
    np.testing.assert_array_equal(delayed.omega_base_body_rad_s[:2], plain.omega_base_body_rad_s[[0, 0]])  # at rest before t = 0
    np.testing.assert_array_equal(delayed.q_rad, plain.q_rad)
    np.testing.assert_array_equal(delayed.quat_base_to_inertial_wxyz, plain.quat_base_to_inertial_wxyz)


def test_fractional_delay_measures_the_true_rate_at_the_earlier_time(quick3: Robot) -> None:
    """A 30 ms delay at 50 Hz against a simulation on a 10 ms grid, whose states fall at t - 30 ms."""
    effects = HiddenEffects(initial_momentum_Nms=(0.2, -0.1, 0.3), external_torque_Nm=(0.01, 0.0, -0.01), delay_s=0.03)
    commands = _commands(quick3, 100, seed=8, hold=3, scale=0.3)  # far from the joint limits
    coarse, fine = _sim(quick3, effects, substeps=4), _sim(quick3, effects, substeps=4)  # integration error << 1e-12
    fine_omega = [fine.state.omega_base_body]
    for u in commands:
        for _ in range(2):
            fine_omega.append(fine.step(u, 0.01).omega_base_body)
    delayed = []
    for u in commands:
        state = coarse.step(u, DT)
        delayed.append(coarse.state_at(state.t_s - 0.03).omega_base_body)
    reference = np.array(fine_omega)[2 * np.arange(1, len(commands) + 1) - 3]
    assert np.abs(reference[1:] - reference[:-1]).max() > 1e-5  # the rate changes between samples
    np.testing.assert_allclose(np.array(delayed)[1:], reference[1:], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(delayed[0], coarse.state_at(0.0).omega_base_body)  # t = -0.01: initial state
    with pytest.raises(SpaceIdInputError, match="after the current time"):
        coarse.state_at(coarse.state.t_s + 0.1)
    with pytest.raises(SpaceIdInputError, match="older than the kept history"):
        coarse.state_at(coarse.state.t_s - 0.2)


def test_gyro_bias_and_scale_shift_the_gyro_as_specified(quick3: Robot) -> None:
    """Same seed, same noise: the difference is exactly ``E omega + b`` (with the true rate from a noise-free run)."""
    bias = np.array([3e-5, -1e-5, 2e-5])
    scale = np.array([[2e-4, 5e-4, 0.0], [-5e-4, -1e-4, 3e-4], [1e-4, 0.0, 3e-4]])
    effects = HiddenEffects(gyro_bias_rad_s=bias, gyro_scale_misalignment=scale)
    plain, biased = _env_log(quick3, None).measurement_log(), _env_log(quick3, effects).measurement_log()
    true_rate = _env_log(quick3, None, sensors="noise_free").measurement_log().omega_base_body_rad_s
    np.testing.assert_array_equal(biased.q_rad, plain.q_rad)  # same noise draws
    expected = true_rate @ scale.T + bias
    np.testing.assert_allclose(biased.omega_base_body_rad_s - plain.omega_base_body_rad_s, expected, rtol=0, atol=1e-17)
    assert np.abs(true_rate @ scale.T).max() > 1e-6  # the scale error is visible at all


def test_spec_drawn_bias_leaves_the_noise_unchanged(quick3: Robot) -> None:
    """Effects drawn from a spec use a spawned generator: same seed, same noise, the mean difference is the bias."""
    plain = _env_log(quick3, None)
    biased = _env_log(quick3, "gyro_bias")
    bias = np.array(biased.truth()["hidden_effects"]["gyro_bias_rad_s"])
    assert np.linalg.norm(bias) == pytest.approx(DEFAULT_MAGNITUDES["gyro_bias"])
    difference = biased.measurement_log().omega_base_body_rad_s - plain.measurement_log().omega_base_body_rad_s
    np.testing.assert_allclose(difference.mean(axis=0), bias, rtol=1e-9)
    assert "hidden_effects" not in plain.truth()


# ---------------------------------------------------------------------- payload
def test_payload_follows_pinocchio_parameter_convention_and_eq8(quick3: Robot) -> None:
    params = draw_effect("payload", np.random.default_rng(4), quick3, FUEL, magnitude=3.0).array("payload_params10")
    sim = _sim(quick3, HiddenEffects(payload_params10=params))
    last = quick3.model.njoints - 1
    expected = quick3.model.inertias[last] + pin.Inertia.FromDynamicParameters(params)
    np.testing.assert_allclose(sim.model.inertias[last].toDynamicParameters(), expected.toDynamicParameters(), atol=1e-13)
    env = _env_log(quick3, HiddenEffects(payload_params10=params), steps=200, sensors="noise_free")
    log = env.measurement_log()
    base = base_after_fuel(quick3.base_full, FUEL, TANK)
    with_payload = base_rate_from_joint_motion(
        quick3.with_payload(RigidBodyInertia.from_params10(params)).model_with_base(base), log.q_rad, log.dq_rad_s
    )
    nominal = base_rate_from_joint_motion(quick3.model_with_base(base), log.q_rad, log.dq_rad_s)
    assert np.abs(with_payload - log.omega_base_body_rad_s).max() < 1e-12
    assert np.abs(nominal - log.omega_base_body_rad_s).max() > 1e-4  # the estimators' robot misses it
    assert env.robot.model.inertias[last] == quick3.model.inertias[last]  # the description stays without payload


# ---------------------------------------------------------------------- env, dataset, command
def test_env_with_a_spec_is_deterministic_and_reports_the_truth(quick3: Robot) -> None:
    spec = "initial_momentum,gyro_bias,payload,slosh,delay[delay_s=0.03],external_torque,gyro_scale"
    a, b = _env_log(quick3, spec, steps=60), _env_log(quick3, spec, steps=60)
    c = _env_log(quick3, spec, steps=60, seed=4)
    for name in ("omega_base_body_rad_s", "q_rad", "quat_base_to_inertial_wxyz"):
        np.testing.assert_array_equal(getattr(a.measurement_log(), name), getattr(b.measurement_log(), name))
    truth = a.truth()["hidden_effects"]
    assert HiddenEffects.from_dict(truth).names == tuple(n for n in EFFECT_NAMES)
    assert truth == b.truth()["hidden_effects"] != c.truth()["hidden_effects"]
    truth["delay_s"] = 1.0  # callers get their own copy
    assert a.truth()["hidden_effects"]["delay_s"] == 0.03
    a.reset()  # the next window draws again
    assert a.truth()["hidden_effects"] != truth
    frame = FreeFloatingIDEnv(quick3, hidden_effects="slosh", render_mode="rgb_array")
    frame.reset(seed=0)
    assert frame.render().shape == (480, 480, 3)
    with pytest.raises(SpaceIdInputError, match="unknown effect 'spin'"):
        FreeFloatingIDEnv(quick3, hidden_effects="spin")


def test_dataset_truth_holds_the_effects(quick3: Robot, tmp_path: Path) -> None:
    code = main(
        [
            "simulate",
            "--robot",
            "quick3",
            "--duration",
            "1",
            "--fuel-consumed",
            "10",
            "--seed",
            "2",
            "--hidden-effects",
            "delay,gyro_bias[magnitude=2e-5]",
            "--out",
            str(tmp_path / "run"),
        ]
    )
    assert code == 0
    dataset = load_dataset(tmp_path / "run")
    effects = HiddenEffects.from_dict(dataset.truth["hidden_effects"])
    assert effects.delay_s == 0.02 and np.linalg.norm(effects.gyro_bias_rad_s) == pytest.approx(2e-5)
    env = simulate_episode(quick3, 0.2, 10.0, TANK, lambda t: np.zeros(3, dtype=np.float32), seed=1, hidden_effects=effects)
    assert env.truth()["hidden_effects"] == effects.to_dict()


def test_bad_spec_on_the_command_line_exits_2(tmp_path: Path, spaceid: Callable[..., Any]) -> None:
    command = ["simulate", "--robot", "quick3", "--duration", "1"]
    result = spaceid(*command, "--hidden-effects", "slosh[mass=3]", "--out", str(tmp_path / "x"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "expected keys magnitude, slosh_mass_kg, slosh_frequency_hz, slosh_damping_ratio" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()
