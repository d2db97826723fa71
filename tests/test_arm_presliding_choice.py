"""Presliding (Dahl) friction as an option of the arm model (estimators.arm.presliding_choice): on simulated UR5
movements whose current is generated from the Dahl columns at known lengths and levels plus white noise, the
training cost picks the true lengths (and the Coulomb column where the truth has it) and the levels come back within
their Cramér-Rao std; each fold of the leave-one-out chooses on its training movements only; bad input is named."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from estimators.arm.identification import Preparation, fit, leave_one_out
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.arm.presliding_choice import (
    PreslidingChoice,
    choose_for_rows,
    coulomb_slots,
    presliding_for_movements,
    with_presliding,
)
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.excitation_design import FourierTrajectory
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.errors import SpaceIdInputError

#: the truth: per joint the grid index of its presliding length (-1: the rate's smooth sign)
TRUE_CHOICE = np.array([3, 5, -1, 7, -1, 9])
#: true Coulomb levels per joint and direction (positive, negative), N m
TRUE_LEVELS_NM = np.array([[6.0, 5.0], [7.0, 8.0], [4.0, 3.5], [2.0, 1.5], [1.2, 1.0], [0.8, 0.9]])
#: current noise std per joint on the prepared samples, A
NOISE_A = np.array([0.05, 0.05, 0.04, 0.02, 0.02, 0.02])
SEEDS = range(20)

Setup = tuple[ArmIdentificationModel, dict[str, IdentificationRows], dict[str, np.ndarray]]


@pytest.fixture(scope="module")
def setup() -> Setup:
    """The UR5 model (asymmetric Coulomb + viscous + armature), 3 movements of 20 s at 125 Hz (Fourier trajectories with
    reversals), their rows and Dahl columns (noise-free effort: zeros; the tests draw it)."""
    model = ArmIdentificationModel.build(load_arm("ur5"), ("coulomb_asymmetric", "viscous"), armature=True)
    rng = np.random.default_rng(2024)
    t = np.arange(2500) * 0.008
    logs = {}
    for k in range(3):
        trajectory = FourierTrajectory(6, 4, 0.1, rng.normal(0.0, 0.12, (6, 2, 4)), rng.uniform(-1.0, 1.0, 6))
        q, dq, _ = trajectory(t)
        logs[f"move{k}"] = ArmLog(t, q, dq, None, np.zeros_like(q), "current_A", f"move{k}")
    preparation = Preparation()
    return model, preparation.all_rows(model, logs), presliding_for_movements(model, logs, preparation)


def true_beta(model: ArmIdentificationModel) -> np.ndarray:
    """The URDF's base parameters with the true Coulomb levels, viscous 2 N m s/rad and armature 0.1 kg m^2 per joint."""
    full = model.regressor.nominal_parameters().copy()
    names = list(model.regressor.parameter_names)
    for j in range(model.n_joints):
        full[names.index(f"joint{j + 1}_coulomb_positive_Nm")] = TRUE_LEVELS_NM[j, 0]
        full[names.index(f"joint{j + 1}_coulomb_negative_Nm")] = TRUE_LEVELS_NM[j, 1]
        full[names.index(f"joint{j + 1}_viscous_Nms")] = 2.0
        full[names.index(f"joint{j + 1}_armature_kgm2")] = 0.1
    return model.base.to_base(full)


def noisy(
    model: ArmIdentificationModel,
    rows: dict[str, IdentificationRows],
    columns: dict[str, np.ndarray],
    beta: np.ndarray,
    rng: np.random.Generator,
) -> dict[str, IdentificationRows]:
    """The rows with the effort of the true model (Dahl columns at :data:`TRUE_CHOICE`) plus white noise."""
    truth = PreslidingChoice(TRUE_CHOICE)
    out = {}
    for name, item in rows.items():
        design = with_presliding(model, item, columns[name], truth).regressor
        effort = design @ beta + rng.normal(0.0, 1.0, design.shape[:2]) * NOISE_A
        out[name] = IdentificationRows(dataclasses.replace(item.log, effort=effort), item.regressor)
    return out


def test_the_training_cost_picks_the_true_lengths_and_the_levels_come_back_within_their_cramer_rao_std(setup: Setup) -> None:
    """Over 20 noise seeds: the choice is the truth every time, and the levels' errors over their Cramér-Rao std
    (``wls`` at the chosen lengths; std from the problem at the true noise) are standard normal: with 20 x 12 values
    their mean square is chi-square / 240, std 0.091, so an RMS outside [0.8, 1.2] (mean square 0.64, 1.44) is
    beyond 3.9 of its stds; none beyond 5 (a chance of 1.4e-4 among the 240)."""
    model, rows, columns = setup
    beta = true_beta(model)
    slots = coulomb_slots(model)
    truth = PreslidingChoice(TRUE_CHOICE)
    z = []
    with threadpool_limits(limits=1):  # small least-squares problems: faster on one BLAS thread on a busy machine
        std = model.problem({n: with_presliding(model, r, columns[n], truth) for n, r in rows.items()}, NOISE_A).crlb_std(beta)
        for seed in SEEDS:
            data = noisy(model, rows, columns, beta, np.random.default_rng(seed))
            choice = choose_for_rows(model, data, columns)
            np.testing.assert_array_equal(choice.grid_index, TRUE_CHOICE)
            train = {name: with_presliding(model, item, columns[name], choice) for name, item in data.items()}
            estimate = fit(model, train, estimator_from_spec("wls", seed=0))
            z.append((estimate.theta[slots] - beta[slots]) / std[slots])
    z = np.array(z)
    assert 0.8 < np.sqrt(np.mean(z**2)) < 1.2, z
    assert np.abs(z).max() < 5.0, z


