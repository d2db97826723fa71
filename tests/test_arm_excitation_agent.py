"""The arm's excitation agent (``ManipulatorID-v0``) end to end (train a few hundred steps, save, load, drive held-out
windows, identify) and its bad inputs.

Nothing here asserts on what the agent learnt: a few hundred steps are noise; docs/results.md shows the learning.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agents.arm_comparison import ARM_METHODS, ARM_POLICY_METHODS, run_arm_comparison
from agents.arm_policy import ArmExcitationEnv, arm_policy_features
from agents.excitation_task import HELD_OUT_FIRST_SEED
from agents.policy import ExcitationPolicy, RandomTargets, train_excitation
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.cli import main
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.errors import SpaceIdInputError

SATELLITE_POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "paper6"


@pytest.fixture(scope="module")
def arm_policy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("arm-agent") / "policy"
    train_excitation("ur5", timesteps=128, out=out, n_envs=1, eval_episodes=1, n_evaluations=1, progress_bar=False)
    return out


def test_tiny_arm_training_saves_loads_drives_held_out_windows_and_identifies(arm_policy: Path) -> None:
    assert {"policy.json", "model.zip", "checkpoints", "eval"} <= {p.name for p in arm_policy.iterdir()}
    metadata = json.loads((arm_policy / "policy.json").read_text())
    assert (metadata["env"], metadata["robot"], metadata["params"], metadata["timesteps"]) == (
        "ManipulatorID-v0",
        "ur5",
        "base",
        128,
    )
    policy = ExcitationPolicy.load(arm_policy, robot="ur5", params="base")
    env = ManipulatorIDEnv()
    rows = run_arm_comparison(1, 1.0, first_window=7, designs={}, env=env, policy=policy)
    assert [r["method"] for r in rows] == [*ARM_METHODS[:3], *ARM_POLICY_METHODS]
    assert all(r["seed"] == HELD_OUT_FIRST_SEED + 7 for r in rows)
    for row in rows[-2:]:  # the policy's and random targets' windows were identified
        assert np.isfinite([row["d_optimality"], row["error_median_prior_std"]]).all() and row["limit_penalty"] >= 0.0


def test_arm_features_hold_the_uncertainty_so_far() -> None:
    """The features' uncertainty block against the information rebuilt in one batch from the window's log (noise-free
    sensors: the log holds the true states), prior added: ``F = I + J^T J``."""
    wrapper = ArmExcitationEnv(window_s=1.0)
    observation, _ = wrapper.reset(seed=3)
    assert observation.shape == wrapper.observation_space.shape and np.isfinite(observation).all()
    env = ManipulatorIDEnv(sensors="noise_free")
    observation, _ = env.reset(seed=3)
    targets = RandomTargets(1)
    targets.start(env)
    for _ in range(40):
        observation = env.step(targets.act(observation))[0]
    features = arm_policy_features(observation, env, 0.25)
    log = env.measurement_log()
    Y = env.base.base_regressor(env.regressor.regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2))
    sigma = ArmSensorModel().torque_std_Nm()
    J = (Y * env.prior.base_parameter_std(env.regressor, env.base) / sigma[None, :, None]).reshape(-1, env.base.rank)
    information = np.eye(env.base.rank) + J.T @ J
    n, rank = env.robot.n_joints, env.base.rank
    assert features[3 * n] == 0.25
    np.testing.assert_allclose(
        features[3 * n + 1 : 3 * n + 1 + rank], np.log10(np.sqrt(np.diag(np.linalg.inv(information)))), atol=1e-6
    )
    np.testing.assert_allclose(features[3 * n + 1 + rank :], -0.5 * np.log10(np.linalg.eigvalsh(information)[:4]), atol=1e-6)
    np.testing.assert_allclose(features[n : 2 * n], observation[n : 2 * n] / env.robot.dq_limit_rad_s)


def test_random_targets_and_policy_drive_only_their_env(arm_policy: Path) -> None:
    policy = ExcitationPolicy.load(arm_policy)
    satellite = FreeFloatingIDEnv("quick3")
    satellite.reset(seed=0)
    with pytest.raises(SpaceIdInputError, match="policy: drives ManipulatorID-v0, got FreeFloatingIDEnv"):
        policy.start(satellite)
    arm = ManipulatorIDEnv()
    observation, _ = arm.reset(seed=0)
    targets = RandomTargets(0)
    targets.start(arm)
    command = targets.act(observation)
    assert command.shape == (6,) and (np.abs(command) <= 1.0).all()


def test_bad_arm_policy_inputs_name_what_is_wrong(arm_policy: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SpaceIdInputError, match=r"trained for robot 'paper6' \(FreeFloatingID-v0\), not 'ur5'"):
        ExcitationPolicy.load(SATELLITE_POLICY, robot="ur5", params="base")
    with pytest.raises(SpaceIdInputError, match=r"trained for robot 'ur5' \(ManipulatorID-v0\), not 'paper6'"):
        ExcitationPolicy.load(arm_policy, robot="paper6", params="fuel")
    for timesteps in (0, -3):
        with pytest.raises(SpaceIdInputError, match="timesteps: expected a positive integer"):
            train_excitation("ur5", timesteps=timesteps)
    with pytest.raises(SpaceIdInputError, match=r"params: the agent for 'ur5' is trained for \['base'\], got 'fuel'"):
        train_excitation("ur5", params="fuel", timesteps=10)
    with pytest.raises(SpaceIdInputError, match="fixed base"):
        train_excitation("ur5", timesteps=10, attitude_weight=0.1)
    with pytest.raises(SpaceIdInputError, match="log_std_init: expected a finite number"):
        train_excitation("ur5", timesteps=10, log_std_init=float("nan"))
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "policy.json").write_text((arm_policy / "policy.json").read_text())
    (corrupt / "model.zip").write_bytes(b"PK\x03\x04 not a zip")
    out = str(tmp_path / "out")
    for argv, message in (
        (["excite", "compare-arm", "--policy", str(SATELLITE_POLICY), "--episodes", "1", "--out", out], "robot 'paper6'"),
        (["excite", "compare-arm", "--policy", str(corrupt), "--episodes", "1", "--out", out], "corrupt"),
        (["excite", "compare-arm", "--policy", str(arm_policy), "--no-policy", "--out", out], "--no-policy"),
        (["excite", "compare", "--robot", "paper6", "--policy", str(arm_policy), "--episodes", "1", "--out", out], "'ur5'"),
        (["simulate", "--robot", "paper6", "--duration", "1", "--excitation", str(arm_policy), "--out", out], "'ur5'"),
        (["excite", "train", "--robot", "ur5", "--timesteps", "0", "--out", out], "timesteps"),
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
