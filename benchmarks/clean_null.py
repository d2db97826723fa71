"""The diagnosis's clean-log tests at the truth, over many clean logs of the variation matrix: how often the gyro's
own noise, and the model's residual at the truth, fail them, against the share each test is allowed. A clean log's
false alarm is either the test's (it fails more often than its level says) or the data's (the noise drawn is what a
missing effect would leave); this tells them apart.

Per clean log (the matrix's own draw of its seed, its motion and noise): the gyro's noise alone (the log minus a
noise-free copy of the same motion, noise x1e-6) and the model's residual at the truth (that noise plus the joint
sensors' noise carried through the prediction), each put through

* the whiteness test (Ljung-Box per axis over 50 lags, :func:`~estimators.diagnostics.residuals.correlation.ljung_box`),
  at the diagnosis's level per axis, ``alpha / CLEAN_LOG_FAMILIES / 3``;
* the gyro bias's and the gyro scale's likelihood ratios (3 and 9 unknowns; linear, so chi-square when the noise is
  white with one variance), at the candidates' level, ``alpha / CLEAN_LOG_FAMILIES`` over the candidate fits.

Both ratios weigh by the series' own residual variance after the regression, approximately as the diagnosis does
(it takes the smallest residual variance of its fits, and tests at its fitted baseline, the base unknowns projected
out, not at the truth): the same chi-square under the null, not the same number on one log. The means of the ratios
are 3 and 9 for calibrated tests; their tails at the diagnosis's levels need far more logs than their means. Usage::

    python benchmarks/clean_null.py --first-seed 10864 --logs 150 --jobs 2
    python benchmarks/clean_null.py --first-seed 10864 --logs 600 --fix rate_hz=20 --jobs 2
    python benchmarks/clean_null.py --first-seed 10987 --logs 1 --noise-draws 150 --jobs 2

``--noise-draws N``: each log's motion measured with its own draw and N - 1 more, their noise seeds drawn per log
(:func:`~spaceid_gym.executors.job_seeds` of the log's seed), instead of its own draw alone. The figures of
docs/results.md (clean logs' false alarms) come from here.
"""

from __future__ import annotations

import argparse
import dataclasses
from functools import partial
from typing import Any

import numpy as np
from scipy.stats import binomtest, chi2

from estimators.diagnostics.diagnose import CANDIDATE_VARIANTS, CLEAN_LOG_FAMILIES, DEFAULT_CANDIDATES, candidate_model
from estimators.diagnostics.residuals.correlation import ljung_box
from estimators.diagnostics.workflow import true_parameters
from estimators.problem import IdentificationModel
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.executors import add_executor_arguments, executor_from_arguments, job_seeds, run_jobs
from spaceid_gym.log import MeasurementLog
from spaceid_gym.variations import VariationCase, draw_variation, parse_fixed, simulate_variation, truth_of

#: the noise scale of the noise-free copy (as benchmarks/attitude_drift.py's)
NOISE_FREE_SCALE = 1e-6

#: the Ljung-Box lags of the diagnosis's residual analysis
LAGS = 50

SERIES = ("gyro noise", "residual at the truth")
TESTS = ("whiteness", "gyro_bias", "gyro_scale")


def _ratio(y: np.ndarray, columns: np.ndarray) -> float:
    """The likelihood ratio of regressing ``y`` (T, 3) on ``columns`` (3 T, k), weighed by the fit's residual variance."""
    flat = y.ravel()
    coef = np.linalg.lstsq(columns, flat, rcond=None)[0]
    left = flat - columns @ coef
    variance = float(left @ left) / (flat.size - columns.shape[1])
    return float(flat @ flat - left @ left) / variance


def _effect_columns(model: IdentificationModel, log: MeasurementLog, truth: dict[str, Any], effect: str) -> np.ndarray:
    """The effect's columns (3 T, k_e) as the diagnosis's candidate has them: the derivative of the candidate model's
    prediction in the effect's unknowns, at the truth with the effect off."""
    extended = candidate_model(model, effect)
    theta = true_parameters(extended, truth)
    if theta is None:
        raise RuntimeError(f"{effect}: the truth has no fuel unknowns")
    added = extended.parameters.n_params - model.parameters.n_params
    return extended.problem(log).jacobian(theta, count=False)[:, -added:]


