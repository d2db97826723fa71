"""UR5 identification end to end: parallel filtering, WLS and the consistent improved ABC against the truth and the
Cramér-Rao bound, friction diagnosis, where it fails, the real logs, and the ``spaceid arm`` commands."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from estimators.arm.arm_diagnosis import diagnose_arm, where_it_fails
from estimators.arm.consistency import params10_from_pseudo_inertia, pseudo_inertia
from estimators.arm.identification import (
    Preparation,
    fit,
    joint_weighted,
    leave_one_out,
    load_movements,
    physically_consistent,
    prediction_error,
    processed_noise_floor,
    summary_table,
)
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.model import ArmIdentificationModel
from estimators.arm.synthetic import last_link_problem
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.joint_sensors import ArmSensorModel
from spaceid_gym.arm.signal import lowpass_zero_phase, prepare_for_identification
from spaceid_gym.arm.simulated_arm_datasets import simulate_arm_dataset
from spaceid_gym.cli import main
from spaceid_gym.errors import SpaceIdInputError

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
FRICTION = ("coulomb", "viscous")


@pytest.fixture(scope="module")
def ur5():
    return load_arm("ur5")


@pytest.fixture(scope="module")
def simulated(ur5, tmp_path_factory):
    """Two noisy 20 s logs (random Fourier excitations) and one noise-free log of the same true UR5 with friction."""
    root = tmp_path_factory.mktemp("ur5sim")
    train = simulate_arm_dataset(ur5, 20.0, FRICTION, 3, "fourier", root / "train")
    p_true = np.array(list(train.truth["parameters"].values()))
    held = simulate_arm_dataset(ur5, 20.0, FRICTION, 4, "fourier", root / "held", parameters=p_true)
    clean = simulate_arm_dataset(
        ur5, 20.0, FRICTION, 5, "fourier", root / "clean", parameters=p_true, sensors=ArmSensorModel.noise_free()
    )
    return {"root": root, "train": train, "held": held, "clean": clean, "p_true": p_true}


@pytest.fixture(scope="module")
def model(ur5):
    return ArmIdentificationModel.build(ur5, FRICTION)


def test_parallel_filtering_keeps_the_model_exact_where_filtering_the_states_does_not(model, simulated) -> None:
    """Noise-free data: the parallel-filtered rows reproduce the filtered torque with the true parameters (up to the
    smoothing of the state filter), while the regressor of filtered states against the filtered torque does not."""
    log = simulated["clean"].simulation.log
    beta = model.base.to_base(simulated["p_true"])
    rows = Preparation().rows(model, log)
    relative = np.sqrt(np.mean((rows.log.effort - model.predict(beta, rows)) ** 2, axis=0) / np.mean(rows.log.effort**2, axis=0))
    assert relative.max() < 2e-5
    states = prepare_for_identification(log, 4.0, 5)
    naive = states.effort - model.log_regressor(states) @ beta
    naive_relative = np.sqrt(np.mean(naive**2, axis=0) / np.mean(states.effort**2, axis=0))
    assert naive_relative.max() > 100 * relative.max()


def test_noise_gain_is_the_std_of_filtered_white_noise() -> None:
    preparation = Preparation()
    dt = 0.008
    noise = np.random.default_rng(0).standard_normal((200_000, 1))
    filtered = lowpass_zero_phase(noise, dt, preparation.cutoff_hz, preparation.order)[1000:-1000]
    assert np.std(filtered) == pytest.approx(preparation.noise_gain(dt), rel=0.02)
    # kappa: block means of 50 decimated samples vary as white noise of kappa x the filtered variance would
    decimated = filtered[::5, 0]
    blocks = decimated[: len(decimated) // 50 * 50].reshape(-1, 50).mean(axis=1)
    kappa = np.var(blocks) * 50 / np.var(decimated)
    assert kappa == pytest.approx(preparation.correlation_factor(dt), rel=0.15)


def _training(model: ArmIdentificationModel, simulated: dict) -> tuple[dict, LinearIdentificationProblem]:
    """The training movement's rows and the cost every consistent estimator minimises (joint-weighted, as ``fit`` poses it)."""
    train = {"train": Preparation().rows(model, simulated["train"].simulation.log)}
    return train, joint_weighted(model.problem(train))


