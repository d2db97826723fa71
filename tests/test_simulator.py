"""The free-floating simulator against independent references.

* pinocchio's centroidal momentum (conservation over 600 s, with and without initial momentum);
* the paper's eq. 8 through pinocchio's centroidal map (a different code path);
* the Newton-Euler equations: RNEA base wrench of the simulated motion is zero;
* the integrator's order of convergence; the servo's closed form against an ODE solver;
* the joint torques the motion needs stay within the URDF effort limits.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import solve_ivp

from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import Robot, load_robot
from spaceid_gym.sim.lie import dexp_inv, matrix_from_quat, quat_from_matrix, so3_exp
from spaceid_gym.sim.servo import default_servo
from spaceid_gym.sim.simulator import FreeFloatingSimulator
from spaceid_gym.sim.state import FreeFloatingState

DT = 0.02


def _random_commands(robot: Robot, steps: int, seed: int, hold: int = 25) -> np.ndarray:
    """Piecewise-constant random rate commands (rad/s) changing every ``hold`` steps."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-1.0, 1.0, size=(steps // hold + 1, robot.n_joints)) * robot.rate_limit_rad_s
    return np.repeat(levels, hold, axis=0)[:steps]


def _momentum(sim: FreeFloatingSimulator, state: FreeFloatingState, data: pin.Data) -> np.ndarray:
    """Centroidal momentum [P; L_G] (inertial axes) by pinocchio."""
    h = pin.computeCentroidalMomentum(sim.model, data, state.pinocchio_configuration(), state.pinocchio_velocity())
    return np.concatenate((h.linear, h.angular))


def _arm_momentum(sim: FreeFloatingSimulator, state: FreeFloatingState, data: pin.Data) -> np.ndarray:
    """Momentum the arm's motion carries with the base held still: the scale of the problem."""
    v = state.pinocchio_velocity()
    v[:6] = 0.0
    h = pin.computeCentroidalMomentum(sim.model, data, state.pinocchio_configuration(), v)
    return np.concatenate((h.linear, h.angular))


@pytest.mark.slow
@pytest.mark.parametrize("initial_momentum", [None, np.array([0.05, -0.02, 0.01, 2.0, -1.0, 3.0])])
def test_momentum_conserved_over_600_s(paper6: Robot, initial_momentum: np.ndarray | None) -> None:
    base = base_after_fuel(paper6.base_full, 40.0, np.array([0.3, -0.1, 0.2]))
    sim = FreeFloatingSimulator(paper6, base)
    data = sim.model.createData()
    h0 = _momentum(sim, sim.reset(momentum_world=initial_momentum), data)
    steps = int(600 / DT)
    worst, scale = 0.0, np.linalg.norm(h0)
    for k, u in enumerate(_random_commands(paper6, steps, seed=1)):
        state = sim.step(u, DT)
        if k % 10 == 0:
            worst = max(worst, float(np.linalg.norm(_momentum(sim, state, data) - h0)))
            scale = max(scale, float(np.linalg.norm(_arm_momentum(sim, state, data))))
    assert state.t_s == pytest.approx(600.0)
    assert scale > 1.0  # the arm really moved: several N m s of internal momentum exchanged
    assert worst / scale < 1e-8


def test_base_rate_equals_generalized_jacobian_prediction(quick3: Robot) -> None:
    """Eq. 8 by pinocchio's centroidal map from (q, dq) alone reproduces the logged base rate."""
    base = base_after_fuel(quick3.base_full, 10.0, np.array([0.1, 0.05, -0.1]))
    env = FreeFloatingIDEnv(quick3, sensors="noise_free", tank_position_m=np.array([0.1, 0.05, -0.1]))
    env.reset(seed=2, options={"fuel_consumed_kg": 10.0})
    for u in _random_commands(quick3, 1500, seed=2, hold=7):
        env.step(u / quick3.rate_limit_rad_s)
    log = env.measurement_log()  # the logged (noise-free) measurements
    base = base_after_fuel(quick3.base_full, 10.0, np.array([0.1, 0.05, -0.1]))
    predicted = base_rate_from_joint_motion(quick3.model_with_base(base), log.q_rad, log.dq_rad_s)
    assert np.abs(log.omega_base_body_rad_s).max() > 1e-3  # the base really moved
    assert np.abs(predicted - log.omega_base_body_rad_s).max() < 1e-8


