"""The shipped robot ``orbit7``: loads like paper6, keeps the momentum, has canted joint axes."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.cli import main
from spaceid_gym.log import load_dataset
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import Robot, available_robots, load_robot
from spaceid_gym.sim.simulator import FreeFloatingSimulator
from spaceid_gym.sim.state import FreeFloatingState

DT_S = 0.02
#: the design tank of orbit7 (its URDF comment), m, base axes, from the full-tank CoM
DESIGN_TANK_M = np.array([-0.266, 0.155, -0.354])


@pytest.fixture(scope="module")
def orbit7() -> Robot:
    return load_robot("orbit7")


def _random_commands(robot: Robot, steps: int, seed: int, hold: int = 25) -> np.ndarray:
    """Piecewise-constant random rate commands (rad/s) changing every ``hold`` steps."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-1.0, 1.0, size=(steps // hold + 1, robot.n_joints)) * robot.rate_limit_rad_s
    return np.repeat(levels, hold, axis=0)[:steps]


def _axes(robot: Robot, q_arm_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit joint axes at arm configuration ``q_arm_rad``, base at the origin: (in the parent link's frame, in the base frame), (n, 3) each."""
    model, data = robot.model, robot.model.createData()
    q = pin.neutral(model)
    q[7:] = q_arm_rad
    pin.computeJointJacobians(model, data, q)
    parent, base = [], []
    for i in range(2, model.njoints):
        axis_local = pin.getJointJacobian(model, data, i, pin.LOCAL)[3:, model.joints[i].idx_v]
        parent.append(model.jointPlacements[i].rotation @ axis_local)
        base.append(data.oMi[i].rotation @ axis_local)  # world = base frame: the base is at the origin
    return np.array(parent), np.array(base)


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between lines (directions without sign), degrees, in [0, 90]."""
    cos = np.abs(np.sum(a * b, axis=-1)) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


# ---------------------------------------------------------------------------------------- (a) loading
def test_orbit7_is_shipped_and_matches_its_description(orbit7: Robot, paper6: Robot) -> None:
    assert "orbit7" in available_robots()
    assert orbit7.name == "orbit7" and orbit7.source == "orbit7 (shipped)"
    assert orbit7.n_joints == 7 and orbit7.joint_names == [f"joint{i}" for i in range(1, 8)]
    assert orbit7.base_full.mass_kg == pytest.approx(820.0)
    assert orbit7.arm_mass_kg() == pytest.approx(79.0)
    link_masses = np.array([orbit7.model.inertias[i].mass for i in range(2, orbit7.model.njoints)])
    assert np.all((link_masses >= 3.0) & (link_masses <= 20.0))
    np.testing.assert_allclose(orbit7.base_full.com_m, [-0.0544, 0.0251, -0.0659])
    np.testing.assert_allclose(np.linalg.eigvalsh(orbit7.base_full.inertia_com_kgm2), [459.29, 532.58, 604.69], atol=0.02)
    # a different satellite than paper6
    assert not np.allclose(orbit7.base_full.inertia_com_kgm2, paper6.base_full.inertia_com_kgm2, rtol=0.1)
    assert orbit7.n_joints != paper6.n_joints
    assert np.all(orbit7.rate_limit_rad_s > 0) and np.all(orbit7.torque_limit_nm > 0)


def test_every_orbit7_body_is_physical(orbit7: Robot) -> None:
    """Positive mass, positive definite inertia about the CoM, triangle inequality, for the base and every link."""
    for i in range(1, orbit7.model.njoints):
        inertia = orbit7.model.inertias[i]
        moments = np.linalg.eigvalsh(inertia.inertia)
        assert inertia.mass > 0 and moments[0] > 0
        assert moments[0] + moments[1] >= moments[2]


def test_the_fuel_model_works_for_orbit7(orbit7: Robot) -> None:
    """The design tank is off the CoM; all the usable fuel can leave it, or any drawn tank, and the base stays physical."""
    schedule = FuelSchedule()
    usable_kg = schedule.usable_fraction * orbit7.base_full.mass_kg
    assert usable_kg == pytest.approx(205.0)
    assert np.linalg.norm(DESIGN_TANK_M) > 0.4  # the tank is not at the base CoM
    empty = base_after_fuel(orbit7.base_full, usable_kg, DESIGN_TANK_M)
    assert empty.mass_kg == pytest.approx(615.0)
    # the CoM moves away from the tank, by mdf / m0 bf (eq. 11)
    np.testing.assert_allclose(empty.com_m - orbit7.base_full.com_m, -(usable_kg / 615.0) * DESIGN_TANK_M)
    # the dry bus and the 10 kg residual of the design (URDF comment): CoM (0.0343, -0.0266, 0.0521) m
    np.testing.assert_allclose(empty.com_m, [0.0343, -0.0266, 0.0521], atol=2e-4)
    rng = np.random.default_rng(0)
    for _ in range(200):
        base_after_fuel(orbit7.base_full, rng.uniform(0.0, usable_kg), schedule.draw_tank_position(orbit7.base_full, rng))


# -------------------------------------------------------------------------------- (b) conservation
def _centroidal_momentum(
    sim: FreeFloatingSimulator, state: FreeFloatingState, data: pin.Data, arm_only: bool = False
) -> np.ndarray:
    """Centroidal momentum [P; L_G] (inertial axes) by pinocchio; ``arm_only``: with the base held still (the scale)."""
    v = state.pinocchio_velocity()
    if arm_only:
        v[:6] = 0.0
    h = pin.computeCentroidalMomentum(sim.model, data, state.pinocchio_configuration(), v)
    return np.concatenate((h.linear, h.angular))


@pytest.mark.parametrize("initial_momentum", [None, np.array([0.03, -0.01, 0.02, 1.5, -2.0, 0.7])])
def test_orbit7_conserves_linear_and_angular_momentum(orbit7: Robot, initial_momentum: np.ndarray | None) -> None:
    """10 s of random joint motion: pinocchio's centroidal momentum stays at its start to round-off."""
    sim = FreeFloatingSimulator(orbit7, base_after_fuel(orbit7.base_full, 60.0, DESIGN_TANK_M))
    data = sim.model.createData()
    h0 = _centroidal_momentum(sim, sim.reset(momentum_world=initial_momentum), data)
    worst_linear, worst_angular, scale = 0.0, 0.0, 0.0
    for u in _random_commands(orbit7, round(10.0 / DT_S), seed=7, hold=20):
        state = sim.step(u, DT_S)
        error = _centroidal_momentum(sim, state, data) - h0
        worst_linear = max(worst_linear, float(np.linalg.norm(error[:3])))
        worst_angular = max(worst_angular, float(np.linalg.norm(error[3:])))
        scale = max(scale, float(np.linalg.norm(_centroidal_momentum(sim, state, data, arm_only=True))))
    assert state.t_s == pytest.approx(10.0)
    assert scale > 1.0  # the arm really moved: N m s of momentum exchanged with the base
    assert np.abs(state.v_base_body[3:]).max() > 1e-3  # and the base reacted
    assert worst_linear / scale < 1e-9
    assert worst_angular / scale < 1e-9


def test_spaceid_simulate_orbit7_logs_a_momentum_conserving_motion(orbit7: Robot, tmp_path: Path) -> None:
    """``spaceid simulate --robot orbit7 --noise-free``: the logged base rate is the zero-momentum one of the logged joint motion."""
    out = tmp_path / "orbit7"
    tank = ",".join(map(str, DESIGN_TANK_M))
    code = main(
        ["simulate", "--robot", "orbit7", "--duration", "4", "--seed", "2", "--noise-free", f"--tank={tank}", "--out", str(out)]
    )
    assert code == 0
    dataset = load_dataset(out, n_joints=7)
    log = dataset.log
    assert log.n_samples == 201 and log.n_joints == 7
    truth = json.loads((out / "truth.json").read_text())
    assert truth["robot"] == "orbit7"
    np.testing.assert_allclose(truth["tank_position_m"], DESIGN_TANK_M)
    base = base_after_fuel(orbit7.base_full, truth["fuel_consumed_kg"], DESIGN_TANK_M)
    predicted = base_rate_from_joint_motion(orbit7.model_with_base(base), log.q_rad, log.dq_rad_s)
    assert np.abs(log.omega_base_body_rad_s).max() > 1e-4  # the base really moved
    assert np.abs(predicted - log.omega_base_body_rad_s).max() < 1e-9 * np.abs(log.omega_base_body_rad_s).max() + 1e-15


# the torques its motion needs against its URDF efforts: tests/test_simulator.py, with the other robots


# -------------------------------------------------------------------------------------- (c) joint axes
def test_orbit7_joint_axes_are_canted_off_their_parent_axes(orbit7: Robot) -> None:
    """Each axis is 10-30 deg off the nearest principal axis of its parent link and orthogonal to none of them."""
    parent, _ = _axes(orbit7, np.zeros(7))
    np.testing.assert_allclose(np.linalg.norm(parent, axis=1), 1.0)
    to_parent_axes = _angles_deg(parent[:, None, :], np.eye(3)[None, :, :])  # (7, 3)
    assert np.all((to_parent_axes.min(axis=1) > 10.0) & (to_parent_axes.min(axis=1) < 30.0)), to_parent_axes
    assert np.all(to_parent_axes < 85.0), to_parent_axes  # every component clearly non-zero


def test_orbit7_consecutive_joint_axes_are_neither_parallel_nor_orthogonal(orbit7: Robot) -> None:
    """The angle between consecutive axes is fixed by the link between them: 50-75 deg in every configuration."""
    rng = np.random.default_rng(1)
    configurations = [np.zeros(7), orbit7.home_configuration()] + [
        rng.uniform(orbit7.q_lower_rad, orbit7.q_upper_rad) for _ in range(5)
    ]
    twists = []
    for q in configurations:
        _, base = _axes(orbit7, q)
        twists.append(_angles_deg(base[:-1], base[1:]))
    np.testing.assert_allclose(twists, np.broadcast_to(twists[0], (len(twists), 6)), atol=1e-9)
    np.testing.assert_allclose(twists[0], [74.0, 72.9, 73.9, 65.0, 56.3, 51.7], atol=0.05)  # the URDF comment's values
    assert np.all((twists[0] > 45.0) & (twists[0] < 80.0))


def test_orbit7_joint_axes_are_not_orthogonal_to_the_base_axes_or_to_each_other(orbit7: Robot, paper6: Robot) -> None:
    """At zero joint angles, in the base frame: every axis 10-30 deg off its nearest base axis, every pair 5+ deg from orthogonal."""
    _, base = _axes(orbit7, np.zeros(7))
    to_base_axes = _angles_deg(base[:, None, :], np.eye(3)[None, :, :])
    assert np.all((to_base_axes.min(axis=1) > 10.0) & (to_base_axes.min(axis=1) < 30.0))
    assert np.all(to_base_axes < 85.0)
    pairs = np.array([_angles_deg(base[i], base[j]) for i, j in itertools.combinations(range(7), 2)])
    assert np.all((pairs > 20.0) & (pairs < 85.0)), pairs
    # the check tells the robots apart: paper6's axes lie along its base axes, parallel or orthogonal to each other
    _, base6 = _axes(paper6, np.zeros(6))
    assert np.all(_angles_deg(base6[:, None, :], np.eye(3)[None, :, :]).min(axis=1) < 1e-9)