def test_wls_and_sdp_reach_the_noise_floor_and_the_bound(model, simulated) -> None:
    """Deterministic: WLS and the convex consistent optimum (sdp) on a 20 s noisy training log, against the truth, the
    held-out noise floor and the Cramér-Rao bound; sdp's cost is the least over consistent parameters (the truth is
    one candidate, WLS's base parameters made consistent link by link another) and at least WLS's."""
    preparation = Preparation()
    train, problem = _training(model, simulated)
    held_rows = preparation.rows(model, simulated["held"].simulation.log)
    noise = np.asarray(simulated["train"].truth["noise"]["torque_std_Nm"])
    floor = processed_noise_floor(preparation, noise, simulated["held"].simulation.log)
    beta_true = model.base.to_base(simulated["p_true"])
    clean = simulated["train"].simulation.clean
    raw = model.log_regressor(clean).reshape(-1, model.n_params)
    bound = LinearIdentificationProblem(
        raw, raw @ beta_true, model.base.names, beta_true - 1, beta_true + 1, row_std=np.tile(noise, clean.n_samples)
    ).crlb_std(beta_true)
    wls = fit(model, train, estimator_from_spec("wls"))
    sdp = fit(model, train, estimator_from_spec("sdp"))
    # a 20 s random excitation (the README's figures: 30 s optimised, benchmarks/ur5_simulated.py): looser bounds
    assert prediction_error(model, wls.theta, held_rows, floor).overall_noise_ratio < 1.3
    assert np.sqrt(np.mean(((wls.theta - beta_true) / bound) ** 2)) < 2.5
    assert physically_consistent(sdp) is True and sdp.extra["solver"] == "CLARABEL"
    assert prediction_error(model, sdp.theta, held_rows, floor).overall_noise_ratio < 1.1  # 1.045 measured, WLS 1.21
    assert np.sqrt(np.mean(((sdp.theta - beta_true) / bound) ** 2)) < 2.5
    cost = problem.cost(np.vstack([wls.theta, sdp.theta, beta_true]), count=False)
    assert cost[0] < cost[1] < cost[2]  # WLS (unconstrained) < sdp < the truth (consistent, fitted to no noise)
    assert cost[1] == pytest.approx(sdp.cost, rel=1e-12)
    # WLS's base parameters made consistent: the full set nearest the URDF's, each pseudo-inertia clipped to PSD
    full = model.base.full_parameters(wls.theta, model.regressor.nominal_parameters())
    for columns in model.consistency().link_columns:
        eigenvalues, vectors = np.linalg.eigh(pseudo_inertia(full[columns]))
        full[columns] = params10_from_pseudo_inertia((vectors * np.clip(eigenvalues, 1e-9, None)) @ vectors.T)
    full[model.consistency().friction_columns] = np.clip(full[model.consistency().friction_columns], 0.0, None)
    assert cost[1] < problem.cost(model.base.to_base(full), count=False)[0]


#: colony seeds of the statistical test and how many must end within 1 % of the sdp cost. Measured (issue 21's seed
#: study, benchmarks/ur5_colony_vs_sdp.py --datasets 3 --seeds 20): 60 of 60 fits within 1 % at 20 000 evaluations
#: (largest excess 0.011 %; this test's data are its dataset 3), so the failure rate is at most 4.9 % (one-sided 95 %
#: Clopper-Pearson bound for 0 of 60); at that rate fewer than 6 of 8 seeds succeed with probability 0.0054: requiring
#: 6 of 8 fails a correct colony less than once in 180 runs, whichever seeds are drawn.
COLONY_SEEDS, COLONY_WITHIN = 8, 6


def test_consistent_colony_reaches_the_sdp_cost(model, simulated) -> None:
    """The polished consistent improved ABC at 20 000 evaluations ends within 1 % of the convex optimum's cost on at
    least ``COLONY_WITHIN`` of ``COLONY_SEEDS`` seeds (the binomial bound above), reports that excess itself, and is
    consistent and never meaningfully below the optimum on every seed."""
    train, problem = _training(model, simulated)
    sdp_cost = float(problem.cost(fit(model, train, estimator_from_spec("sdp")).theta, count=False)[0])
    within = 0
    for seed in range(COLONY_SEEDS):
        colony = fit(
            model, train, estimator_from_spec("improved-abc[consistent=true,polish=true,max_evaluations=20000]", seed=seed)
        )
        excess = (colony.cost - sdp_cost) / sdp_cost
        assert physically_consistent(colony) is True
        assert colony.cost_history[-1] <= colony.extra["colony_cost"]
        assert colony.extra["cost_excess_over_sdp"] == pytest.approx(excess, abs=1e-9)
        assert excess > -1e-4  # the sdp's regulariser trades at most ~1e-5 here
        within += excess <= 0.01
    assert within >= COLONY_WITHIN


