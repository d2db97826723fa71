"""The arm's excitation comparison on ``ManipulatorID-v0``: random multi-sines, one joint at a time and the arm's
optimised Fourier trajectories, on the same windows.

Every method drives the same windows of ``ManipulatorID-v0`` (the UR5 with Coulomb + viscous friction, rate actions,
125 Hz, default sensors, the env's rate, acceleration and joint limits, equal duration): window i is
``env.reset(seed=HELD_OUT_FIRST_SEED + first_window + i)``, which draws the robot's true parameters from the prior
and the start pose (within 0.3 rad of the middle of each range) and seeds the sensor noise. The methods are
normalised joint-rate commands (time, s -> action in [-1, 1]):

* ``random``: the random multi-sine of the free-floating comparison (:class:`~spaceid_gym.excitation.FourierExcitation`,
  5 harmonics of 0.025 Hz, seeded by the window's seed);
* ``random_0.1hz``: the same with 5 harmonics of 0.1 Hz (periods of 2 - 10 s, within a 30 s window);
* ``one_joint``: the source paper's one joint at a time (:class:`~spaceid_gym.fuel_excitation_design.OneJointExcitation`,
  the window split into n slots, one sine cycle of joint i in slot i);
* ``fourier``: the arm's optimised Fourier trajectory
  (:func:`~spaceid_gym.arm.excitation_design.optimise_excitation`, condition-number criterion, 5 harmonics of
  0.1 Hz, seeded starts), its rates ``dq(t) / rate limit`` followed from the env's start pose;
* ``fourier_d``: the same optimised for D-optimality;
* ``policy`` (when a policy folder is given): the learnt excitation of :mod:`agents.arm_policy`, which picks a target
  angle per joint every 0.5 s from the measured state and the information so far;
* ``random_targets`` (with ``policy``): the policy's action space without the learning, uniform random targets every
  0.5 s followed like the policy's (:class:`~agents.policy.RandomTargets`, seeded by the window's seed).

Per window and method: the env's excitation measures of the torque data about the 48 base parameters in prior-std
units (:meth:`ManipulatorIDEnv.excitation_measures`): D-optimality ``log det F``, the condition number of ``F`` (the
square of the scaled, noise-weighted regressor's) and the largest Cramér-Rao std; the error of a least-squares fit
of the base parameters to the window's log (weighted by the known torque noise; measured angles and rates, the
simulator's true acceleration), in prior stds: median and largest over the 48; and the env's limit penalties summed
over the window (0 when no joint or torque came near its limit).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.comparison import write_tables
from agents.policy import HELD_OUT_FIRST_SEED, ExcitationPolicy, RandomTargets
from estimators.arm.linear_ls import weighted_lstsq
from estimators.arm.linear_problem import LinearIdentificationProblem
from spaceid_gym.arm.excitation_design import ExcitationResult, optimise_excitation
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.datasets import FeedbackExcitation
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.fuel_excitation_design import OneJointExcitation

#: the methods, in table order
ARM_METHODS = ("random", "random_0.1hz", "one_joint", "fourier", "fourier_d")
#: the methods added after them when a policy is given
ARM_POLICY_METHODS = ("policy", "random_targets")
#: the optimised trajectories' criteria (:func:`optimise_excitation`)
_CRITERIA = {"fourier": "condition", "fourier_d": "d-optimal"}

Command = Callable[[float], np.ndarray] | FeedbackExcitation


def optimise_arm_designs(env: ManipulatorIDEnv, seed: int = 0, n_starts: int = 2) -> dict[str, ExcitationResult]:
    """The optimised Fourier trajectories of the comparison (``fourier``, ``fourier_d``) for the env's arm and base
    parameters, from seeded starts."""
    return {
        name: optimise_excitation(
            env.regressor, env.base, rng=np.random.default_rng(seed), criterion=criterion, n_starts=n_starts
        )
        for name, criterion in _CRITERIA.items()
    }


def _commands(
    env: ManipulatorIDEnv,
    designs: dict[str, ExcitationResult],
    duration_s: float,
    seed: int,
    policy: ExcitationPolicy | None,
) -> dict[str, Command]:
    n, limit = env.robot.n_joints, env.robot.dq_limit_rad_s

    def follow(result: ExcitationResult) -> Command:
        return lambda t: np.clip(result.trajectory.state(t)[1] / limit, -1.0, 1.0)

    commands: dict[str, Command] = {
        "random": FourierExcitation(n, seed),
        "random_0.1hz": FourierExcitation(n, seed, base_frequency_hz=0.1),
        "one_joint": OneJointExcitation(n, duration_s),
        **{name: follow(result) for name, result in designs.items()},
    }
    if policy is not None:
        commands.update(policy=policy, random_targets=RandomTargets(seed))
    return commands


def _window(env: ManipulatorIDEnv, command: Command, seed: int, steps: int) -> dict[str, float]:
    """Drive one window and return its measures (see the module docstring)."""
    observation, info = env.reset(seed=seed)
    feedback = isinstance(command, FeedbackExcitation)
    if feedback:
        command.start(env)
    penalty = 0.0
    for k in range(steps):
        action = command.act(observation) if feedback else command(k * env.control_period_s)
        observation, _, _, _, info = env.step(np.asarray(action, dtype=np.float32))
        penalty += info["penalty_joint_limit"] + info["penalty_torque_limit"]
    measures = env.excitation_measures()
    log = env.measurement_log()
    rows = env.base.base_regressor(env.regressor.regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2)).reshape(-1, env.base.rank)
    sigma = np.broadcast_to(ArmSensorModel().torque_std_Nm(), log.effort.shape).reshape(-1)
    truth = np.array(info["truth"]["base_parameters"])
    scale = env.prior.base_parameter_std(env.regressor, env.base)
    problem = LinearIdentificationProblem(
        rows, log.effort.reshape(-1), env.base.names, truth - 10 * scale, truth + 10 * scale, row_std=sigma
    )
    estimate, _ = weighted_lstsq(problem, sigma)
    error = np.abs(estimate - truth) / scale
    return {
        "d_optimality": measures.d_optimality,
        "condition_number": measures.condition_number,
        "max_cramer_rao_std": measures.max_cramer_rao_std,
        "error_median_prior_std": float(np.median(error)),
        "error_max_prior_std": float(np.max(error)),
        "limit_penalty": penalty,
    }


def run_arm_comparison(
    episodes: int,
    duration_s: float = 30.0,
    first_window: int = 0,
    designs: dict[str, ExcitationResult] | None = None,
    env: ManipulatorIDEnv | None = None,
    policy: ExcitationPolicy | None = None,
) -> list[dict[str, Any]]:
    """One row per window and method (:data:`ARM_METHODS` order within a window, then :data:`ARM_POLICY_METHODS` with
    a policy); see the module docstring.

    Args:
        episodes: windows (>= 1).
        duration_s: each window, s (at least one control period).
        first_window: index of the first window (>= 0): windows ``first_window .. first_window + episodes - 1``.
        designs: the optimised trajectories (default :func:`optimise_arm_designs` with seed 0).
        env: the env (default ``ManipulatorIDEnv()``; the sensors must be noisy, the default).
        policy: a learnt excitation for the env's arm (adds the ``policy`` and ``random_targets`` rows).
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise SpaceIdInputError(f"episodes: expected an integer >= 1, got {episodes!r}")
    if not isinstance(first_window, int) or first_window < 0:
        raise SpaceIdInputError(f"first_window: expected an index >= 0, got {first_window!r}")
    env = ManipulatorIDEnv() if env is None else env
    steps = round(duration_s / env.control_period_s) if np.isfinite(duration_s) else 0
    if steps < 1:
        raise SpaceIdInputError(
            f"duration_s: expected at least one control period ({env.control_period_s} s), got {duration_s!r}"
        )
    designs = optimise_arm_designs(env) if designs is None else designs
    rows = []
    for i in range(first_window, first_window + episodes):
        seed = HELD_OUT_FIRST_SEED + i
        for method, command in _commands(env, designs, duration_s, seed, policy).items():
            rows.append({"method": method, "window": i, "seed": seed, **_window(env, command, seed, steps)})
    return rows


