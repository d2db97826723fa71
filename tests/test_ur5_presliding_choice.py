"""The presliding option on the real UR5 logs: each of the 7 undisturbed folds chooses, on its 6 training movements,
the lengths the screening chose (results/ur5-extra-terms/dahl-sdp-asymmetric-coulomb-viscous-armature.txt,
``dahl_per_joint``), and all 7 movements the lengths of the fresh-data check (benchmarks/ur5_fresh_movements.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimators.arm.identification import Preparation, load_movements
from estimators.arm.model import ArmIdentificationModel
from estimators.arm.presliding_choice import choose_for_rows, presliding_for_movements
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.cli import main

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
pytestmark = pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")

#: held-out movement -> the lengths its fold chose in the screening (rad; coulomb = the smooth sign kept)
SCREENING = {
    "Movement_No1": "4.8e-05 1.0e-04 2.3e-03 1.0e-03 2.2e-04 2.2e-04",
    "Movement_No2": "4.8e-05 1.0e-04 coulomb coulomb 2.2e-04 2.2e-04",
    "Movement_No3_Acc": "4.8e-05 1.0e-04 coulomb coulomb 2.2e-04 2.2e-04",
    "Movement_No4_Acc": "4.8e-05 1.0e-04 coulomb coulomb coulomb 2.2e-04",
    "Movement_No5_Acc_slow_no_disturbance": "2.2e-05 1.0e-04 coulomb coulomb 2.2e-04 4.8e-04",
    "Movement_No8_Singularity_Free_1": "4.8e-05 1.0e-04 coulomb coulomb 2.2e-04 2.2e-04",
    "Movement_No9_Singularity_Free_NoDist": "4.8e-05 1.0e-04 coulomb coulomb 2.2e-04 2.2e-04",
}
#: the lengths chosen on all 7 (docs/results.md, the pushed movements' check)
ALL_SEVEN = "4.8e-05 1.0e-04 coulomb coulomb 2.2e-04 2.2e-04"


def test_each_fold_chooses_what_the_screening_chose() -> None:
    model = ArmIdentificationModel.build(load_arm("ur5"), ("coulomb_asymmetric", "viscous"), armature=True)
    preparation = Preparation()
    logs = load_movements(UR5_REAL, list(SCREENING))
    rows, columns = preparation.all_rows(model, logs), presliding_for_movements(model, logs, preparation)
    chosen = {held: choose_for_rows(model, {n: r for n, r in rows.items() if n != held}, columns).text() for held in SCREENING}
    assert chosen == SCREENING
    assert choose_for_rows(model, rows, columns).text() == ALL_SEVEN
    assert np.all(np.isfinite(np.concatenate([c.ravel() for c in columns.values()])))


def test_the_command_line_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``arm identify --presliding`` prints the lengths chosen on its training movements and stores them with the
    estimate; without a Coulomb term, or with identified gains, the command stops with the option named."""
    train, held = (
        ["Movement_No5_Acc_slow_no_disturbance", "Movement_No9_Singularity_Free_NoDist"],
        "Movement_No8_Singularity_Free_1",
    )
    common = ["--data", str(UR5_REAL), "--armature", "--presliding", "--estimator", "sdp", "--train", ",".join(train)]
    args = ["arm", "identify", *common, "--friction", "coulomb_asymmetric,viscous", "--validate", held]
    assert main([*args, "--out", str(tmp_path / "id")]) == 0
    printed = capsys.readouterr().out
    model = ArmIdentificationModel.build(load_arm("ur5"), ("coulomb_asymmetric", "viscous"), armature=True)
    preparation = Preparation()
    logs = load_movements(UR5_REAL, train)
    expected = choose_for_rows(model, preparation.all_rows(model, logs), presliding_for_movements(model, logs, preparation))
    assert f"presliding length per joint (rad, chosen on the training movements): {expected.text()}" in printed
    stored = json.loads((tmp_path / "id" / "estimate.json").read_text())["presliding_rad"]
    assert stored == expected.lengths_rad
    for extra in (["--friction", "viscous"], ["--friction", "coulomb", "--identify-gains"]):
        assert main(["arm", "identify", *common, *extra, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err
        assert "--presliding" in err and "Traceback" not in err