def tested(case: VariationCase, duration_s: float, noise_seed: int | None) -> dict[str, Any]:
    """The whiteness p-values (per axis) and the bias's and scale's ratios of the gyro noise and of the residual at the
    truth, for ``case``'s motion measured with ``noise_seed``'s noise (``None``: the case's own draw). The whiteness
    test over :data:`LAGS` lags, or a quarter of the samples on a shorter log, as the diagnosis's residual analysis."""
    quiet = simulate_variation(dataclasses.replace(case, noise_scale=NOISE_FREE_SCALE), duration_s, noise_seed=0)
    env = simulate_variation(case, duration_s, noise_seed=noise_seed)
    log = env.measurement_log()
    model = IdentificationModel(env.robot, "fuel")
    truth = truth_of(env)
    theta = true_parameters(model, truth)
    if theta is None:
        raise RuntimeError(f"seed {case.seed}: the truth has no fuel unknowns")
    residual = model.problem(log).residuals(theta, count=False).reshape(-1, 3)  # predicted - measured
    series = (log.omega_base_body_rad_s - quiet.measurement_log().omega_base_body_rad_s, -residual)
    columns = {test: _effect_columns(model, log, truth, test) for test in TESTS[1:]}
    lags = min(LAGS, len(residual) // 4)
    out: dict[str, Any] = {"seed": case.seed, "draw": noise_seed, "axes": case.axes()}
    for name, y in zip(SERIES, series, strict=True):
        out[name] = {
            "whiteness": np.asarray(ljung_box(y, lags)[1], dtype=float),
            **{test: _ratio(y, cols) for test, cols in columns.items()},
            "rms": float(np.sqrt(np.mean(y * y))),
        }
    return out


def levels(alpha: float) -> dict[str, float]:
    """The diagnosis's level of each test: per axis for the whiteness test, per candidate for the ratios."""
    fits = sum(len(CANDIDATE_VARIANTS.get(name, (name,))) for name in DEFAULT_CANDIDATES)
    family = alpha / CLEAN_LOG_FAMILIES
    return {"whiteness": family / 3.0, "gyro_bias": family / fits, "gyro_scale": family / fits}


def _share(failed: int, total: int) -> str:
    """``failed / total`` with its exact (Clopper-Pearson) 95 % interval."""
    interval = binomtest(failed, total).proportion_ci(0.95)
    return f"{failed}/{total} ({failed / total:.4f}, 95 % {interval.low:.4f}-{interval.high:.4f})"


def summary(rows: list[dict[str, Any]], alpha: float) -> list[str]:
    """Per series and test: the logs failing at the diagnosis's level (with the share's interval, against the nominal:
    the level, Bonferroni over the axes for the whiteness test), the shares below 1 %, the ratios' mean (3 and 9 when
    calibrated, with its standard error), and the logs that fail."""
    level = levels(alpha)
    dof = {"gyro_bias": 3, "gyro_scale": 9}
    lines = []
    for name in SERIES:
        ratio_rms = np.mean([r[name]["rms"] / r[SERIES[0]]["rms"] for r in rows])
        lines.append(f"{name} (RMS over the gyro noise's, mean over the logs: {ratio_rms:.3f})")
        for test in TESTS:
            if test == "whiteness":
                p = np.array([r[name][test] for r in rows])  # (N, 3)
                fails = p.min(axis=1) < level[test]
                detail = f"share p < 1 % per axis {', '.join(f'{v:.4f}' for v in np.mean(p < 0.01, axis=0))} (0.01 each)"
                nominal = 3.0 * level[test]
            else:
                ratio = np.array([r[name][test] for r in rows])
                p = chi2.sf(ratio, dof[test])
                fails = p < level[test]
                sem = ratio.std(ddof=1) / np.sqrt(len(ratio)) if len(ratio) > 1 else float("nan")
                detail = f"mean ratio {ratio.mean():.2f} +- {sem:.2f} ({dof[test]}), share p < 1 % {_share(int(np.sum(p < 0.01)), len(p))}"
                nominal = level[test]
            failing = ", ".join(
                f"{r['seed']}" + ("" if r["draw"] is None else f"/{r['draw']}") for r, f in zip(rows, fails, strict=True) if f
            )
            lines.append(
                f"  {test:10s} fails at the diagnosis's level on {_share(int(fails.sum()), len(rows))}, nominal {nominal:.4f}; "
                f"{detail}" + (f"; failing: {failing}" if failing else "")
            )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first-seed", type=int, required=True, help="the first clean log's seed")
    parser.add_argument("--alpha", type=float, default=0.01, help="the diagnosis's clean-log budget (its default)")
    parser.add_argument("--logs", type=int, default=60, help="how many clean logs, from --first-seed on")
    parser.add_argument("--fix", default=None, help="pin axes of the cases, e.g. 'rate_hz=20'")
    parser.add_argument("--noise-draws", type=int, default=None, help="measure each motion with this many noise seeds")
    parser.add_argument("--seconds", type=float, default=60.0, help="the log's length (the matrix's: 60 s)")
    add_executor_arguments(parser)
    args = parser.parse_args()
    expected = {
        "--logs": ("at least 1", args.logs >= 1),
        "--noise-draws": ("at least 1", args.noise_draws is None or args.noise_draws >= 1),
        "--alpha": ("a level in (0, 1)", 0.0 < args.alpha < 1.0),
        "--seconds": ("a positive length", args.seconds > 0.0),
    }
    for flag, (what, ok) in expected.items():
        if not ok:
            parser.error(f"{flag}: expected {what}, got {getattr(args, flag[2:].replace('-', '_'))}")
    try:
        fixed = parse_fixed(args.fix)
        cases = [draw_variation("none", seed, fixed) for seed in range(args.first_seed, args.first_seed + args.logs)]
        executor = executor_from_arguments(args, 64)
    except SpaceIdInputError as error:
        parser.error(str(error))
    jobs: list[tuple[VariationCase, int | None]] = []
    for case in cases:
        more = [] if args.noise_draws is None else job_seeds(case.seed, args.noise_draws - 1)
        jobs += [(case, draw) for draw in [None, *more]]
    rows = run_jobs(partial(_tested_pair, args.seconds), jobs, executor, desc="logs")
    print(
        f"{len(rows)} measurements of {args.logs} clean logs, seeds {args.first_seed}-{args.first_seed + args.logs - 1}"
        + (f", {args.fix}" if args.fix else "")
    )
    print("\n".join(summary(rows, args.alpha)))
    others = [r for r in rows if r["draw"] is not None]
    if others:
        print(f"without the logs' own draws ({len(others)} measurements):")
        print("\n".join(summary(others, args.alpha)))


def _tested_pair(duration_s: float, job: tuple[VariationCase, int | None]) -> dict[str, Any]:
    case, draw = job
    return tested(case, duration_s, draw)


if __name__ == "__main__":
    main()