def test_sdp_keeps_the_levels_non_negative_and_finds_them(setup: Setup) -> None:
    """``sdp`` on the Dahl rows (the levels' constraint ``>= 0`` unchanged): physically consistent, and its levels
    within 4.5 Cramér-Rao std of the truth (its constraints are inactive at this truth, so it is the WLS optimum)."""
    model, rows, columns = setup
    beta = true_beta(model)
    slots = coulomb_slots(model)
    data = noisy(model, rows, columns, beta, np.random.default_rng(100))
    choice = choose_for_rows(model, data, columns)
    train = {name: with_presliding(model, item, columns[name], choice) for name, item in data.items()}
    with threadpool_limits(limits=1):
        estimate = fit(model, train, estimator_from_spec("sdp", seed=0))
        std = model.problem(train, row_std=NOISE_A).crlb_std(beta)
    assert all(estimate.physical["links_physically_consistent"])
    assert np.all(estimate.theta[slots] >= -1e-9)
    assert np.abs((estimate.theta[slots] - beta[slots]) / std[slots]).max() < 4.5


def raw_logs(seed: int, n_movements: int = 3) -> dict[str, ArmLog]:
    """Raw current logs of 12 s at 125 Hz: Fourier trajectories, a Coulomb-like current plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(1500) * 0.008
    logs = {}
    for k in range(n_movements):
        trajectory = FourierTrajectory(6, 3, 0.15, rng.normal(0.0, 0.12, (6, 2, 3)), rng.uniform(-1.0, 1.0, 6))
        q, dq, _ = trajectory(t)
        logs[f"m{k}"] = ArmLog(t, q, dq, None, rng.normal(0.0, 0.1, q.shape) + np.tanh(dq / 0.01), "current_A", f"m{k}")
    return logs


def test_each_fold_chooses_on_its_training_movements_only(setup: Setup) -> None:
    """In ``leave_one_out(..., presliding=[label])`` each fold records the lengths that :func:`choose_for_rows` picks
    on its training rows; the held-out movement's current replaced by another changes neither them nor the fit."""
    model, _, _ = setup
    logs = raw_logs(3)
    estimators = {"wls": estimator_from_spec("wls", seed=0)}
    preparation = Preparation()
    rows = leave_one_out({"dahl": model}, logs, estimators, preparation, presliding=["dahl"])
    prepared, columns = preparation.all_rows(model, logs), presliding_for_movements(model, logs, preparation)
    for row in rows:
        train = {name: item for name, item in prepared.items() if name != row.error.movement}
        assert row.presliding_rad == choose_for_rows(model, train, columns).lengths_rad
    spoiled = dict(logs)
    spoiled["m0"] = dataclasses.replace(logs["m0"], effort=-3.0 * logs["m0"].effort)
    again = leave_one_out({"dahl": model}, spoiled, estimators, preparation, presliding=["dahl"])
    assert again[0].presliding_rad == rows[0].presliding_rad
    measured = prepared["m0"].log.effort  # the same prediction: the residual moves by the current's change only
    np.testing.assert_allclose(again[0].error.residual, rows[0].error.residual - 4.0 * measured, atol=1e-9)


def test_bad_input_is_named(setup: Setup) -> None:
    """A model without a Coulomb term, an unknown model label and the combination with identified gains are clear
    errors."""
    model, _, _ = setup
    logs = raw_logs(4, 2)
    estimators = {"wls": estimator_from_spec("wls", seed=0)}
    bare = ArmIdentificationModel.build(load_arm("ur5"), ("viscous",), armature=True)
    with pytest.raises(SpaceIdInputError, match="no Coulomb term"):
        leave_one_out({"bare": bare}, logs, estimators, Preparation(), presliding=["bare"])
    with pytest.raises(SpaceIdInputError, match="unknown model"):
        leave_one_out({"dahl": model}, logs, estimators, Preparation(), presliding=["other"])
    with pytest.raises(SpaceIdInputError, match="identify-gains"):
        leave_one_out({"dahl": model}, logs, estimators, Preparation(), gain_reference="gravity", presliding=["dahl"])