def test_motion_satisfies_newton_euler_with_zero_base_wrench(paper6: Robot) -> None:
    """RNEA of the simulated motion (base acceleration by central differences) gives no base wrench."""
    sim = FreeFloatingSimulator(paper6, paper6.base_full)
    sim.reset(momentum_world=np.array([0.0, 0.0, 0.0, 1.0, 0.5, -2.0]))
    for u in _random_commands(paper6, 60, seed=3, hold=60):
        sim.step(u, DT)
    h = 1e-3
    u = 0.7 * paper6.rate_limit_rad_s * np.array([1, -1, 1, -1, 1, -1])
    before = sim.state
    mid = sim.step(u, h)
    after = sim.step(u, h)
    data = sim.model.createData()
    a_base = (after.v_base_body - before.v_base_body) / (2 * h)
    a_joint = (after.dq_rad_s - before.dq_rad_s) / (2 * h)
    tau = pin.rnea(sim.model, data, mid.pinocchio_configuration(), mid.pinocchio_velocity(), np.concatenate((a_base, a_joint)))
    assert np.linalg.norm(tau[6:]) > 1.0  # the joints do work
    assert np.linalg.norm(tau[:6]) < 1e-5 * np.linalg.norm(tau[6:])


def test_attitude_integrator_is_fourth_order(quick3: Robot) -> None:
    commands = _random_commands(quick3, 100, seed=4, hold=10)
    momentum = np.array([0.02, 0.0, -0.01, 0.5, -0.3, 0.8])

    def final_attitude(substeps: int) -> np.ndarray:
        sim = FreeFloatingSimulator(quick3, quick3.base_full, substeps=substeps)
        sim.reset(momentum_world=momentum)
        for u in commands:
            state = sim.step(u, 0.1)
        return state.rot_wb

    reference = final_attitude(64)
    errors = [np.linalg.norm(final_attitude(s) - reference) for s in (1, 2, 4)]
    assert errors[0] > 1e-12  # the test measures something
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert min(ratios) > 12.0  # 2^4 = 16 for a fourth-order scheme


def test_servo_closed_form_matches_ode_solution(paper6: Robot) -> None:
    servo = default_servo(paper6.rate_limit_rad_s)
    q0 = np.linspace(-0.5, 0.5, 6)
    dq0 = np.array([0.05, -0.1, 0.0, 0.1, -0.15, 0.02])
    u = np.array([-0.1, 0.1, 0.001, 0.15, 0.15, -0.08])
    times = np.linspace(0.0, 2.0, 41)
    q, dq, ddq = servo.motion(q0, dq0, u, times)

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        acc = np.clip(servo.gain_per_s * (u - y[6:]), -servo.accel_limit_rad_s2, servo.accel_limit_rad_s2)
        return np.concatenate((y[6:], acc))

    sol = solve_ivp(rhs, (0, 2.0), np.concatenate((q0, dq0)), t_eval=times, rtol=1e-12, atol=1e-14, method="DOP853")
    np.testing.assert_allclose(q, sol.y[:6].T, atol=1e-9)
    np.testing.assert_allclose(dq, sol.y[6:].T, atol=1e-9)
    np.testing.assert_allclose(ddq[1:], np.array([rhs(0, y)[6:] for y in sol.y.T])[1:], atol=1e-7)


@pytest.mark.parametrize(("period_s", "overshoot_rad"), [(DT, 0.0), (0.2, 1e-6), (1.0, 1e-3)])
def test_servo_respects_rate_and_joint_limits(paper6: Robot, period_s: float, overshoot_rad: float) -> None:
    """No overshoot at the default period; a bounded one for long held commands (documented)."""
    sim = FreeFloatingSimulator(paper6, paper6.base_full)
    for k in range(int(80 / period_s)):
        sign = 1.0 if k * period_s < 50 else -1.0  # drive into the upper limits, then the lower ones
        state = sim.step(5.0 * sign * paper6.rate_limit_rad_s, period_s)  # far beyond the rate limit
        assert np.all(np.abs(state.dq_rad_s) <= paper6.rate_limit_rad_s + 1e-12)
        assert np.all((state.q_rad <= paper6.q_upper_rad + overshoot_rad) & (state.q_rad >= paper6.q_lower_rad - overshoot_rad))
        if k * period_s < 50:
            top = state.q_rad
    assert np.all(top > paper6.q_upper_rad - 0.1)  # it got there, not stopped far off


