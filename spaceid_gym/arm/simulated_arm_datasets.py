"""Simulated arm datasets: run :class:`~spaceid_gym.arm.torque_simulator.ArmSimulator` on an excitation, write a folder.

The folder has the layout of the free-floating datasets (:mod:`spaceid_gym.log`), every file
written atomically:

| file | content |
|---|---|
| ``log.csv`` | the :class:`~spaceid_gym.arm.joint_log.ArmLog` CSV: ``t,q1..qN,dq1..dqN,ddq1..ddqN,tau1..tauN`` (or ``i1..iN``); measured q, dq and effort; ``ddq`` is the simulator's true acceleration (not a measurement) |
| ``robot.urdf`` | the robot as the estimators get it (the URDF's nominal inertias, no friction) |
| ``truth.json`` | ``parameters`` (name -> true value), ``base_parameters`` (combination -> value), friction model, noise, controller, rates, trajectory, seed, tracking error and torque use |

Random streams: the seed's generator is split (``Generator.spawn``) into four independent
streams, for the true parameters, the trajectory, the sensor noise and the base-parameter
structure, so changing the trajectory does not change the robot or the noise of a seed.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from spaceid_gym.arm.arm_robot import ArmRobot, load_arm
from spaceid_gym.arm.excitation_design import (
    FourierTrajectory,
    optimise_excitation,
    random_fourier_trajectory,
    regressor_condition,
)
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.parameter_prior import ParameterPrior
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet
from spaceid_gym.arm.torque_simulator import INTERNAL_RATE_HZ, SAMPLE_RATE_HZ, ArmSimulation, ArmSimulator
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import write_dataset

TRAJECTORIES = ("fourier", "optimised")


@dataclass(frozen=True, eq=False)
class ArmDataset:
    """A written simulated dataset: its ``path``, the :class:`ArmSimulation` (with the noise-free log) and the ``truth`` written."""

    path: Path
    simulation: ArmSimulation
    truth: dict[str, Any]


def simulate_arm_dataset(
    robot: str | ArmRobot,
    duration_s: float,
    friction: FrictionModel | Sequence[str] | None,
    seed: int,
    trajectory: str | FourierTrajectory,
    out_dir: str | Path,
    *,
    sample_rate_hz: float = SAMPLE_RATE_HZ,
    internal_rate_hz: float = INTERNAL_RATE_HZ,
    sensors: ArmSensorModel | str | None = None,
    parameters: np.ndarray | None = None,
    prior: ParameterPrior | None = None,
) -> ArmDataset:
    """Simulate ``duration_s`` of the arm on an excitation and write the dataset folder ``out_dir``.

    Args:
        robot: ``"ur5"``, a URDF path or an :class:`ArmRobot`.
        duration_s: length of the log, s.
        friction: friction terms of the true robot (e.g. ``("coulomb", "viscous")``; ``None`` = none).
        seed: the seed of every random draw (see the module docstring).
        trajectory: ``"fourier"`` (random feasible Fourier series, 5 harmonics of 0.1 Hz),
            ``"optimised"`` (:func:`~spaceid_gym.arm.excitation_design.optimise_excitation`, condition
            number, a few seconds) or a :class:`FourierTrajectory`.
        out_dir: the folder (created; existing files replaced).
        sample_rate_hz, internal_rate_hz: log and RK4 rates, Hz.
        sensors: :class:`ArmSensorModel` (default noise), or ``"noise_free"``.
        parameters: true parameters in :class:`ArmRegressor` order (default: drawn from ``prior``).
        prior: :class:`ParameterPrior` of the draw (default settings).

    Returns:
        the folder, the :class:`ArmSimulation` (with the noise-free log) and the truth written.
    """
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise SpaceIdInputError(f"duration: expected a positive number of seconds, got {duration_s!r}")
    arm = robot if isinstance(robot, ArmRobot) else load_arm(robot)
    regressor = ArmRegressor(arm, friction)
    prior = prior if prior is not None else ParameterPrior()
    parameter_rng, trajectory_rng, noise_rng, structure_rng = np.random.default_rng(seed).spawn(4)
    p = prior.draw(regressor, parameter_rng) if parameters is None else np.asarray(parameters, dtype=float)
    with threadpool_limits(limits=1):  # a 1800 x 72 QR: BLAS threads slow it down several times on a busy 2-core machine
        base = BaseParameterSet.from_regressor(regressor, structure_rng)
    excitation: dict[str, Any] = {}
    if isinstance(trajectory, FourierTrajectory):
        reference, excitation["kind"] = trajectory, "given"
    elif trajectory == "fourier":
        reference, excitation["kind"] = random_fourier_trajectory(arm, trajectory_rng), "fourier"
    elif trajectory == "optimised":
        result = optimise_excitation(regressor, base, rng=trajectory_rng)
        reference, excitation["kind"] = result.trajectory, "optimised"
        excitation["optimisation"] = result.summary()
    else:
        raise SpaceIdInputError(f"trajectory: expected one of {list(TRAJECTORIES)} or a FourierTrajectory, got {trajectory!r}")
    if reference.n_joints != arm.n_joints:
        raise SpaceIdInputError(f"trajectory: has {reference.n_joints} joints, the robot {arm.n_joints}")
    excitation["condition_number"] = regressor_condition(reference, regressor, base)[0]
    excitation["peak_ratios"] = reference.peak_ratios(arm)
    excitation.update(reference.to_dict())

    simulator = ArmSimulator(arm, p, friction, sensors, internal_rate_hz=internal_rate_hz, sample_rate_hz=sample_rate_hz)
    start = time.perf_counter()
    simulation = simulator.run(reference, duration_s, noise_rng, name=f"{arm.name}-sim")
    truth = dict(simulation.truth)
    truth.update(
        seed=seed,
        base_parameters=dict(zip(base.names, base.to_base(p).tolist(), strict=True)),
        prior=prior.as_dict(),
        trajectory=excitation,
        log_ddq="true acceleration of the simulator (not a measurement)",
        simulation_wall_time_s=time.perf_counter() - start,
    )
    folder = write_dataset(out_dir, simulation.log, arm.urdf_text, truth)  # type: ignore[arg-type]  # any log with to_csv
    return ArmDataset(folder, simulation, truth)


def simulate_train_and_held_out(
    robot: str | ArmRobot,
    friction: FrictionModel | Sequence[str] | None,
    train: tuple[float, int, str],
    held: tuple[float, int, str],
    out_dir: str | Path,
) -> tuple[ArmDataset, ArmDataset]:
    """Two datasets of the same true robot: ``train`` = (duration s, seed, trajectory) draws the robot and is written to
    ``out_dir/train``; ``held`` = (duration s, seed, trajectory) reuses its parameters, with its own excitation and
    noise, in ``out_dir/held`` (:func:`simulate_arm_dataset` for both)."""
    folder = Path(out_dir)
    first = simulate_arm_dataset(robot, train[0], friction, train[1], train[2], folder / "train")
    parameters = np.array(list(first.truth["parameters"].values()))
    second = simulate_arm_dataset(robot, held[0], friction, held[1], held[2], folder / "held", parameters=parameters)
    return first, second
