"""The excitation agent end to end (train a few hundred steps, save, load, drive the env, identify) and its bad inputs.

Nothing here asserts on what the agent learnt: a few hundred steps are noise; the benchmark shows the learning.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import agents
from agents.comparison import held_out_setting
from agents.policy import ExcitationEnv, ExcitationPolicy, rate_command, train_excitation
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.fuel_excitation_design import optimise_fourier_excitation, write_fourier_design
from spaceid_gym.log import load_dataset
from spaceid_gym.robots import load_robot


@pytest.fixture(scope="module")
def policy_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("agent") / "policy"
    train_excitation("quick3", timesteps=256, out=out, n_envs=1, eval_episodes=1, n_evaluations=1, progress_bar=False)
    return out


def test_tiny_training_saves_loads_drives_the_env_and_identifies(policy_folder: Path) -> None:
    assert {"policy.json", "model.zip", "checkpoints", "eval"} <= {p.name for p in policy_folder.iterdir()}
    metadata = json.loads((policy_folder / "policy.json").read_text())
    assert metadata["robot"] == "quick3" and metadata["params"] == "fuel" and metadata["timesteps"] == 256
    policy = ExcitationPolicy.load(policy_folder, robot="quick3", params="fuel")
    robot = load_robot("quick3")
    env = simulate_episode(robot, 6.0, 12.0, np.array([0.05, -0.02, 0.03]), policy, seed=5)
    log = env.measurement_log()
    assert log.n_samples == 301 and np.isfinite(log.q_rad).all()
    inside = (log.q_rad >= robot.q_lower_rad) & (log.q_rad <= robot.q_upper_rad)
    assert inside.all()
    estimate = make_estimator("hybrid", seed=0).fit(IdentificationModel(robot, "fuel"), log)
    assert np.isfinite(estimate.theta).all()
    assert math.isfinite(env.excitation_measures().d_optimality)


def test_simulate_cli_drives_the_arm_with_a_policy_folder(policy_folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    code = main(["simulate", "--robot", "quick3", "--duration", "2", "--excitation", str(policy_folder), "--out", str(out)])
    assert code == 0
    truth = load_dataset(out).truth
    assert truth is not None and truth["excitation"]["kind"] == "policy"


def test_rate_command_follows_targets_inside_the_range() -> None:
    robot = load_robot("quick3")
    mid = 0.5 * (robot.q_lower_rad + robot.q_upper_rad)
    np.testing.assert_allclose(rate_command(np.zeros(3, dtype=np.float32), mid, robot), 0.0, atol=1e-6)
    assert (rate_command(np.ones(3, dtype=np.float32), mid, robot) == 1.0).all()  # far from the target: full rate
    env = ExcitationEnv("quick3", window_s=5.0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and np.isfinite(obs).all()


def test_bad_policy_inputs_name_what_is_wrong(policy_folder: Path, tmp_path: Path) -> None:
    with pytest.raises(SpaceIdInputError, match=r"trained for robot 'quick3' \(FreeFloatingID-v0\), not 'paper6'"):
        ExcitationPolicy.load(policy_folder, robot="paper6")
    with pytest.raises(SpaceIdInputError, match="trained for parameterisation 'fuel', not 'base'"):
        ExcitationPolicy.load(policy_folder, params="base")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "policy.json").write_text((policy_folder / "policy.json").read_text())
    (corrupt / "model.zip").write_bytes(b"PK\x03\x04 this is not a zip archive")
    with pytest.raises(SpaceIdInputError, match=r"model\.zip: corrupt or unreadable policy model"):
        ExcitationPolicy.load(corrupt)
    with pytest.raises(SpaceIdInputError, match="not a policy folder"):
        ExcitationPolicy.load(tmp_path)
    for timesteps in (0, -5):
        with pytest.raises(SpaceIdInputError, match="timesteps: expected a positive integer"):
            train_excitation("quick3", timesteps=timesteps)
    with pytest.raises(SpaceIdInputError, match="params"):
        train_excitation("quick3", params="base", timesteps=10)
    for argv in (
        ["excite", "train", "--robot", "quick3", "--timesteps", "0", "--out", str(tmp_path / "p")],
        ["simulate", "--robot", "paper6", "--duration", "1", "--excitation", str(policy_folder), "--out", str(tmp_path / "r")],
        ["excite", "compare", "--robot", "quick3", "--policy", str(corrupt), "--episodes", "1", "--out", str(tmp_path / "c")],
        ["excite", "compare", "--robot", "quick3", "--first-window", "-1", "--episodes", "1", "--out", str(tmp_path / "w")],
    ):
        assert main(argv) == 2


def test_compare_cli_writes_the_table_and_plots(policy_folder: Path, tmp_path: Path) -> None:
    robot = load_robot("quick3")
    design = optimise_fourier_excitation(robot, 4.0, n_harmonics=2, n_starts=1, n_grid=20, n_constraint_grid=40, max_iterations=5)
    fourier = write_fourier_design(tmp_path / "traj.json", design, robot)
    out = tmp_path / "exc"
    argv = ["excite", "compare", "--robot", "quick3", "--policy", str(policy_folder), "--fourier", str(fourier)]
    assert main([*argv, "--episodes", "1", "--duration", "4", "--jobs", "1", "--first-window", "7", "--out", str(out)]) == 0
    seed = int(next(csv.DictReader((out / "episodes.csv").open()))["seed"])
    assert seed == held_out_setting("quick3", 7)[0]  # the windows start where asked
    assert {"episodes.csv", "summary.csv", "table.md", "errors.png", "pareto.png"} <= {p.name for p in out.iterdir()}
    rows = [line for line in (out / "table.md").read_text().splitlines() if line.startswith("| ")]
    assert [row.split("|")[1].strip() for row in rows[1:]] == [
        "random",
        "one_joint",
        "fourier",
        "policy",
        "random_targets",
        "fourier_equal_attitude",
    ]


def test_agents_package_offers_the_learnt_policy_api() -> None:
    assert agents.ExcitationPolicy is ExcitationPolicy and agents.train_excitation is train_excitation
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = agents.nothing  # type: ignore[attr-defined]
