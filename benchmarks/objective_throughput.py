"""Identification objective throughput: the batched momentum model vs a per-sample pinocchio loop.

The objective (paper eq. 15) is ``sum_t |omega(theta) - omega_measured|^2`` for each of P particles
over T samples. Figures are particle-samples per second, median of ``--repeats`` runs, for the
batched :class:`estimators.models.MomentumModel` and for the reference (eq. 8 through pinocchio's
centroidal map, one sample at a time), with their ratio. Usage::

    python benchmarks/objective_throughput.py [--robot paper6] [--particles 50] [--seconds 60]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from estimators.models import MomentumModel
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.physics.fuel import base_after_fuel
from spaceid_gym.physics.momentum import base_rate_from_joint_motion
from spaceid_gym.robots import load_robot


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="paper6")
    parser.add_argument("--particles", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=60.0, help="window length at 50 Hz")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    robot = load_robot(args.robot)
    env = simulate_episode(robot, args.seconds, 40.0, np.array([0.3, -0.1, 0.2]), FourierExcitation(robot.n_joints, 0), seed=0)
    log = env.measurement_log()
    start = time.perf_counter()
    model = MomentumModel(robot, log)
    setup_s = time.perf_counter() - start
    rng = np.random.default_rng(0)
    thetas = np.column_stack((rng.uniform(0, 130, args.particles), rng.uniform(-0.4, 0.4, (args.particles, 3))))

    def batched() -> np.ndarray:
        return np.sum((model.predict_fuel(thetas) - log.omega_base_body_rad_s) ** 2, axis=(1, 2))

    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        costs = batched()
        times.append(time.perf_counter() - start)
    work = args.particles * log.n_samples
    rate = work / statistics.median(times)
    # reference: the same objective for a few particles through pinocchio, one sample at a time
    n_ref = 2
    start = time.perf_counter()
    ref_costs = [
        np.sum(
            (
                base_rate_from_joint_motion(
                    robot.model_with_base(base_after_fuel(robot.base_full, t[0], t[1:])), log.q_rad, log.dq_rad_s
                )
                - log.omega_base_body_rad_s
            )
            ** 2
        )
        for t in thetas[:n_ref]
    ]
    ref_rate = n_ref * log.n_samples / (time.perf_counter() - start)
    assert np.allclose(ref_costs, costs[:n_ref], rtol=1e-9)
    print(
        f"window: {log.n_samples} samples ({args.seconds:.0f} s at 50 Hz), {args.particles} particles; model set-up {setup_s * 1e3:.0f} ms"
    )
    print(
        f"batched MomentumModel objective : {rate:12.3e} particle-samples/s ({statistics.median(times) * 1e3:.1f} ms per swarm evaluation)"
    )
    print(f"pinocchio per-sample reference  : {ref_rate:12.3e} particle-samples/s")
    print(f"ratio                           : {rate / ref_rate:12.1f}")


if __name__ == "__main__":
    main()