def test_diagnose_names_missing_friction_and_adding_it_reaches_the_noise_floor(ur5, model, simulated) -> None:
    logs = {"train": simulated["train"].simulation.log, "held": simulated["held"].simulation.log}
    preparation = Preparation()
    without = ArmIdentificationModel.build(ur5, ())
    diagnosis = diagnose_arm(without, logs, preparation)
    assert diagnosis.verdict == "friction" and diagnosis.family == "friction"
    assert np.all(diagnosis.correlation.p_sign < 1e-6)
    best = diagnosis.best()
    assert best is not None and best.model.regressor.friction.terms == FRICTION
    noise = np.asarray(simulated["train"].truth["noise"]["torque_std_Nm"])
    floor = processed_noise_floor(preparation, noise, logs["train"])
    before = prediction_error(without, diagnosis.baseline.theta, diagnosis.baseline.rows["train"], floor)
    after = prediction_error(best.model, best.theta, best.rows["train"], floor)
    assert before.overall_noise_ratio > 10 and after.overall_noise_ratio < 1.1
    # the model with friction is complete: nothing else is named
    assert diagnose_arm(model, logs, preparation).verdict == "none"


def test_where_it_fails_flags_a_push_on_the_arm(model, simulated) -> None:
    held = simulated["held"].simulation.log
    t = held.t_s - held.t_s[0]
    push = np.zeros_like(held.effort)
    push[(t > 8.0) & (t < 10.0), 1:3] = [4.0, 3.0]  # N m on the shoulder and elbow for 2 s
    logs = {"train": simulated["train"].simulation.log, "pushed": dataclasses.replace(held, effort=held.effort + push)}
    failing = where_it_fails(model, Preparation().all_rows(model, logs))
    name, worst = failing.ranked()[0]
    assert name == "pushed"
    assert worst.t_start_s - held.t_s[0] < 10.0 and worst.t_end_s - held.t_s[0] > 8.0
    assert not failing.segments["train"]


def test_load_movements_says_what_is_available(simulated, tmp_path) -> None:
    logs = load_movements(simulated["root"])
    assert set(logs) == {"train", "held", "clean"}
    with pytest.raises(SpaceIdInputError, match="no movement \\['nope'\\]; available: "):
        load_movements(simulated["root"], ["nope"])
    with pytest.raises(SpaceIdInputError, match="no such folder"):
        load_movements(tmp_path / "missing")
    with pytest.raises(SpaceIdInputError, match="no movement folders"):
        load_movements(tmp_path)


def test_root_form_is_the_cost_above_its_minimum() -> None:
    problem, _ = last_link_problem(seed=0, n_samples=40)
    matrix, minimiser = problem.root_form()
    rng = np.random.default_rng(1)
    for theta in rng.uniform(problem.parameters.lower, problem.parameters.upper, (5, problem.n_params)):
        root = problem.root_cost(theta, count=False)
        expected = problem.cost(theta, count=False)[0] - problem.cost(minimiser, count=False)[0]
        assert root @ root == pytest.approx(expected, rel=1e-8, abs=1e-12)
    assert matrix.shape[1] == problem.n_params


