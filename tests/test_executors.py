"""The pluggable executor: the same results in-process, in 2 local processes and on a Dask LocalCluster; per-job
seeds; clear errors; a cancelled run leaves no output."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from estimators import evaluation
from estimators.arm.identification import Preparation, leave_one_out, load_movements
from estimators.arm.model import ArmIdentificationModel
from estimators.evaluation import draw_settings, estimator_from_spec, run_evaluation
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.cli import main
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import (
    DASK_MISSING,
    ExecutorSpec,
    add_executor_arguments,
    executor_from_arguments,
    job_seeds,
    run_jobs,
)
from spaceid_gym.robots import load_robot


def _draw(seed: int) -> list[float]:
    """A job that draws from its own seed and multiplies matrices (a BLAS reduction)."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((120, 120))
    return [float(x) for x in (a @ a.T @ rng.standard_normal(120))[:5]]


def _fail_on_two(item: int) -> int:
    if item == 2:
        raise ZeroDivisionError("job 2")
    return item


def _without_times(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.items() if k != "wall_time_s"} for row in rows]


def test_job_seeds_are_the_seed_sequences_children_and_do_not_depend_on_the_job_count() -> None:
    seeds = job_seeds(7, 5)
    expected = [int(c.generate_state(1)[0]) for c in np.random.SeedSequence(7).spawn(5)]
    assert seeds == expected and len(set(seeds)) == 5
    assert job_seeds(7, 3) == seeds[:3]
    with pytest.raises(SpaceIdInputError, match="seed"):
        job_seeds(-1, 3)


def test_a_tiny_evaluation_is_bit_identical_in_process_in_two_processes_and_on_a_dask_local_cluster() -> None:
    pytest.importorskip("distributed")
    settings = draw_settings(load_robot("paper6"), 3, 5)
    specs = ["lm", "pso[n_particles=8,n_generations=3]"]

    def run(executor: ExecutorSpec) -> list[dict[str, Any]]:
        rows = run_evaluation("paper6", specs, settings, duration_s=4.0, executor=executor, seed=11, progress=False)
        return _without_times(rows)

    serial = run(ExecutorSpec("serial"))
    assert [(r["setting"], r["estimator"]) for r in serial] == [(i, s) for i in range(3) for s in specs]
    assert {r["estimator_seed"] for r in serial} == set(job_seeds(11, 3))
    assert run(ExecutorSpec("processes", 2)) == serial
    environment = dict(os.environ)
    assert run(ExecutorSpec("dask", 2)) == serial
    # the cluster's nannies left OMP_NUM_THREADS=1, OPENBLAS_NUM_THREADS=1, ... in this process's environment, so a
    # process started afterwards computed with one BLAS thread (a later test's fresh process differed in the last bits)
    assert dict(os.environ) == environment
    # the random draws and BLAS products of jobs, whatever the executor and the number of workers
    draws = run_jobs(_draw, job_seeds(3, 4), ExecutorSpec("serial"), progress=False)
    assert run_jobs(_draw, job_seeds(3, 4), ExecutorSpec("processes", 2), progress=False) == draws
    assert run_jobs(_draw, job_seeds(3, 4), ExecutorSpec("processes", 1), progress=False) == draws


UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"


@pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")
def test_arm_cross_validation_is_bit_identical_in_process_and_in_two_processes() -> None:
    # the folds get processed rows built in this process (strided views among them): the serial executor hands each
    # job the copy a worker receives, so the sums run in the same order
    names = ["Movement_No8_Singularity_Free_1", "Movement_No9_Singularity_Free_NoDist", "Movement_No5_Acc_slow_no_disturbance"]
    logs = load_movements(UR5_REAL, names)
    models = {"friction": ArmIdentificationModel.build(load_arm("ur5"), ("coulomb", "viscous"))}
    estimators = {"ols": estimator_from_spec("ols"), "wls": estimator_from_spec("wls")}

    def rows(executor: ExecutorSpec) -> list[dict[str, Any]]:
        return _without_times([r.to_dict() for r in leave_one_out(models, logs, estimators, Preparation(), None, executor)])

    assert rows(ExecutorSpec("processes", 2)) == rows(ExecutorSpec("serial"))


def test_a_failing_job_raises_its_error_in_every_executor() -> None:
    for spec in (ExecutorSpec("serial"), ExecutorSpec("processes", 2)):
        with pytest.raises(ZeroDivisionError, match="job 2"):
            run_jobs(_fail_on_two, [0, 1, 2, 3], spec, progress=False)
    assert run_jobs(_fail_on_two, [], ExecutorSpec("processes", 2)) == []


def test_without_dask_the_executor_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # an import of it raises ImportError
    with pytest.raises(SpaceIdInputError, match=r"spaceid-gym\[dask\]"):
        run_jobs(_draw, [1], ExecutorSpec("dask", 1), progress=False)
    assert "dask[distributed]" in DASK_MISSING


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--executor", "serial", "--jobs", "2"], "serial executor runs in this process"),
        (["--executor", "processes", "--scheduler", "tcp://h:8786"], "only with --executor dask"),
        (["--jobs", "0"], "--jobs: expected an integer from 1 to"),
        (["--executor", "dask", "--scheduler", " "], "--scheduler: expected an address"),
    ],
)
def test_bad_executor_options_are_refused(argv: list[str], message: str) -> None:
    parser = argparse.ArgumentParser()
    add_executor_arguments(parser)
    with pytest.raises(SpaceIdInputError, match=message):
        executor_from_arguments(parser.parse_args(argv), 16)


def test_executor_defaults_keep_the_old_meaning_of_jobs() -> None:
    parser = argparse.ArgumentParser()
    add_executor_arguments(parser)
    assert executor_from_arguments(parser.parse_args([]), 16) == ExecutorSpec("serial")
    assert executor_from_arguments(parser.parse_args(["--jobs", "2"]), 16) == ExecutorSpec("processes", 2)
    spec = executor_from_arguments(parser.parse_args(["--scheduler", "tcp://h:8786"]), 16)
    assert spec.kind == "dask" and spec.describe() == "dask (tcp://h:8786)"
    assert ExecutorSpec("processes", 2).describe() == "processes (2 workers)"


def test_ctrl_c_exits_130_and_writes_nothing(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    calls: list[int] = []

    def interrupted(job: Any) -> list[dict[str, Any]]:
        calls.append(job.setting.index)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return []

    monkeypatch.setattr(evaluation, "evaluate_setting", interrupted)
    out = tmp_path / "eval"
    code = main(["evaluate", "--settings", "4", "--duration", "5", "--estimators", "lm", "--out", str(out)])
    assert code == 130 and calls == [0, 1]
    assert not out.exists()
