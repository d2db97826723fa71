"""UR's own model refitted (per joint: gain x m_target + friction), the real UR5's comparison baseline: it recovers a
known gain and friction from a synthetic movement, runs on the same folds and samples as the identification, and is a
row of ``spaceid arm cross-validate --compare-ur-model``."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from estimators.arm.controller_model import (
    CONTROLLER_MODEL_LABEL,
    controller_model_leave_one_out,
    controller_rows,
    fit_controller_model,
)
from estimators.arm.identification import Preparation, load_movements
from estimators.arm.model import ArmIdentificationModel
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.cli import main
from spaceid_gym.errors import SpaceIdInputError

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
GAIN = np.array([0.13, 0.15, 0.14, 0.36, 0.31, 0.29])  # A / (N m)
FRICTION = np.array([[0.2, 0.05, 0.01]] * 6)  # A, A s/rad, A: Coulomb, viscous, offset


def _movement(seed: int, noise_A: float) -> tuple[ArmLog, ArmLog]:
    """A synthetic movement: smooth joint motion, a torque signal, and the current the per-joint model makes of it."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 0.008)
    frequency, phase = rng.uniform(0.1, 0.5, 6), rng.uniform(0, 2 * np.pi, 6)
    q = np.sin(2 * np.pi * frequency * t[:, None] + phase)
    dq = 2 * np.pi * frequency * np.cos(2 * np.pi * frequency * t[:, None] + phase)
    torque = 10.0 * np.sin(2 * np.pi * 0.7 * frequency * t[:, None] + 2 * phase) + 5.0 * q
    current = GAIN * torque + np.einsum("tjk,jk->tj", FrictionModel(("coulomb", "viscous", "offset")).features(dq), FRICTION)
    current = current + noise_A * rng.standard_normal(current.shape)
    log = ArmLog(t, q, dq, None, current, "current_A", f"m{seed}")
    return log, dataclasses.replace(log, effort=torque, effort_kind="torque_Nm")


def test_refit_recovers_the_gain_and_friction_of_a_synthetic_movement() -> None:
    preparation = Preparation()
    rows = [controller_rows(preparation, *_movement(seed, 0.0)) for seed in (1, 2)]
    coefficients = fit_controller_model(rows)
    np.testing.assert_allclose(coefficients[:, 0], GAIN, rtol=1e-3)
    np.testing.assert_allclose(coefficients[:, 1:], FRICTION, rtol=2e-2, atol=2e-3)
    noisy = {f"m{s}": controller_rows(preparation, *_movement(s, 0.05)) for s in (3, 4, 5)}
    table, fitted = controller_model_leave_one_out(noisy)
    assert [r.error.movement for r in table] == list(noisy) and all(r.model == CONTROLLER_MODEL_LABEL for r in table)
    assert all(np.allclose(c[:, 0], GAIN, rtol=2e-2) for c in fitted.values())
    torque = _movement(1, 0.0)[1]
    with pytest.raises(SpaceIdInputError, match="needs a current log"):
        controller_rows(preparation, torque, torque)


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_real_logs_same_samples_as_the_identification_and_the_command(tmp_path: Path, capsys) -> None:
    names = ["Movement_No8_Singularity_Free_1", "Movement_No9_Singularity_Free_NoDist"]
    preparation = Preparation()
    currents = load_movements(UR5_REAL, names)
    torques = load_movements(UR5_REAL, names, effort="m_target")
    model = ArmIdentificationModel.build(load_arm("ur5"), ("coulomb", "viscous"))
    for name in names:
        ours = preparation.rows(model, currents[name]).log
        theirs = controller_rows(preparation, currents[name], torques[name]).log
        np.testing.assert_array_equal(ours.t_s, theirs.t_s)
        np.testing.assert_array_equal(ours.effort, theirs.effort)
    out = tmp_path / "cv"
    args = ["arm", "cross-validate", "--data", str(UR5_REAL), "--movements", ",".join(names), "--estimators", "wls"]
    assert main([*args, "--compare-ur-model", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert CONTROLLER_MODEL_LABEL in text and "torque constants UR's refitted model implies" in text
    written = json.loads((out / "rows.json").read_text())
    assert [r["model"] for r in written["rows"]].count(CONTROLLER_MODEL_LABEL) == 2
    table = (out / "table.md").read_text()
    assert table.count(f"| {CONTROLLER_MODEL_LABEL} |") == 2 and table.count(f"| **{CONTROLLER_MODEL_LABEL}** |") == 1


def test_the_option_on_simulated_data_is_a_clear_error(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "sim"
    folder.mkdir()
    for seed in (1, 2):
        (folder / f"m{seed}").mkdir()
        _movement(seed, 0.0)[0].to_csv(folder / f"m{seed}" / "log.csv")
    code = main(
        [
            "arm",
            "cross-validate",
            "--data",
            str(folder),
            "--estimators",
            "ols",
            "--compare-ur-model",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert code == 2
    assert "--compare-ur-model" in capsys.readouterr().err