def test_consistency_of_a_model_with_a_free_offset(ur5) -> None:
    with_offset = ArmIdentificationModel.build(ur5, ("coulomb", "offset"), armature=True)
    consistency = with_offset.consistency()
    lower, _ = consistency.search_box()
    assert len(consistency.free_columns) == 6 and np.all(lower[consistency.free_columns] < 0)
    assert len(consistency.friction_columns) == 12 and np.all(lower[consistency.friction_columns] == 0)
    names = with_offset.regressor.parameter_names
    assert all("offset" in names[c] for c in consistency.free_columns)


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_real_ur5_friction_lowers_the_prediction_error(ur5) -> None:
    names = ["Movement_No8_Singularity_Free_1", "Movement_No9_Singularity_Free_NoDist", "Movement_No5_Acc_slow_no_disturbance"]
    logs = load_movements(UR5_REAL, names)
    models = {"friction": ArmIdentificationModel.build(ur5, FRICTION), "none": ArmIdentificationModel.build(ur5, ())}
    rows = leave_one_out(models, logs, {"ols": estimator_from_spec("ols")}, Preparation())
    summary = {entry["model"]: entry["mean_overall_percent"] for entry in summary_table(rows)}
    assert len(rows) == 6
    assert summary["friction"] < 0.6 * summary["none"]


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_real_ur5_sdp_is_consistent_and_the_colony_reaches_it(ur5) -> None:
    """Real logs, with armature: trained on two undisturbed movements, sdp is consistent and predicts the third about
    as well as WLS (the constraint can cost a little on real data: 7.1 % against 6.9 % here; over the 7 undisturbed
    folds of leave one out 12.6 % against 12.9 %); the polished colony ends within 1 % of its cost on at least one
    of two seeds. Measured on this very split at this budget, seeds 0-29: 30 of 30 within 1 % (largest excess
    -0.008 %, the sdp's regulariser trade), so a seed fails with probability at most 9.5 % (one-sided 95 %
    Clopper-Pearson bound for 0 of 30) and both fail with probability below 1 %."""
    names = ["Movement_No8_Singularity_Free_1", "Movement_No5_Acc_slow_no_disturbance", "Movement_No9_Singularity_Free_NoDist"]
    model = ArmIdentificationModel.build(ur5, FRICTION, armature=True)
    rows = Preparation().all_rows(model, load_movements(UR5_REAL, names))
    train, held = {n: rows[n] for n in names[:2]}, rows[names[2]]
    wls, sdp = (fit(model, train, estimator_from_spec(spec)) for spec in ("wls", "sdp"))
    assert physically_consistent(sdp) is True
    wls_error, sdp_error = (prediction_error(model, e.theta, held).overall_percent for e in (wls, sdp))
    assert sdp_error < 1.1 * wls_error
    spec = "improved-abc[consistent=true,polish=true,max_evaluations=20000]"
    colonies = [fit(model, train, estimator_from_spec(spec, seed=seed)) for seed in (0, 1)]
    assert all(physically_consistent(c) is True for c in colonies)
    assert min(c.extra["cost_excess_over_sdp"] for c in colonies) < 0.01


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_arm_identify_command_on_real_logs(tmp_path: Path, capsys) -> None:
    out = tmp_path / "id"
    args = ["arm", "identify", "--data", str(UR5_REAL), "--train", "Movement_No9_Singularity_Free_NoDist,Movement_No1"]
    code = main([*args, "--validate", "Movement_No8_Singularity_Free_1", "--estimator", "wls", "--out", str(out)])
    assert code == 0
    assert (out / "estimate.json").is_file() and (out / "overlay_Movement_No8_Singularity_Free_1.png").is_file()
    assert "Movement_No8_Singularity_Free_1" in capsys.readouterr().out
    assert main([*args, "--validate", "Movement_No99", "--out", str(out)]) == 2
    assert "no movement ['Movement_No99']" in capsys.readouterr().err


def test_arm_diagnose_and_cross_validate_commands(simulated, tmp_path: Path, capsys) -> None:
    root = simulated["root"]
    assert (
        main(["arm", "diagnose", "--data", str(root), "--movements", "train,held", "--apply", "--out", str(tmp_path / "d")]) == 0
    )
    text = capsys.readouterr().out
    assert "verdict: friction" in text and "where it fails" in text and "x noise" in text
    assert (tmp_path / "d" / "diagnosis.json").is_file()
    code = main(
        [
            "arm",
            "cross-validate",
            "--data",
            str(root),
            "--movements",
            "train,held",
            "--estimators",
            "ols",
            "--out",
            str(tmp_path / "c"),
        ]
    )
    assert code == 0 and (tmp_path / "c" / "table.md").read_text().count("| with coulomb,viscous | ols |") == 2
    assert main(["arm", "diagnose", "--data", str(root), "--decimate", "0", "--out", str(tmp_path / "e")]) == 2


def test_sdp_in_the_arm_commands(simulated, tmp_path: Path, capsys) -> None:
    """``spaceid arm identify --estimator sdp`` and ``arm cross-validate`` with sdp and the consistent colony: the
    estimate file names the solver, the table and the printout give each colony fit's cost over the sdp optimum and
    the time per fit."""
    root = str(simulated["root"])
    args = ["arm", "identify", "--data", root, "--train", "train", "--validate", "held", "--estimator", "sdp"]
    assert main([*args, "--out", str(tmp_path / "i")]) == 0
    written = json.loads((tmp_path / "i" / "estimate.json").read_text())
    assert written["estimator"] == "sdp" and written["solver"] == "CLARABEL" and written["fallback_reason"] is None
    assert "held" in capsys.readouterr().out
    colony = "improved-abc[consistent=true,polish=true,max_evaluations=5000]"
    code = main(
        [
            "arm",
            "cross-validate",
            "--data",
            root,
            "--movements",
            "train,held",
            "--estimators",
            f"sdp,{colony}",
            "--out",
            str(tmp_path / "c"),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0 and "cost over sdp:" in text and "s/fit" in text
    rows = json.loads((tmp_path / "c" / "rows.json").read_text())["rows"]
    excess = [r["cost_excess_over_sdp"] for r in rows if r["estimator"] == colony]
    # seeds 0-29 of this colony on these two folds: 60 of 60 fits within 1 %, largest excess 0.023 % (43 times below)
    assert len(excess) == 2 and all(abs(e) < 0.01 for e in excess)
    assert all(r["physically_consistent"] for r in rows)
    assert "cost over sdp %" in (tmp_path / "c" / "table.md").read_text()