@pytest.mark.parametrize("name", ["paper6", "quick3", "orbit7"])
def test_required_joint_torques_stay_within_effort_limits(name: str, paper6: Robot, quick3: Robot) -> None:
    robot = {"paper6": paper6, "quick3": quick3}.get(name) or load_robot(name)
    sim = FreeFloatingSimulator(robot, robot.base_full)
    data = sim.model.createData()
    rng = np.random.default_rng(5)
    worst = np.zeros(robot.n_joints)
    for _ in range(1500):  # bang-bang commands: every step a new full-scale rate, worst case
        state = sim.step(rng.choice([-1.0, 1.0], size=robot.n_joints) * robot.rate_limit_rad_s, DT)
        q_full, v_full = state.pinocchio_configuration(), state.pinocchio_velocity()
        mass = pin.crba(sim.model, data, q_full)
        mass = np.triu(mass) + np.triu(mass, 1).T
        nle = pin.nonLinearEffects(sim.model, data, q_full, v_full)
        a_base = -np.linalg.solve(mass[:6, :6], mass[:6, 6:] @ state.ddq_rad_s2 + nle[:6])
        tau = pin.rnea(sim.model, data, q_full, v_full, np.concatenate((a_base, state.ddq_rad_s2)))[6:]
        worst = np.maximum(worst, np.abs(tau))
    assert np.all(worst < robot.torque_limit_nm), (worst, robot.torque_limit_nm)
    assert np.any(worst > 0.05 * robot.torque_limit_nm)


def test_so3_helpers_against_pinocchio() -> None:
    rng = np.random.default_rng(6)
    for _ in range(20):
        theta = rng.normal(size=3)
        np.testing.assert_allclose(so3_exp(theta), pin.exp3(theta), atol=1e-14)
        rot = pin.exp3(theta)
        quat = quat_from_matrix(rot)
        pq = pin.Quaternion(rot)
        np.testing.assert_allclose(np.abs(quat), np.abs([pq.w, pq.x, pq.y, pq.z]), atol=1e-14)
        np.testing.assert_allclose(matrix_from_quat(quat), rot, atol=1e-14)
        # dexp_inv: R0 exp(theta + eps theta_dot) ~ R0 exp(theta) exp(eps omega)
        omega = rng.normal(size=3)
        theta_dot = dexp_inv(theta, omega)
        eps = 1e-6
        rel = pin.exp3(theta).T @ pin.exp3(theta + eps * theta_dot)
        np.testing.assert_allclose(pin.log3(rel) / eps, omega, atol=1e-5)
        np.testing.assert_allclose(dexp_inv(theta, omega), np.linalg.solve(pin.Jexp3(theta), omega), atol=1e-12)


def test_attitude_follows_the_gyro_rate_in_the_body_frame(paper6: Robot) -> None:
    """R(t + h) = R(t) exp(omega_body h) to O(h^3) with the rate averaged; the world-frame product is wrong."""
    sim = FreeFloatingSimulator(paper6, paper6.base_full)
    sim.reset(rot_wb=pin.exp3(np.array([0.4, -0.7, 0.2])), momentum_world=np.array([0.0, 0.0, 0.0, 20.0, -15.0, 10.0]))
    for u in _random_commands(paper6, 50, seed=7, hold=50):
        sim.step(u, DT)
    h = 1e-3
    before = sim.state
    after = sim.step(0.5 * paper6.rate_limit_rad_s, h)
    omega = 0.5 * (before.omega_base_body + after.omega_base_body)
    assert np.linalg.norm(omega) > 1e-2  # a real rotation over the step
    body = before.rot_wb @ pin.exp3(omega * h)
    world = pin.exp3(omega * h) @ before.rot_wb
    assert np.linalg.norm(after.rot_wb - body) < 1e-9
    assert np.linalg.norm(after.rot_wb - world) > 1e-6
    np.testing.assert_allclose(matrix_from_quat(after.quat_wb), after.rot_wb, atol=1e-14)  # base to inertial