def summarise_arm(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method: windows and the median of each measure over them (the largest error's 95th percentile too)."""
    keys = (
        "d_optimality",
        "condition_number",
        "max_cramer_rao_std",
        "error_median_prior_std",
        "error_max_prior_std",
        "limit_penalty",
    )
    summary = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        entry: dict[str, Any] = {"method": method, "windows": len(mine)}
        entry.update({key: statistics.median(r[key] for r in mine) for key in keys})
        entry["error_max_p95_prior_std"] = float(np.percentile([r["error_max_prior_std"] for r in mine], 95))
        summary.append(entry)
    return summary


#: the table's columns: header and the cell's format of a summary entry
_TABLE = (
    ("method", "{method}"),
    ("windows", "{windows}"),
    ("D-optimality log det F", "{d_optimality:.1f}"),
    ("condition number of F", "{condition_number:.3g}"),
    ("largest CR std (prior std)", "{max_cramer_rao_std:.3g}"),
    ("LS error, median / largest (prior std)", "{error_median_prior_std:.3g} / {error_max_prior_std:.3g}"),
    ("largest, 95th pct", "{error_max_p95_prior_std:.3g}"),
    ("limit penalty", "{limit_penalty:.3g}"),
)


def arm_markdown_table(summary: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table (medians over the windows)."""
    rows = [[header for header, _ in _TABLE], ["---"] * len(_TABLE)]
    rows += [[cell.format(**entry) for _, cell in _TABLE] for entry in summary]
    return "".join("| " + " | ".join(row) + " |\n" for row in rows)


def write_arm_comparison(out: str | Path, rows: list[dict[str, Any]], info: dict[str, Any]) -> dict[str, Path]:
    """Write ``episodes.csv``, ``summary.csv`` and ``table.md`` (the settings in ``info`` as comments) to ``out``."""
    summary = summarise_arm(rows)
    return write_tables(Path(out), rows, summary, arm_markdown_table(summary), info)
