"""Torque constants identified with the dynamic parameters (``--identify-gains``): a simulated UR5 logged in current
with a model given wrong constants gets the true ones back within what the data determine, the scale needs a
reference, and the commands take the option."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimators.arm.gains import identify_gains, scaled_rows
from estimators.arm.identification import Preparation
from estimators.arm.model import ArmIdentificationModel
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.real_logs import UR5_TORQUE_CONSTANTS_NM_A
from spaceid_gym.arm.simulated_arm_datasets import simulate_arm_dataset
from spaceid_gym.cli import main
from spaceid_gym.errors import SpaceIdInputError

K_TRUE = np.array(UR5_TORQUE_CONSTANTS_NM_A)
WRONG = np.array([1.15, 1.0, 0.85, 1.25, 0.8, 1.1])  # the model's constants over the true ones; joint 2 right
FRICTION = ("coulomb", "viscous")


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    ur5 = load_arm("ur5")
    model = ArmIdentificationModel.build(ur5, FRICTION, torque_constants_Nm_A=K_TRUE * WRONG)
    root = tmp_path_factory.mktemp("gains")
    logs = {
        seed: simulate_arm_dataset(
            ur5, 20.0, FRICTION, seed, "fourier", root / f"s{seed}", sensors=ArmSensorModel(effort_kind="current_A")
        ).simulation.log
        for seed in (1, 3)
    }
    return ur5, model, logs, root


def test_true_gains_come_back_within_their_cramer_rao_std(setting) -> None:
    """Joint 2 as the reference: on two seeds the ALS/Newton iteration converges, every gain whose Cramér-Rao std is
    below 15 % is within 4 std of the truth (over seeds 1-4 tried, |z| <= 1.5), and the wrong constants were far
    outside that (joint 3's std is about 1 %, its error 15 %). Joint 6's gain is not determined by a 20 s log
    (std 70-230 %): the test says so rather than asserting it."""
    _, model, logs, _ = setting
    preparation = Preparation()
    kappa = preparation.correlation_factor(float(np.median(np.diff(logs[1].t_s))))
    for log in logs.values():
        rows = preparation.all_rows(model, {"log": log})
        found = identify_gains(model, rows, "joint:2", kappa=kappa)
        assert found.converged
        std = found.gain_std_relative
        assert std[1] == 0.0 and std[2] < 0.02 and std[5] > 0.5
        z = np.log(found.torque_constants_Nm_A / K_TRUE) / np.where(std > 0, std, 1.0)
        informed = std < 0.15
        assert informed[:3].all() and np.all(np.abs(z[informed]) < 4.0)
        assert abs(np.log(WRONG[2])) > 10 * std[2]  # the model's wrong constant was far outside
        # the rows with the found gains predict as a model built with those constants would
        rebuilt = ArmIdentificationModel.build(model.robot, FRICTION, torque_constants_Nm_A=found.torque_constants_Nm_A)
        np.testing.assert_allclose(
            scaled_rows(rows, found.correction)["log"].regressor, preparation.rows(rebuilt, log).regressor, rtol=1e-9, atol=1e-12
        )


def test_the_scale_needs_a_reference_and_bad_input_is_named(setting) -> None:
    """Gravity and joint references differ only by one common scale: the gains' ratios are the same; several joints
    can be held at the model's constants."""
    _, model, logs, _ = setting
    rows = Preparation().all_rows(model, {"log": logs[1]})
    by_joint = identify_gains(model, rows, "joint:2").torque_constants_Nm_A
    by_gravity = identify_gains(model, rows, "gravity").torque_constants_Nm_A
    ratio = by_gravity / by_joint
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-4)
    held = identify_gains(model, rows, "joint:2,6")
    assert held.correction[1] == 1.0 and held.correction[5] == 1.0 and held.gain_std_relative[5] == 0.0
    for bad in ("joint:7", "joint:1,2,3,4,5,6", "joint:x", "payload"):
        with pytest.raises(SpaceIdInputError, match="gain-reference"):
            identify_gains(model, rows, bad)
    torque = ArmIdentificationModel.build(model.robot, FRICTION)
    with pytest.raises(SpaceIdInputError, match="needs current logs"):
        identify_gains(torque, {"t": Preparation().rows(torque, dataclasses.replace(logs[1], effort_kind="torque_Nm"))})


def test_commands_take_identify_gains(setting, tmp_path: Path, capsys) -> None:
    root = setting[3]
    args = [
        "arm",
        "cross-validate",
        "--data",
        str(root),
        "--estimators",
        "wls",
        "--identify-gains",
        "--gain-reference",
        "joint:2",
    ]
    assert main([*args, "--out", str(tmp_path / "c")]) == 0
    assert "torque constants identified" in capsys.readouterr().out
    args = ["arm", "identify", "--data", str(root), "--train", "s1", "--validate", "s3", "--identify-gains"]
    assert main([*args, "--out", str(tmp_path / "i")]) == 0
    assert "torque constants (N m/A, reference gravity" in capsys.readouterr().out
    assert main([*args[:-1], "--identify-gains", "--gain-reference", "joint:0", "--out", str(tmp_path / "e")]) == 2
