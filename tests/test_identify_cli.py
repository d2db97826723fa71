"""``spaceid identify`` / ``spaceid evaluate`` and the env's estimator option."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from estimators.evaluation import estimator_from_spec, parse_estimator_specs
from spaceid_gym.cli import main
from spaceid_gym.envs import FreeFloatingIDEnv
from spaceid_gym.envs.estimation import EstimatorWrapper
from spaceid_gym.errors import SpaceIdInputError

TRUTH_KEYS = ("base_mass_kg", "base_com_m", "base_inertia_kgm2", "fuel_consumed_kg", "tank_position_m")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("data") / "run1"
    args = ["simulate", "--duration", "30", "--fuel-consumed", "70", "--tank", "0.3,-0.2,0.15", "--seed", "2", "--out", str(out)]
    assert main(args) == 0
    return out


def _identify(dataset: Path, out: Path, *extra: str) -> int:
    return main(
        ["identify", "--robot", str(dataset / "robot.urdf"), "--log", str(dataset / "log.csv"), "--out", str(out), *extra]
    )


def test_identify_writes_an_estimate_that_compares_key_by_key_with_the_truth(dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "estimate.json"
    assert _identify(dataset, out, "--params", "fuel", "--estimator", "lm") == 0
    estimate = json.loads(out.read_text())
    truth = json.loads((dataset / "truth.json").read_text())
    for key in TRUTH_KEYS:
        error = np.asarray(estimate[key]) - np.asarray(truth[key])
        std = np.asarray(estimate[f"{key}_std"])
        assert np.all(np.abs(error) < 5 * std + 1e-12), key  # within 5 sigma of its own reported uncertainty
    assert estimate["estimator"] == "lm" and estimate["seed"] == 0 and estimate["n_evaluations"] > 0
    assert estimate["wall_time_s"] > 0 and isinstance(estimate["options"], dict)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--estimator", "simplex"], "unknown estimator 'simplex'; available:"),
        (["--estimator", "lm", "--lower", "10,-0.5,-0.5,-0.5"], "the bounds exclude the nominal value: fuel_consumed_kg"),
        (["--estimator", "lm", "--upper", "100,0.5"], "upper must be 4 finite numbers"),
        (["--params", "mass"], "unknown parameterisation 'mass'"),
    ],
)
def test_identify_rejects_bad_input_with_a_clear_message(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    out = tmp_path / "estimate.json"
    assert _identify(dataset, out, *extra) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_identify_rejects_a_log_shorter_than_the_estimator_needs(
    dataset: Path, tmp_path: Path, spaceid: Callable[..., Any]
) -> None:
    short = tmp_path / "short"
    short.mkdir()
    lines = (dataset / "log.csv").read_text().splitlines()
    (short / "log.csv").write_text("\n".join(lines[:6]) + "\n")  # header and 5 samples
    (short / "robot.urdf").write_text((dataset / "robot.urdf").read_text())
    command = ["identify", "--robot", str(short / "robot.urdf")]
    command += ["--log", str(short / "log.csv"), "--estimator", "improved-pso", "--out", str(tmp_path / "e.json")]
    result = spaceid(*command)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert "5 samples is shorter than the estimator 'improved-pso' needs" in result.stderr


def test_evaluate_writes_tables_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    args = [
        "evaluate",
        "--settings",
        "2",
        "--duration",
        "10",
        "--estimators",
        "lm,pso[n_particles=10,n_generations=5]",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    names = {p.name for p in out.iterdir()}
    assert {
        "episodes.csv",
        "summary.csv",
        "summary.json",
        "table.md",
        "convergence.png",
        "mass.png",
        "bound_vs_tank.png",
    } <= names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["n_settings"] == 2
    rows = {(r["estimator"], r["quantity"]): r for r in summary["summary"]}
    assert rows[("lm", "M")]["n_settings"] == 2 and rows[("lm", "M")]["rms_over_bound"] > 0
    assert "| lm |" in (out / "table.md").read_text()


def test_estimator_specs_split_at_the_commas_outside_brackets() -> None:
    """A list-valued option (an inertia schedule) stays one option; each spec builds its estimator."""
    specs = parse_estimator_specs("improved-pso, pso[topology=ring,inertia=[0.9,0.4]] ,lm")
    assert specs == ["improved-pso", "pso[topology=ring,inertia=[0.9,0.4]]", "lm"]
    swarm = estimator_from_spec(specs[1], seed=5)
    assert swarm.get_params()["inertia"] == (0.9, 0.4)
    assert swarm.get_params()["topology"] == "ring" and swarm.seed == 5
    with pytest.raises(SpaceIdInputError, match="not key=value"):
        estimator_from_spec("pso[inertia]")
    with pytest.raises(SpaceIdInputError, match="expected a comma-separated list"):
        parse_estimator_specs(" , ")
    with pytest.raises(SpaceIdInputError, match="unbalanced"):
        parse_estimator_specs("pso[c1=2],inertia=0.5],lm")
    with pytest.raises(SpaceIdInputError, match="unclosed"):
        parse_estimator_specs("pso[inertia=[0.9,0.4],lm")
    with pytest.raises(SpaceIdInputError, match="unbalanced"):
        estimator_from_spec("pso[inertia=[0.9,0.4]]]")


def test_env_runs_the_estimator_at_the_window_end() -> None:
    env = gym.make("FreeFloatingID-v0", robot="paper6", estimator="lm", max_episode_steps=400, identify_after_steps=400)
    env.reset(seed=0, options={"fuel_consumed_kg": 80.0, "tank_position_m": [0.3, -0.25, 0.2]})
    action = np.full(6, 0.8, dtype=np.float32)
    for k in range(400):
        action[:] = np.sin(0.05 * k * np.arange(1, 7))
        _, _, terminated, truncated, info = env.step(action)
        assert ("estimate" in info) == (k == 399)
    assert truncated and not terminated
    assert info["estimate"]["estimator"] == "lm"
    assert set(info["estimate_errors"]) == {"M", "r", "Ixx", "Iyy", "Izz", "mdf", "bf"}
    assert info["estimate_errors"]["mdf"] < 5 * info["estimate"]["fuel_consumed_kg_std"]
    env.close()


def test_env_rejects_a_bad_window_and_an_unknown_estimator() -> None:
    with pytest.raises(SpaceIdInputError, match="identify_after_steps: expected a positive number of steps"):
        EstimatorWrapper(FreeFloatingIDEnv("quick3"), "lm", identify_after_steps=0)
    with pytest.raises(SpaceIdInputError, match="unknown estimator 'simplex'"):
        EstimatorWrapper(FreeFloatingIDEnv("quick3"), "simplex")
