"""The friction model's two fixed velocities from the command line: ``--stribeck-velocity`` (``vs`` of the Stribeck
term) and ``--coulomb-smoothing`` (``v_eps`` of the smooth sign) reach our model, UR's refitted model and the
candidates of ``arm diagnose``; bad values stop the command with an error naming the option."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimators.arm.arm_diagnosis import extended_model
from estimators.arm.controller_model import controller_model_leave_one_out, load_controller_rows
from estimators.arm.identification import Preparation, leave_one_out, load_movements
from estimators.arm.model import ArmIdentificationModel
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.cli import main

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
MOVEMENTS = ["Movement_No5_Acc_slow_no_disturbance", "Movement_No8_Singularity_Free_1", "Movement_No9_Singularity_Free_NoDist"]


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--stribeck-velocity", "0"),
        ("--stribeck-velocity", "-0.05"),
        ("--stribeck-velocity", "nan"),
        ("--coulomb-smoothing", "-0.01"),
    ],
)
def test_bad_velocities_stop_every_command_with_the_option_named(tmp_path: Path, capsys, option: str, value: str) -> None:
    for command in ("identify", "cross-validate", "diagnose"):
        assert main(["arm", command, "--data", str(tmp_path), option, value, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert option in err and "Traceback" not in err


def test_the_diagnosis_candidates_keep_the_models_velocities() -> None:
    friction = FrictionModel(("coulomb", "viscous"), coulomb_smoothing_rad_s=0.02, stribeck_velocity_rad_s=0.3)
    extended = extended_model(ArmIdentificationModel.build(load_arm("ur5"), friction), "stribeck")
    assert extended is not None
    assert extended.regressor.friction == FrictionModel(("coulomb", "viscous", "stribeck"), 0.02, 0.3)


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_cross_validate_fits_the_velocities_given(tmp_path: Path) -> None:
    """The command's held-out errors, ours and UR's refitted model's, are those of models built with the velocities
    given, and differ from those of the default velocities."""
    terms = ("coulomb", "viscous", "stribeck")
    args = ["arm", "cross-validate", "--data", str(UR5_REAL), "--movements", ",".join(MOVEMENTS), "--estimators", "wls"]
    args += ["--friction", ",".join(terms), "--compare-ur-model", "--ur-model-friction", ",".join((*terms, "offset"))]
    assert main([*args, "--stribeck-velocity", "0.3", "--coulomb-smoothing", "0.02", "--out", str(tmp_path / "c")]) == 0
    written = json.loads((tmp_path / "c" / "rows.json").read_text())
    assert written["friction_velocities_rad_s"] == {"coulomb_smoothing": 0.02, "stribeck": 0.3}
    command = np.array([r["overall_percent"] for r in written["rows"]])

    def direct(friction: FrictionModel) -> np.ndarray:
        logs, preparation = load_movements(UR5_REAL, MOVEMENTS), Preparation()
        model = ArmIdentificationModel.build(load_arm("ur5"), friction)
        ours = leave_one_out({"m": model}, logs, {"wls": estimator_from_spec("wls", seed=0)}, preparation)
        ur_friction = FrictionModel((*terms, "offset"), friction.coulomb_smoothing_rad_s, friction.stribeck_velocity_rad_s)
        ur, _ = controller_model_leave_one_out(load_controller_rows(UR5_REAL, logs, preparation, ur_friction))
        return np.array([r.error.overall_percent for r in (*ours, *ur)])

    np.testing.assert_allclose(command, direct(FrictionModel(terms, 0.02, 0.3)), rtol=1e-9)
    assert np.max(np.abs(command - direct(FrictionModel(terms)))) > 0.01
