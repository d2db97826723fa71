"""Accuracy figures of the simulator, measured against independent references (for the README).

    python benchmarks/physics_checks.py [--robot paper6] [--duration 600]

Prints: the momentum drift of a noise-free run (pinocchio centroidal momentum, relative to the
momentum the arm exchanges with the base), the largest deviation of the logged base rate from
the paper's eq. 8 evaluated through pinocchio's centroidal map, the attitude error of the RKMK4
integrator against a 64-substep reference and its convergence ratios, and the fuel model's
recomposition error against pinocchio's inertia arithmetic.
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np
import pinocchio as pin

from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import load_robot
from spaceid_gym.sim.simulator import FreeFloatingSimulator

TANK_M = np.array([0.3, -0.1, 0.2])
FUEL_KG = 40.0


def _momentum(model: pin.Model, data: pin.Data, q_full: np.ndarray, v_full: np.ndarray) -> np.ndarray:
    h = pin.computeCentroidalMomentum(model, data, q_full, v_full)
    return np.concatenate((h.linear, h.angular))


def momentum_drift(robot_name: str, duration_s: float, initial: np.ndarray | None) -> tuple[float, float]:
    """(max |h(t) - h(0)| / scale, scale) over a run with piecewise-constant random commands."""
    robot = load_robot(robot_name)
    sim = FreeFloatingSimulator(robot, base_after_fuel(robot.base_full, FUEL_KG, TANK_M))
    data = sim.model.createData()
    state = sim.reset(momentum_world=initial)
    h0 = _momentum(sim.model, data, state.pinocchio_configuration(), state.pinocchio_velocity())
    rng = np.random.default_rng(1)
    worst, scale = 0.0, float(np.linalg.norm(h0))
    for k in range(round(duration_s / 0.02)):
        if k % 25 == 0:
            command = rng.uniform(-1, 1, robot.n_joints) * robot.rate_limit_rad_s
        state = sim.step(command, 0.02)
        q_full, v_full = state.pinocchio_configuration(), state.pinocchio_velocity()
        worst = max(worst, float(np.linalg.norm(_momentum(sim.model, data, q_full, v_full) - h0)))
        v_arm = v_full.copy()
        v_arm[:6] = 0.0
        scale = max(scale, float(np.linalg.norm(_momentum(sim.model, data, q_full, v_arm))))
    return worst / scale, scale


def eq8_deviation(robot_name: str) -> float:
    robot = load_robot(robot_name)
    env = FreeFloatingIDEnv(robot, sensors="noise_free", tank_position_m=TANK_M)
    env.reset(seed=0, options={"fuel_consumed_kg": FUEL_KG})
    rng = np.random.default_rng(2)
    for _ in range(3000):
        env.step(rng.uniform(-1, 1, robot.n_joints).astype(np.float32))
    log = env.measurement_log()
    model = robot.model_with_base(base_after_fuel(robot.base_full, FUEL_KG, TANK_M))
    return float(np.abs(base_rate_from_joint_motion(model, log.q_rad, log.dq_rad_s) - log.omega_base_body_rad_s).max())


def integrator_order(robot_name: str) -> list[float]:
    robot = load_robot(robot_name)
    rng = np.random.default_rng(4)
    commands = np.repeat(rng.uniform(-1, 1, (10, robot.n_joints)) * robot.rate_limit_rad_s, 10, axis=0)

    def attitude(substeps: int) -> np.ndarray:
        sim = FreeFloatingSimulator(robot, robot.base_full, substeps=substeps)
        sim.reset(momentum_world=np.array([0.02, 0.0, -0.01, 0.5, -0.3, 0.8]))
        for u in commands:
            state = sim.step(u, 0.1)
        return state.rot_wb

    reference = attitude(64)
    return [float(np.linalg.norm(attitude(s) - reference)) for s in (1, 2, 4, 8)]


def fuel_recomposition_error(robot_name: str) -> float:
    robot = load_robot(robot_name)
    full = robot.base_full
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(100):
        mdf, bf = rng.uniform(0, 0.25 * full.mass_kg), rng.uniform(-0.4, 0.4, 3)
        rest = base_after_fuel(full, mdf, bf)
        total = pin.Inertia(rest.mass_kg, rest.com_m, rest.inertia_com_kgm2) + pin.Inertia(mdf, full.com_m + bf, np.zeros((3, 3)))
        full_pin = pin.Inertia(full.mass_kg, full.com_m, full.inertia_com_kgm2)
        worst = max(worst, float(np.abs(total.matrix() - full_pin.matrix()).max() / np.abs(full_pin.matrix()).max()))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="paper6")
    parser.add_argument("--duration", type=float, default=600.0)
    args = parser.parse_args()
    start = time.perf_counter()
    for label, initial in (("zero", None), ("non-zero", np.array([0.05, -0.02, 0.01, 2.0, -1.0, 3.0]))):
        drift, scale = momentum_drift(args.robot, args.duration, initial)
        print(f"momentum drift, {args.duration:.0f} s, {label} initial momentum: {drift:.2e} (relative to {scale:.2f} N m s)")
    print(f"eq. 8 vs logged base rate, 60 s noise-free, max deviation: {eq8_deviation(args.robot):.2e} rad/s")
    errors = integrator_order(args.robot)
    ratios = [a / b for a, b in itertools.pairwise(errors)]
    print(
        f"RKMK4 attitude error vs 64 substeps (1, 2, 4, 8 substeps): {', '.join(f'{e:.1e}' for e in errors)}; "
        f"ratios {', '.join(f'{r:.1f}' for r in ratios)} (16 = fourth order)"
    )
    print(
        f"fuel model recomposed with pinocchio Inertia arithmetic, max relative error: {fuel_recomposition_error(args.robot):.1e}"
    )
    print(f"({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
