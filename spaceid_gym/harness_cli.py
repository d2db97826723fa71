"""Bodies of the commands that run a harness over many simulated logs: ``spaceid evaluate`` (the estimators against the
truth, :mod:`estimators.evaluation`) and ``spaceid diagnose-suite`` (the diagnosis on logs with each effect hidden,
and the variation matrix, :mod:`estimators.diagnostics.suite`) and ``spaceid pool-matrix`` (matrix runs pooled,
:mod:`estimators.diagnostics.matrix_pool`); wired into :mod:`spaceid_gym.cli`, which defines their
arguments.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

from estimators.diagnostics.matrix import run_matrix, write_matrix
from estimators.diagnostics.matrix_pool import pool_matrix_runs, read_matrix_run
from estimators.diagnostics.suite import (
    DIAGNOSTIC_EXCITATION,
    SUITE_EFFECTS,
    code_version,
    failed_rows,
    parse_magnitudes,
    run_suite,
    write_suite,
)
from estimators.evaluation import (
    draw_settings,
    parse_estimator_specs,
    run_evaluation,
    settings_info,
    write_results,
)
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import ExecutorSpec, executor_from_arguments
from spaceid_gym.limits import check_count, check_log_size, max_jobs
from spaceid_gym.robots import load_robot
from spaceid_gym.variations import AXIS_RANGES, AXIS_VALUES, parse_fixed


def run_evaluate(args: argparse.Namespace) -> None:
    """``spaceid evaluate``: the estimators episode by episode against the truth; writes the results table."""
    check_count(args.settings, "--settings")
    executor = executor_from_arguments(args, max_jobs())
    robot = load_robot(args.robot)
    check_log_size(args.duration, 0.02, robot.n_joints, "--duration")
    specs = parse_estimator_specs(args.estimators)
    settings = draw_settings(robot, args.settings, args.seed)
    start = time.perf_counter()
    rows = run_evaluation(
        args.robot,
        specs,
        settings,
        budget_reference=args.budget_reference or None,
        duration_s=args.duration,
        executor=executor,
        seed=args.seed,
    )
    wall_s = time.perf_counter() - start
    info = settings_info(args.robot, settings, args.seed, args.duration, 0.02) | {
        "executor": executor.describe(),
        "wall_time_s": wall_s,
    }
    paths = write_results(args.out, rows, info)
    print(paths["table"].read_text())
    print(
        f"{len(settings)} settings x {len(specs)} estimators in {wall_s:.1f} s ({executor.describe()}); wrote {', '.join(p.name for p in paths.values())}"
    )


def run_diagnose_suite(args: argparse.Namespace) -> int:
    """Runs the suite (or with ``--matrix`` the variation matrix) and writes it; exit code 1 (after writing) if the
    diagnosis of any log raised."""
    executor = executor_from_arguments(args, max_jobs())
    check_count(args.seeds, "--seeds")
    if args.first_seed < 0:
        raise SpaceIdInputError(f"--first-seed: expected an integer >= 0, got {args.first_seed}")
    check_log_size(args.duration, 1.0 / max(AXIS_VALUES["rate_hz"]), 7, "--duration")  # the matrix's fastest, largest
    effects = SUITE_EFFECTS if args.effects is None else tuple(e.strip() for e in args.effects.split(",") if e.strip())
    unknown = [e for e in effects if e not in SUITE_EFFECTS]
    if unknown:
        raise SpaceIdInputError(f"--effects: unknown {unknown}; expected names from {', '.join(SUITE_EFFECTS)}")
    if not effects:
        raise SpaceIdInputError(f"--effects: expected at least one of {', '.join(SUITE_EFFECTS)}")
    runs = {"seeds": args.seeds, "first_seed": args.first_seed, "effects": list(effects), "duration_s": args.duration}
    runs["executor"] = executor.describe()
    if args.matrix:
        return _diagnose_matrix(args, effects, runs, executor)
    if args.fix is not None:
        raise SpaceIdInputError("--fix: pins axes of the variation matrix; give --matrix too")
    robot = args.robot or "paper6"
    magnitudes = parse_magnitudes(args.magnitude, effects, robot, range(args.first_seed, args.first_seed + args.seeds))
    info: dict[str, object] = {"robot": robot, **runs, "magnitudes": magnitudes, "excitation": DIAGNOSTIC_EXCITATION}
    rows = _timed_run(info, lambda: run_suite(robot, effects, args.seeds, args.first_seed, executor, args.duration, magnitudes))
    return _report_suite(rows, write_suite(args.out, rows, info), info)


def _timed_run(info: dict[str, object], run: Callable[[], list[dict[str, object]]]) -> list[dict[str, object]]:
    """``run()``'s rows; adds the code's version (read before it runs) and the wall time to ``info``."""
    start = time.perf_counter()
    info["code_version"] = code_version()
    rows = run()
    info["wall_time_s"] = time.perf_counter() - start
    return rows


def _diagnose_matrix(args: argparse.Namespace, effects: tuple[str, ...], runs: dict[str, object], executor: ExecutorSpec) -> int:
    """``diagnose-suite --matrix``: the variation matrix, written to ``--out`` (``runs``: the seeds, effects and
    duration, for ``summary.json``)."""
    if args.robot is not None or args.magnitude is not None:
        raise SpaceIdInputError("--robot and --magnitude: not with --matrix, whose logs draw them (pin with --fix robot=...)")
    try:
        fixed = parse_fixed(args.fix)
    except SpaceIdInputError as exc:
        raise SpaceIdInputError(f"--fix: {exc}") from None
    info: dict[str, object] = {"matrix": True, **runs, "fixed": fixed, "axis_values": AXIS_VALUES, "axis_ranges": AXIS_RANGES}
    rows = _timed_run(info, lambda: run_matrix(effects, args.seeds, args.first_seed, executor, args.duration, fixed))
    return _report_suite(rows, write_matrix(args.out, rows, info), info)


def run_pool_matrix(args: argparse.Namespace) -> int:
    """``spaceid pool-matrix``: the runs' rows pooled and written as one matrix run; exit code 1 (after writing) if
    any pooled log's diagnosis had raised in its run."""
    rows, info = pool_matrix_runs([read_matrix_run(path) for path in args.runs], args.mixed_code)
    info["executor"] = f"pooled from {len(args.runs)} runs"
    return _report_suite(rows, write_matrix(args.out, rows, info), info)


def _report_suite(rows: list[dict[str, object]], paths: dict[str, Path], info: dict[str, object]) -> int:
    """Print the table and the logs that failed; exit code 1 if any did."""
    print(paths["table"].read_text())
    print(
        f"{len(rows)} logs in {info['wall_time_s']:.1f} s ({info.get('executor', 'serial')}); wrote {', '.join(p.name for p in paths.values())}"
    )
    failed = failed_rows(rows)
    for row in failed:
        print(
            f"spaceid: error: diagnosis of the {row['effect']} log of seed {row['seed']} raised {row['error']}", file=sys.stderr
        )
    if failed:
        print(
            f"spaceid: error: {len(failed)} of {len(rows)} logs failed (verdict 'error' in {paths['csv'].name})", file=sys.stderr
        )
    return 1 if failed else 0
