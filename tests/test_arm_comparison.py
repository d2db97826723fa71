"""The arm's excitation comparison (``spaceid excite compare-arm``): what each row reports, against references built
here, and its bad inputs.

Independent references: the Fisher information rebuilt in one batch from the window's log (regressor of all samples
at once, as in ``tests/test_manipulator_env.py``) against the row's D-optimality and condition number; with
noise-free sensors the least-squares fit must return the true base parameters.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from agents.arm_comparison import ARM_METHODS, run_arm_comparison, write_arm_comparison
from spaceid_gym.arm.excitation_design import optimise_excitation
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.cli import main
from spaceid_gym.envs.manipulator import ManipulatorIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation

DURATION_S = 3.0


@pytest.fixture(scope="module")
def env() -> ManipulatorIDEnv:
    return ManipulatorIDEnv()


@pytest.fixture(scope="module")
def designs(env: ManipulatorIDEnv) -> dict:
    """Cheap optimised trajectories (one start, few iterations): the plumbing, not the optimum."""
    return {
        name: optimise_excitation(
            env.regressor, env.base, rng=np.random.default_rng(0), criterion=criterion, n_starts=1, n_grid=12, max_iterations=3
        )
        for name, criterion in (("fourier", "condition"), ("fourier_d", "d-optimal"))
    }


def test_rows_report_the_information_of_the_windows_data(designs: dict) -> None:
    """Noise-free sensors: the log holds the true states, so the batch information is the env's, and the fit is exact."""
    quiet = ManipulatorIDEnv(sensors="noise_free")
    rows = run_arm_comparison(2, DURATION_S, first_window=3, designs=designs, env=quiet)
    assert [r["method"] for r in rows] == list(ARM_METHODS) * 2
    assert [r["window"] for r in rows] == [3] * len(ARM_METHODS) + [4] * len(ARM_METHODS)
    assert all(r["limit_penalty"] >= 0.0 for r in rows)
    # the random 0.1 Hz row of window 4 again, by hand: the same seed and commands, then F = J^T J from the whole log
    row = rows[1 + len(ARM_METHODS)]
    assert row["method"] == "random_0.1hz"
    quiet.reset(seed=row["seed"])
    command = FourierExcitation(quiet.robot.n_joints, row["seed"], base_frequency_hz=0.1)
    for k in range(round(DURATION_S / quiet.control_period_s)):
        quiet.step(command(k * quiet.control_period_s))
    log = quiet.measurement_log()
    Y = quiet.base.base_regressor(quiet.regressor.regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2))
    sigma = ArmSensorModel().torque_std_Nm()
    J = (Y * quiet.prior.base_parameter_std(quiet.regressor, quiet.base) / sigma[None, :, None]).reshape(-1, quiet.base.rank)
    eigenvalues = np.linalg.eigvalsh(J.T @ J)
    assert row["d_optimality"] == pytest.approx(np.sum(np.log(eigenvalues)), rel=1e-6)
    assert row["condition_number"] == pytest.approx(eigenvalues[-1] / eigenvalues[0], rel=1e-4)
    # exact data (a regressor of full rank, however ill-conditioned): the fit returns the true base parameters
    assert row["error_max_prior_std"] < 1e-6, row["error_max_prior_std"]


def test_writes_the_table_and_names_bad_input(env: ManipulatorIDEnv, designs: dict, tmp_path) -> None:
    rows = run_arm_comparison(1, 0.5, designs=designs, env=env)
    paths = write_arm_comparison(tmp_path, rows, {"episodes": 1})
    table = paths["table"].read_text()
    assert "<!-- episodes: 1 -->" in table and all(f"| {m} | 1 |" in table for m in ARM_METHODS)
    with paths["summary"].open() as handle:
        assert [r["method"] for r in csv.DictReader(handle)] == list(ARM_METHODS)
    for kwargs, message in (({"episodes": 0}, "episodes"), ({"episodes": 1, "first_window": -1}, "first_window")):
        with pytest.raises(SpaceIdInputError, match=message):
            run_arm_comparison(designs=designs, env=env, **kwargs)
    with pytest.raises(SpaceIdInputError, match="duration_s"):
        run_arm_comparison(1, 0.001, designs=designs, env=env)
    for argv in (
        ["excite", "compare-arm", "--episodes", "0", "--out", str(tmp_path / "a")],
        ["excite", "compare-arm", "--duration", "nan", "--out", str(tmp_path / "b")],
        ["excite", "compare-arm", "--first-window", "-2", "--out", str(tmp_path / "c")],
    ):
        assert main(argv) == 2
