"""Hidden physical effects on the truth side: settings, spec strings and the simulator's physics.

Independent references: pinocchio's centroidal momentum, kinetic energy and RNEA (Newton-Euler) on
the simulated motion; the closed-form small oscillations of the base + slosh two-body problem;
the fuel-removal model for the slosh mass; a finer time grid for the gyro delay; pinocchio's own
``Inertia.FromDynamicParameters`` and the eq. 8 map for the payload.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.effects import (
    DEFAULT_MAGNITUDES,
    EFFECT_NAMES,
    ORBITAL_RATE_RAD_S,
    PAYLOAD_BOX_M,
    PAYLOAD_DISTANCE_M,
    HiddenEffects,
    draw_effect,
    parse_hidden_effects,
    remaining_liquid_kg,
)
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import load_dataset
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.inertia import RigidBodyInertia, skew
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import Robot
from spaceid_gym.sim.simulator import FreeFloatingSimulator, FreeFloatingState

DT = 0.02
TANK = np.array([0.1, 0.05, -0.1])  # quick3 tank position bf (m, from the full-tank CoM)
FUEL = 8.0  # kg consumed (quick3)
SLOSH_KG = 5.0


def _commands(robot: Robot, steps: int, seed: int, hold: int = 10, scale: float = 1.0) -> np.ndarray:
    """Piecewise-constant random rate commands (rad/s) changing every ``hold`` steps."""
    rng = np.random.default_rng(seed)
    levels = scale * rng.uniform(-1.0, 1.0, size=(steps // hold + 1, robot.n_joints)) * robot.rate_limit_rad_s
    return np.repeat(levels, hold, axis=0)[:steps]


def _slosh(zeta: float = 0.05, frequency_hz: float = 0.3) -> HiddenEffects:
    return HiddenEffects(slosh_mass_kg=SLOSH_KG, slosh_frequency_hz=frequency_hz, slosh_damping_ratio=zeta)


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
        ({"payload_params10": [1.0, 0, 0, 0, 1.0, 0, 0.1, 0, 0, 0.1]}, "triangle inequality"),
        ({"gyro_scale_misalignment": [[0.0] * 3] * 2}, "'gyro_scale_misalignment': expected 3x3"),
    ],
)
def test_bad_settings_are_named(kwargs: dict, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        HiddenEffects(**kwargs)


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
        ("", "expected a spec"),
    ],
)
def test_bad_spec_strings_are_named(paper6: Robot, spec: str, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_hidden_effects(spec, np.random.default_rng(0), paper6, 40.0)


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


@pytest.mark.parametrize("slosh", [False, True])
def test_external_torque_is_the_base_wrench_newton_euler(quick3: Robot, slosh: bool) -> None:
    """RNEA of the simulated motion: the base wrench is the torque (base axes); with slosh, the spring-damper on its joints."""
    torque = np.array([0.5, -0.3, 0.8])  # large, so the finite-difference error stays far below it
    effects = HiddenEffects(external_torque_Nm=torque)
    sim = _sim(quick3, effects.combine(_slosh(zeta=0.1)) if slosh else effects)
    sim.reset(rot_wb=pin.exp3(np.array([0.3, -0.5, 0.2])))
    for u in _commands(quick3, 100, seed=3, hold=100):
        sim.step(u, DT)
    tau, mid = _newton_euler_residual(sim, 0.5 * quick3.rate_limit_rad_s)
    expected = np.concatenate((np.zeros(3), mid.rot_wb.T @ torque))  # a pure torque, base axes
    assert np.linalg.norm(tau[6:9]) > 1.0  # the joints do work
    assert np.linalg.norm(tau[:6] - expected) < 1e-4 * np.linalg.norm(torque)
    assert np.linalg.norm(tau[:6]) > 0.9 * np.linalg.norm(torque)
    if slosh:
        spring = -sim.slosh.stiffness_n_m * mid.slosh_m - sim.slosh.damping_n_s_m * mid.slosh_rate_m_s
        assert np.linalg.norm(spring) > 1e-2
        assert np.linalg.norm(tau[9:] - spring) < 1e-5 * np.linalg.norm(spring)


def _convergence_ratios(final: list[np.ndarray], reference: np.ndarray) -> list[float]:
    errors = [float(np.linalg.norm(f - reference)) for f in final]
    assert errors[0] > 1e-12  # the test measures something
    return [errors[0] / errors[1], errors[1] / errors[2]]


@pytest.mark.parametrize("slosh", [False, True])
def test_integrator_stays_fourth_order_with_torque_and_slosh(quick3: Robot, slosh: bool) -> None:
    """The stages use the momentum (and slosh state) at their own times: the error falls as h^4."""
    effects = HiddenEffects(
        initial_momentum_Nms=(0.5, -0.3, 0.8), external_torque_Nm=(0.05, 0.02, -0.04), external_torque_rate_Nm_s=(0.0, 0.01, 0.0)
    )
    if slosh:
        effects = effects.combine(_slosh(frequency_hz=0.5))
    commands = _commands(quick3, 40, seed=4, hold=4)

    def final(substeps: int) -> np.ndarray:
        sim = _sim(quick3, effects, substeps=substeps)
        sim.reset(slosh_m=np.array([0.02, -0.01, 0.01]) if slosh else None)
        for u in commands:
            state = sim.step(u, 0.1)
        return np.concatenate((state.rot_wb.ravel(), [] if state.slosh_m is None else state.slosh_m))

    assert min(_convergence_ratios([final(s) for s in (1, 2, 4)], final(32))) > 12.0  # 2^4 = 16


# ---------------------------------------------------------------------- slosh
def test_slosh_mass_is_taken_from_the_base_at_the_tank(quick3: Robot) -> None:
    """At rest the mass distribution is the rigid one: rigid base + slosh mass = the base after fuel removal."""
    sim = _sim(quick3, _slosh())
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
    np.testing.assert_allclose(
        sim.reset(momentum_world=momentum).v_base_body, rigid_sim.reset(momentum_world=momentum).v_base_body, atol=1e-15
    )
    # an empty tank has nothing to slosh: no extra body
    empty = draw_effect("slosh", np.random.default_rng(0), quick3, 0.25 * quick3.base_full.mass_kg)
    assert empty.slosh_mass_kg == 0.0 and empty.names == ("slosh",)
    assert _sim(quick3, empty).slosh is None and _sim(quick3, empty).model.nq == quick3.model.nq


def test_slosh_conserves_momentum_with_the_arm_moving(quick3: Robot) -> None:
    sim = _sim(quick3, _slosh())
    data = sim.model.createData()
    h0 = _centroidal(sim, sim.reset(momentum_world=np.array([0.0, 0.0, 0.0, 0.2, -0.1, 0.3])), data)
    worst, scale = 0.0, 0.0
    for u in _commands(quick3, 1000, seed=5):
        state = sim.step(u, DT)
        worst = max(worst, float(np.linalg.norm(_centroidal(sim, state, data) - h0)))
        scale = max(scale, _arm_momentum(sim, state, data))
    assert scale > 0.5 and np.abs(state.slosh_m).max() > 1e-4  # the arm and the slosh mass really moved
    assert worst / scale < 1e-12


def test_slosh_satisfies_newton_euler(quick3: Robot) -> None:
    """RNEA of the simulated motion: no base wrench, the spring-damper force on the slosh joints."""
    sim = _sim(quick3, _slosh(zeta=0.1))
    for u in _commands(quick3, 150, seed=6, hold=150):
        sim.step(u, DT)
    tau, mid = _newton_euler_residual(sim, -0.6 * quick3.rate_limit_rad_s)
    k, c = sim.slosh.stiffness_n_m, sim.slosh.damping_n_s_m
    spring = -k * mid.slosh_m - c * mid.slosh_rate_m_s
    assert np.linalg.norm(spring) > 1e-2
    assert np.linalg.norm(tau[:6]) < 1e-5 * np.linalg.norm(tau[6:9])
    assert np.linalg.norm(tau[9:] - spring) < 1e-5 * np.linalg.norm(spring)


def test_slosh_energy_is_conserved_without_damping_at_fourth_order(quick3: Robot) -> None:
    """Arm locked, no damping: kinetic (pinocchio) + spring energy is constant up to the integrator's error."""
    errors = []
    for substeps in (1, 2, 4):
        sim = _sim(quick3, _slosh(zeta=0.0), substeps=substeps)
        data = sim.model.createData()

        def energy(state: FreeFloatingState, sim: FreeFloatingSimulator = sim, data: pin.Data = data) -> float:
            kinetic = pin.computeKineticEnergy(sim.model, data, state.pinocchio_configuration(), state.pinocchio_velocity())
            return kinetic + 0.5 * sim.slosh.stiffness_n_m * float(state.slosh_m @ state.slosh_m)

        state = sim.reset(slosh_m=np.array([0.03, -0.02, 0.01]), momentum_world=np.array([0.0, 0.0, 0.0, 2.0, -1.0, 1.5]))
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
    rigid = base_after_fuel(quick3.base_full, FUEL + SLOSH_KG, TANK)  # the rigid part, by the fuel model
    model = quick3.model_with_base(rigid)
    data = model.createData()
    q_full = pin.neutral(model)
    q_full[7:] = quick3.home_configuration()
    pin.crba(model, data, q_full)
    body = data.Ycrb[1]
    r = quick3.base_full.com_m + TANK - body.lever
    a_matrix = (1.0 + SLOSH_KG / body.mass) * np.eye(3) - SLOSH_KG * skew(r) @ np.linalg.solve(body.inertia, skew(r))
    eigenvalues, modes = np.linalg.eigh(a_matrix)
    stiffness = effects.slosh_stiffness_damping()[0]
    dt = 0.05
    for lam, mode in zip(eigenvalues, modes.T, strict=True):
        sim = _sim(quick3, effects, substeps=4)
        sim.reset(slosh_m=1e-5 * mode)
        x = np.array([sim.state.slosh_m @ mode] + [sim.step(np.zeros(3), dt).slosh_m @ mode for _ in range(200)])
        # a damped sinusoid obeys x[k+1] = a x[k] + b x[k-1], a = 2 e^{-s dt} cos(w_d dt), b = -e^{-2 s dt}
        (a, b), *_ = np.linalg.lstsq(np.column_stack((x[1:-1], x[:-2])), x[2:], rcond=None)
        decay = -math.log(-b) / (2 * dt)
        damped = math.acos(a / (2 * math.sqrt(-b))) / dt
        omega = math.sqrt(stiffness * lam / SLOSH_KG)
        zeta_mode = zeta * math.sqrt(lam)
        assert damped == pytest.approx(omega * math.sqrt(1 - zeta_mode**2), rel=1e-7)
        assert decay == pytest.approx(zeta_mode * omega, rel=1e-6, abs=1e-9)
    assert eigenvalues.max() > 1.0 + SLOSH_KG / body.mass + 1e-3  # the rotation matters (not the translation alone)


def test_slosh_changes_the_base_rate_and_starts_from_rest(quick3: Robot) -> None:
    with_slosh, without = _sim(quick3, _slosh()), _sim(quick3)
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


def test_bad_spec_on_the_command_line_exits_2(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "spaceid_gym.cli", "simulate", "--robot", "quick3", "--duration", "1"]
    result = subprocess.run(
        [*command, "--hidden-effects", "slosh[mass=3]", "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "expected keys magnitude, slosh_mass_kg, slosh_frequency_hz, slosh_damping_ratio" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()
