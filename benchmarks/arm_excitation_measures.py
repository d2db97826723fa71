"""The arm's excitations in ``ManipulatorID-v0``: the excitation measures of a random multi-sine against the arm's
optimised Fourier trajectory.

Each excitation drives ``ManipulatorID-v0`` (UR5, Coulomb + viscous friction, rate actions, 30 s at 125 Hz) from the
same seeded reset; the figures are the env's :meth:`excitation_measures` (torque data about the 48 base parameters,
prior-std units): D-optimality ``log det F``, the largest Cramér-Rao std and the condition number of the scaled
information, medians over ``--seeds`` windows. The optimised trajectory is
:func:`spaceid_gym.arm.excitation_design.optimise_excitation` (condition-number criterion, one period of 10 s, seed 0); the
env follows its rates ``dq(t) / rate limit`` from its own start (not the trajectory's mean angles). No learnt policy
is trained for the arm. Usage::

    python benchmarks/arm_excitation_measures.py [--seeds 5]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

from spaceid_gym.arm.excitation_design import optimise_excitation
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.information import ExcitationMeasures

WINDOW_S = 30.0


def measures(env: ManipulatorIDEnv, action: Callable[[float], np.ndarray], seed: int) -> ExcitationMeasures:
    env.reset(seed=seed)
    steps = round(WINDOW_S / env.control_period_s)
    for k in range(steps):
        env.step(np.asarray(action(k * env.control_period_s), dtype=np.float32))
    return env.excitation_measures()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    env = ManipulatorIDEnv()
    result = optimise_excitation(env.regressor, env.base, rng=np.random.default_rng(0))
    trajectory, limit = result.trajectory, env.robot.dq_limit_rad_s
    excitations: dict[str, Callable[[int], Callable[[float], np.ndarray]]] = {
        "random multi-sine (0.025-0.125 Hz)": lambda seed: FourierExcitation(env.robot.n_joints, seed),
        "random multi-sine (0.1-0.5 Hz)": lambda seed: FourierExcitation(env.robot.n_joints, seed, base_frequency_hz=0.1),
        "optimised Fourier (condition)": lambda seed: lambda t: np.clip(trajectory.state(t)[1] / limit, -1.0, 1.0),
    }
    print("excitation | D-optimality | largest CR std (prior std) | condition number (median over seeds)")
    for name, make in excitations.items():
        values = [measures(env, make(seed), seed) for seed in range(args.seeds)]
        d = np.median([m.d_optimality for m in values])
        std = np.median([m.max_cramer_rao_std for m in values])
        cond = np.median([m.condition_number for m in values])
        print(f"{name} | {d:.1f} | {std:.3g} | {cond:.3g}")


if __name__ == "__main__":
    main()
