"""``spaceid track``: the fuel through a multi-window mission, tracked by the unscented Kalman filter, against ``hybrid``
fitted window by window.

The mission (:func:`simulate_mission`): one satellite (tank position drawn once from the seed), ``windows``
identification windows of ``duration_s`` (60 s at 50 Hz by default), each with its own Fourier excitation (seed
``job_seeds(seed, windows)[w]``, :func:`spaceid_gym.executors.job_seeds`); between two windows the satellite burns
fuel as :class:`~spaceid_gym.mission.FuelSchedule` draws it (5 % of the wet base mass consumed in the first
window, then ``|N(2 %, 1 %)|`` per gap: 27.5 kg, then about 11 kg per gap for paper6), as the env's ``reset`` does
between episodes.

The tracker (:func:`track_mission`): the filter takes the first window from ``hybrid``'s fit of it, polished again
from each of its mirror images (the tank offset reflected; :func:`~estimators.fuel_posterior.basin_minima`: seeds 309
and 218 had their first fit in a mirrored basin 67 and 36 chi-square units above the truth's), the lowest minimum
kept and every distinct basin covered by the posterior's sampler, as is the cost's valley along the fuel
(:func:`~estimators.fuel_posterior.valley_slices`: mission 322's posterior, 18 +- 15 kg, lay far from its 47.5 kg
fit). By default
(``--first-window posterior``) its state and covariance are the posterior mean and covariance of the window's
unknowns under the physical prior (fuel consumed between 0 and the tank's capacity, the tank inside its box in the
satellite), by importance sampling around the fit (:func:`~estimators.fuel_posterior.fuel_posterior`, ~2 s):
the Cramér-Rao covariance at the fit (``--first-window batch``, the default before) is tangent to a curved valley
of the cost (the first window has the least fuel consumed, 27.5 kg for paper6, where the rates see mostly the first
moment ``mdf bf``) and left the first windows' NEES at 11.4, 8.7, 5.2 (30 missions, seeds 230-259), while the
fit's std per unknown was right. ``--first-window ukf`` runs the ``ukf`` estimator's own fit (global start,
tempered passes, :meth:`~estimators.ukf.UnscentedKalman.fitted_tracker`; its covariance is too small there too).
From then on the same filter runs on: before each later
window its parameter random walk runs over the gap (:meth:`~estimators.ukf.UKFTracker.advance`), then it updates
sample by sample through the window (one plain pass, weight 1). The random walk is the documented process noise
of the mission: over a gap of ``gap_s`` seconds it adds the variance ``burn_rms_kg^2`` to the fuel consumed,
``burn_rms_kg = sqrt(mean^2 + std^2)`` of the schedule's step (12.3 kg for paper6: the mean burn is not known to
the filter, so the walk covers it), and nothing to the tank position (a tank does not move):
``random_walk = [burn_rms_kg / (scale_mdf sqrt(gap_s)), 0, 0, 0]`` in the tracker's units (fractions of the scale per
square-root second; inside a 60 s window of a day's gap it adds 0.03 % of that variance).

Until the hand-over (``--first-window posterior``): the first posterior can be wide and curved, and the filter's
Gaussian update of the next window from its moments then over-counts (mission 241: 10.5 +- 7.1 kg after window 0,
truth 27.5; the filter's pass over window 1 ended at 20.3 +- 5.1 kg against 44.3, NEES 125, where the exact
posterior is 29.2 +- 7.5 kg; ``benchmarks/track_second_window.py``). So the tracker keeps the first window's
importance-sampled paths (:class:`~estimators.fuel_posterior.FuelPaths`) and, after each later window, pushes them
through the same random walk and weights them by the window's likelihood (the same identification model). The
filter still streams the window (its NIS, the alarm test and ``samples.csv`` are its); then its state and
covariance are set to the paths' posterior mean and covariance (the window's row: ``exact_posterior`` 1, with the
paths' ``exact_effective_samples`` and ``exact_regularised`` when they were sampled afresh under the kernel prior).
The hand-over test: the mean NEES the filter's own Gaussian after the window would have if the truth were drawn from
the exact posterior, ``tr(P^-1 C) + d^T P^-1 d`` (``handover_nees``; 4 when they agree,
:func:`~estimators.fuel_posterior.expected_nees`), at most :data:`HANDOVER_NEES`; from the next window on the filter
runs alone. A NIS alarm re-initialises the paths with the filter.

The filter's gyro noise ``R = sigma^2 I_3``: in each window the noise the previous window left, the RMS of that
window's residual at the filter's state after it, ``sqrt(RSS / (3T - k))`` (:meth:`~estimators.problem.IdentificationProblem.noise_std`;
in the first window ``hybrid``'s residual there; ``--first-window ukf``: the ``ukf`` estimator's noise, the gyro's
by the median of the log's third differences). That is the noise a user measures: the gyro's, the joint-rate
sensors' carried through the model (white, ~4 % of the variance with the default sensors) and what the model
misses. The gyro's noise alone, or the white part by third differences, left the mean NIS 1-2 % high, beyond the
95 % bounds of 27 000 updates (+-1 %).

Fault detection and recovery (never silent): after each streamed window the window's mean NIS is tested against
:func:`nis_alarm_bound`, its one-sided upper point at the false-alarm rate :data:`NIS_FALSE_ALARM` (1e-4 per
window). The noise ``R`` is the previous window's residual variance, itself estimated from ``3T - k`` residuals, so
for a consistent filter the mean NIS over 3 is F(3n, 3T - k)-distributed rather than chi-square(3n)/3n: the bound is
that F's point (3.25 for 3001 updates; chi-square's alone, 3.17, sits inside the measured spread of consistent
missions, whose largest window of 351 was 3.19). When it fires the filter is re-initialised from ``hybrid``'s fit of
THAT window, as on the first window (``posterior`` or ``batch``; ``posterior`` after a ``ukf`` first window;
nothing carried from the diverged state), and it is recorded: ``reinitialised`` (1) and ``alarm_nis_mean`` (the NIS that
fired) in ``track.csv``, the count and the windows in ``track.json``'s summary, a line printed by the command and a
red marker in ``track.png``. That window's NEES is the re-initialised filter's, and its NIS, like the first
window's, is left out of the NIS figure (``ukf_nis_mean`` nan, ``ukf_updates`` 0).

Judged per window against the truth: the fuel error of the filter (after the window) and of ``hybrid`` on the window
alone; the NEES ``e^T P^-1 e`` of the filter's 4 unknowns (chi-square(4) when consistent) and the mean NIS
``y^T S^-1 y`` of its updates in the window (chi-square(3) each); over the mission: the fuel-mass RMS errors and
their ratio (target: within 1.5 x of hybrid's), the mean NEES over the windows and the mean NIS over every
streaming update, each against the two-sided 95 % bounds of its chi-square mean. The first window's NIS comes from
tempered passes (noise variance x passes) and is left out of the NIS figure.

Writes ``track.csv`` (a row per window), ``samples.csv`` (the filter's fuel and its std once per second of every
later window), ``track.json`` (the figures and the run's settings) and ``track.png`` (the tracked fuel and its
3-sigma band against the truth and hybrid's per-window estimates with their 3-sigma bars), each file atomically.
"""

from __future__ import annotations

import argparse
import io
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy.stats import f

from estimators.estimate import Estimate
from estimators.evaluation import estimator_from_spec
from estimators.fuel_posterior import FuelPaths, basin_minima, expected_nees
from estimators.problem import IdentificationModel, IdentificationProblem
from estimators.ukf import UKFTracker, UnscentedKalman
from spaceid_gym.arrays import FloatArray
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.executors import job_seeds
from spaceid_gym.limits import check_count, check_log_size
from spaceid_gym.log import MeasurementLog, write_bytes_atomic, write_csv_atomic, write_json_atomic
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot
from spaceid_gym.track_statistics import mean_bounds

#: the most windows one mission may have
MAX_WINDOWS = 1000

#: the nominal time between two windows, s (a day)
DEFAULT_GAP_S = 86400.0

#: how the filter takes the mission's first window (see the module docstring)
FIRST_WINDOW = ("posterior", "batch", "ukf")

#: the per-window false-alarm rate of the NIS fault test: 10 windows x hundreds of missions must see about none
NIS_FALSE_ALARM = 1e-4

#: the innovations' dimension (the gyro's 3 axes)
INNOVATION_DOF = 3

#: the unknowns of the fuel problem (fuel consumed, tank x, y, z): a consistent window's NEES is chi-square(4)
UNKNOWNS = 4

#: the hand-over test's bound on the filter's mean NEES under the exact posterior (module docstring): chi-square(4)'s
#: mean 4 plus 0.5, 2.5 times the statistic's Monte Carlo std at the paths' 200 effective draws (about
#: ``sqrt(2 x 4 / 200) = 0.2``), so a filter that agrees is handed over with ~99 % probability, and a hand-over adds at
#: most 12 % to a window's NEES (the 30-mission per-window band allows +27 %)
HANDOVER_NEES = UNKNOWNS + 0.5


@dataclass(frozen=True)
class MissionWindow:
    """One window of a simulated mission: its log, the true fuel unknowns ``theta`` (mdf kg, bf m) and its excitation's seed."""

    index: int
    log: MeasurementLog
    theta_true: FloatArray
    excitation_seed: int


def simulate_mission(robot_name: str, windows: int, seed: int, duration_s: float = 60.0) -> list[MissionWindow]:
    """The mission's windows (see the module docstring): one env, reset with ``seed`` for the first window (the tank
    drawn) and without for the later ones (fuel burnt as the schedule draws it)."""
    robot = load_robot(robot_name)
    env = FreeFloatingIDEnv(robot)
    n_steps = check_log_size(duration_s, env.control_period_s, robot.n_joints, "--duration")
    out = []
    for w, excitation_seed in enumerate(job_seeds(seed, windows)):
        env.reset(seed=seed if w == 0 else None)
        excitation = FourierExcitation(robot.n_joints, seed=excitation_seed)
        for k in range(n_steps):
            env.step(excitation(k * env.control_period_s))
        truth = env.truth()
        theta = np.array([truth["fuel_consumed_kg"], *truth["tank_position_m"]], dtype=float)
        out.append(MissionWindow(w, env.measurement_log(), theta, excitation_seed))
    return out


def burn_rms_kg(robot_name: str, schedule: FuelSchedule | None = None) -> float:
    """The std of the random walk's fuel step over one gap, kg: the RMS of the schedule's step (module docstring)."""
    schedule = schedule or FuelSchedule()
    return math.hypot(schedule.mean_step_fraction, schedule.std_step_fraction) * load_robot(robot_name).base_full.mass_kg


def mission_random_walk(robot_name: str, gap_s: float, schedule: FuelSchedule | None = None) -> FloatArray:
    """The tracker's random walk (4,) for a gap of ``gap_s`` s between windows (see the module docstring)."""
    model = IdentificationModel(load_robot(robot_name), "fuel")
    step_kg = burn_rms_kg(robot_name, schedule)
    return np.array([step_kg / (model.parameters.scale[0] * math.sqrt(gap_s)), 0.0, 0.0, 0.0])


def first_window_tracker(
    ukf: UnscentedKalman, problem: IdentificationProblem, first_window: str, seed: int
) -> tuple[UKFTracker, Estimate | None, FuelPaths | None]:
    """The tracker after the mission's first window (module docstring): ``hybrid``'s fit (returned too) is polished
    again from its mirror images (:func:`~estimators.fuel_posterior.basin_minima`); ``posterior`` starts the tracker
    at the posterior mean and covariance under the physical prior, sampled around every basin found, draws seeded by
    ``seed``, and returns the posterior's importance-sampled paths, carried on until the hand-over; ``batch`` at the
    lowest minimum with its Cramér-Rao covariance; ``ukf`` runs the estimator's own fit."""
    if first_window == "ukf":
        return ukf.fitted_tracker(problem, np.random.default_rng(seed)), None, None
    fitted = estimator_from_spec("hybrid", seed=seed).fit_problem(problem)
    best, *others = basin_minima(problem, fitted.theta)
    noise = problem.noise_std(best)[0]
    paths = None
    if first_window == "posterior":
        paths = FuelPaths(problem, best, noise, np.random.default_rng(seed), basins=others)
        posterior = paths.posterior()
        x0, cov = posterior.mean, posterior.covariance
    else:
        x0, cov = best, np.linalg.inv(problem.fisher(best, noise))
    tracker = ukf.tracker(problem, x0, 0.5 * (cov + cov.T))
    tracker.set_noise(noise)
    return tracker, fitted, paths


def track_mission(
    windows: list[MissionWindow],
    robot_name: str,
    estimator: str = "ukf",
    seed: int = 0,
    gap_s: float = DEFAULT_GAP_S,
    first_window: str = "posterior",
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Track the fuel through ``windows`` with the ``estimator`` spec (a ``ukf``) and fit ``hybrid`` per window.

    ``first_window``: ``posterior``, ``batch`` or ``ukf``, how the filter takes the first window (module docstring). Returns the rows
    of ``track.csv`` (one per window) and of ``samples.csv`` (the filter once per second)."""
    if first_window not in FIRST_WINDOW:
        raise SpaceIdInputError(f"--first-window: expected one of {', '.join(FIRST_WINDOW)}, got {first_window!r}")
    ukf = _ukf(estimator, seed)
    robot = load_robot(robot_name)
    model = IdentificationModel(robot, "fuel")
    walk = mission_random_walk(robot_name, gap_s)
    step_kg = burn_rms_kg(robot_name)
    hybrid = estimator_from_spec("hybrid", seed=seed)
    rows: list[dict[str, Any]] = []
    samples: list[dict[str, Any]] = []
    tracker = None
    paths = None  # the exact posterior's paths while the filter is not yet handed the mission (module docstring)
    reinit = "posterior" if first_window == "ukf" else first_window
    noise_dof = 0  # the degrees of freedom of the previous window's residual noise, set after each window
    for window in windows:
        start = time.perf_counter()
        problem = model.problem(window.log)
        fitted = None
        alarm_nis = handover = effective = math.nan
        regularised = 0
        if tracker is None:
            tracker, fitted, paths = first_window_tracker(ukf, problem, first_window, seed)
            exact = paths is not None
            noise = tracker.noise_std_rad_s
            tracker.random_walk = walk.copy()
            nis = math.nan
        else:
            tracker.advance(gap_s)
            tracker.bind(problem)
            tracker.set_noise(noise)  # the previous window's residual noise at the filter's state after it
            first_update = len(tracker.nis)
            period = max(1, round(1.0 / float(np.median(np.diff(window.log.t_s)))))
            for index in range(problem.n_samples):
                tracker.update(index)
                if index % period == period - 1:
                    x, cov = tracker.filter.x, tracker.filter.P
                    samples.append(
                        {
                            "window": window.index,
                            "t_s": float(window.log.t_s[index] - window.log.t_s[0]),
                            "fuel_consumed_kg": float(x[0]),
                            "fuel_std_kg": float(math.sqrt(cov[0, 0])),
                            "true_fuel_consumed_kg": float(window.theta_true[0]),
                        }
                    )
            nis = float(np.mean(tracker.nis[first_update:]))
            if nis > nis_alarm_bound(problem.n_samples, noise_dof):
                alarm_nis = nis  # diverged: restart from this window's batch fit, nothing carried over
                tracker, fitted, paths = first_window_tracker(ukf, problem, reinit, seed)
                tracker.random_walk = walk.copy()
                noise, nis = tracker.noise_std_rad_s, math.nan
                exact = paths is not None
            elif exact := paths is not None:
                paths.extend(problem, noise, step_kg, tracker.estimate())  # the window's exact posterior
                posterior = paths.posterior()
                effective, regularised = posterior.effective_samples, int(paths.regularised)
                handover = expected_nees(posterior, *tracker.estimate())
                tracker.set_state(posterior.mean, posterior.covariance)
                if handover <= HANDOVER_NEES:
                    paths = None  # the filter's update agrees with the exact posterior: it runs on alone
        filter_s = time.perf_counter() - start
        x, cov = tracker.estimate()
        window_noise = noise
        noise = problem.noise_std(x)[0]  # for the next window
        noise_dof = INNOVATION_DOF * problem.n_samples - problem.n_params
        error = x - window.theta_true
        if fitted is None:
            fitted = hybrid.fit(model, window.log)
        rows.append(
            {
                "window": window.index,
                "true_fuel_consumed_kg": float(window.theta_true[0]),
                "true_tank_x_m": float(window.theta_true[1]),
                "true_tank_y_m": float(window.theta_true[2]),
                "true_tank_z_m": float(window.theta_true[3]),
                "ukf_fuel_consumed_kg": float(x[0]),
                "ukf_fuel_std_kg": float(math.sqrt(cov[0, 0])),
                "ukf_tank_x_m": float(x[1]),
                "ukf_tank_y_m": float(x[2]),
                "ukf_tank_z_m": float(x[3]),
                "ukf_nees": float(error @ np.linalg.solve(cov, error)),
                "ukf_nis_mean": nis,
                "ukf_updates": 0 if math.isnan(nis) else int(problem.n_samples),
                "ukf_noise_std_rad_s": window_noise,
                "ukf_wall_time_s": filter_s,
                "reinitialised": int(not math.isnan(alarm_nis)),
                "exact_posterior": int(exact),
                "handover_nees": handover,
                "exact_effective_samples": effective,
                "exact_regularised": regularised,
                "alarm_nis_mean": alarm_nis,
                "hybrid_fuel_consumed_kg": float(fitted.theta[0]),
                "hybrid_fuel_std_kg": float(fitted.theta_std[0]),
                "hybrid_tank_x_m": float(fitted.theta[1]),
                "hybrid_tank_y_m": float(fitted.theta[2]),
                "hybrid_tank_z_m": float(fitted.theta[3]),
                "hybrid_wall_time_s": fitted.wall_time_s,
                "excitation_seed": window.excitation_seed,
            }
        )
    return rows, samples


def _ukf(spec: str, seed: int = 0) -> UnscentedKalman:
    """The tracking filter of the ``--estimator`` spec; raises unless it is a ``ukf``."""
    ukf = estimator_from_spec(spec, seed=seed)
    if not isinstance(ukf, UnscentedKalman):
        raise SpaceIdInputError(f"--estimator: track runs the unscented Kalman filter (ukf[...]), got {spec!r}")
    return ukf


def nis_alarm_bound(updates: int, noise_dof: int, false_alarm: float = NIS_FALSE_ALARM) -> float:
    """The upper ``1 - false_alarm`` point of a consistent filter's mean NIS over ``updates`` 3-axis innovations when
    ``R`` is a residual variance estimated with ``noise_dof`` degrees of freedom: 3 F(3 updates, noise_dof)."""
    if updates < 1 or noise_dof < 1:
        raise SpaceIdInputError(f"nis_alarm_bound: expected updates and noise_dof >= 1, got {updates}, {noise_dof}")
    return float(INNOVATION_DOF * f.ppf(1.0 - false_alarm, INNOVATION_DOF * updates, noise_dof))


def summarise_track(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The mission's figures (see the module docstring)."""
    truth = np.array([r["true_fuel_consumed_kg"] for r in rows])
    ukf = np.array([r["ukf_fuel_consumed_kg"] for r in rows])
    hybrid = np.array([r["hybrid_fuel_consumed_kg"] for r in rows])
    rms_ukf = float(np.sqrt(np.mean((ukf - truth) ** 2)))
    rms_hybrid = float(np.sqrt(np.mean((hybrid - truth) ** 2)))
    nees = np.array([r["ukf_nees"] for r in rows])
    nees_low, nees_high = mean_bounds(4, len(rows))
    streamed = [r for r in rows if r["ukf_updates"] > 0]
    updates = sum(r["ukf_updates"] for r in streamed)
    nis = float(sum(r["ukf_nis_mean"] * r["ukf_updates"] for r in streamed) / updates) if updates else math.nan
    nis_low, nis_high = mean_bounds(3, updates) if updates else (math.nan, math.nan)
    return {
        "windows": len(rows),
        "fuel_rms_error_ukf_kg": rms_ukf,
        "fuel_rms_error_hybrid_kg": rms_hybrid,
        "fuel_rms_ratio_ukf_over_hybrid": rms_ukf / rms_hybrid if rms_hybrid > 0.0 else math.inf,
        "fuel_within_1_5x_hybrid": bool(rms_ukf <= 1.5 * rms_hybrid),
        "nees_mean": float(nees.mean()),
        "nees_bounds_95": [nees_low, nees_high],
        "nees_consistent": bool(nees_low <= nees.mean() <= nees_high),
        "nis_mean": nis,
        "nis_updates": int(updates),
        "nis_bounds_95": [nis_low, nis_high],
        "nis_consistent": bool(nis_low <= nis <= nis_high) if updates else False,
        "reinitialisations": sum(int(r.get("reinitialised", 0)) for r in rows),
        "reinitialised_windows": [r["window"] for r in rows if r.get("reinitialised", 0)],
    }


def plot_track(path: Path, rows: list[dict[str, Any]], samples: list[dict[str, Any]], duration_s: float) -> Path:
    """``track.png``: the fuel consumed over the mission's windows (see the module docstring)."""
    fig = Figure(figsize=(9, 7))
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    w = np.array([r["window"] for r in rows], dtype=float)
    truth = np.array([r["true_fuel_consumed_kg"] for r in rows])
    ukf, ukf_std = (np.array([r[k] for r in rows]) for k in ("ukf_fuel_consumed_kg", "ukf_fuel_std_kg"))
    hyb, hyb_std = (np.array([r[k] for r in rows]) for k in ("hybrid_fuel_consumed_kg", "hybrid_fuel_std_kg"))
    if samples:
        pos = np.array([s["window"] + s["t_s"] / duration_s for s in samples])
        x = np.array([s["fuel_consumed_kg"] for s in samples])
        std = np.array([s["fuel_std_kg"] for s in samples])
        top.fill_between(
            pos, x - 3 * std, x + 3 * std, color="tab:blue", alpha=0.2, step="post", label="ukf 3-sigma (within windows)"
        )
        top.plot(pos, x, color="tab:blue", lw=0.8)
    ends = w + 1.0
    label = "re-initialised (NIS alarm)"
    for end in ends[[bool(r.get("reinitialised", 0)) for r in rows]]:
        bottom.axvline(end, color="tab:red", ls="--", lw=1.0)
        top.axvline(end, color="tab:red", ls="--", lw=1.0, label=label)
        label = None
    top.step(np.r_[w, ends[-1]], np.r_[truth, truth[-1]], where="post", color="k", lw=1.2, label="truth")
    top.errorbar(ends, ukf, yerr=3 * ukf_std, fmt="o", color="tab:blue", ms=4, capsize=3, label="ukf after the window (3 sigma)")
    top.errorbar(
        ends - 0.1, hyb, yerr=3 * hyb_std, fmt="s", color="tab:orange", ms=4, capsize=3, label="hybrid per window (3 sigma)"
    )
    top.set_ylabel("fuel consumed (kg)")
    top.legend(loc="upper left", fontsize=8)
    top.set_title("Fuel through the mission: the ukf tracking across windows vs hybrid per window")
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.errorbar(ends, ukf - truth, yerr=3 * ukf_std, fmt="o", color="tab:blue", ms=4, capsize=3, label="ukf")
    bottom.errorbar(ends - 0.1, hyb - truth, yerr=3 * hyb_std, fmt="s", color="tab:orange", ms=4, capsize=3, label="hybrid")
    bottom.set_ylabel("error (kg)")
    bottom.set_xlabel("window (the marks at each window's end)")
    bottom.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    return write_bytes_atomic(path, buffer.getvalue())


def add_track_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``spaceid track``."""
    parser.add_argument("--robot", default="paper6", help="shipped robot name or URDF path (default paper6)")
    parser.add_argument("--windows", type=int, default=10, help="identification windows of the mission (default 10)")
    parser.add_argument("--estimator", default="ukf", help="the tracking filter, ukf or ukf[key=value,...] (default ukf)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the satellite, its fuel burns, excitations and noise")
    parser.add_argument("--duration", type=float, default=60.0, help="window length, s (default 60)")
    parser.add_argument(
        "--gap",
        type=float,
        default=DEFAULT_GAP_S,
        help="time between windows, s, over which the random walk runs (default 86400)",
    )
    parser.add_argument(
        "--first-window",
        choices=FIRST_WINDOW,
        default="posterior",
        help="start the filter at the posterior mean and covariance around hybrid's fit of the first window "
        "(posterior, default), at the fit with its Cramér-Rao covariance (batch) or run the ukf fit on it (ukf)",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")


def run_track(args: argparse.Namespace) -> None:
    """``spaceid track``: simulate, track, fit, write and print (see the module docstring)."""
    check_count(args.windows, "--windows", MAX_WINDOWS)
    if args.seed < 0:
        raise SpaceIdInputError(f"--seed: expected an integer >= 0, got {args.seed}")
    if not (math.isfinite(args.gap) and args.gap > 0.0):
        raise SpaceIdInputError(f"--gap: expected a positive number of seconds, got {args.gap!r}")
    robot = load_robot(args.robot)
    check_log_size(args.duration, FreeFloatingIDEnv(robot).control_period_s, robot.n_joints, "--duration")
    _ukf(args.estimator)
    start = time.perf_counter()
    windows = simulate_mission(args.robot, args.windows, args.seed, args.duration)
    rows, samples = track_mission(windows, args.robot, args.estimator, args.seed, args.gap, args.first_window)
    summary = summarise_track(rows)
    info = {
        "robot": args.robot,
        "windows": args.windows,
        "seed": args.seed,
        "duration_s": args.duration,
        "gap_s": args.gap,
        "estimator": args.estimator,
        "first_window": args.first_window,
        "random_walk": mission_random_walk(args.robot, args.gap).tolist(),
        "wall_time_s": time.perf_counter() - start,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv_atomic(args.out / "track.csv", rows)
    write_csv_atomic(args.out / "samples.csv", samples)
    write_json_atomic(args.out / "track.json", {"info": info, "summary": summary, "windows": rows})
    plot_track(args.out / "track.png", rows, samples, args.duration)
    print("window | true mdf | ukf mdf +- std | hybrid mdf +- std | NEES | mean NIS (kg)")
    for r in rows:
        nis = "" if math.isnan(r["ukf_nis_mean"]) else f"{r['ukf_nis_mean']:.3f}"
        print(
            f"{r['window']:6d} | {r['true_fuel_consumed_kg']:8.2f} | {r['ukf_fuel_consumed_kg']:7.2f} +- {r['ukf_fuel_std_kg']:5.2f}"
            f" | {r['hybrid_fuel_consumed_kg']:7.2f} +- {r['hybrid_fuel_std_kg']:5.2f} | {r['ukf_nees']:6.2f} | {nis}"
        )
    for r in rows:
        if r["reinitialised"]:
            print(
                f"window {r['window']}: mean NIS {r['alarm_nis_mean']:.3f} above the alarm bound "
                f"(false-alarm rate {NIS_FALSE_ALARM:g}): the filter was re-initialised from hybrid's fit of the window"
            )
    s = summary
    print(f"re-initialisations: {s['reinitialisations']} (windows {s['reinitialised_windows']})")
    print(
        f"fuel RMS error: ukf {s['fuel_rms_error_ukf_kg']:.2f} kg, hybrid {s['fuel_rms_error_hybrid_kg']:.2f} kg "
        f"(ratio {s['fuel_rms_ratio_ukf_over_hybrid']:.2f}; target <= 1.5)"
    )
    print(
        f"NEES mean {s['nees_mean']:.2f} (95 % bounds {s['nees_bounds_95'][0]:.2f}-{s['nees_bounds_95'][1]:.2f}): "
        f"{'consistent' if s['nees_consistent'] else 'NOT consistent'}; NIS mean {s['nis_mean']:.4f} over "
        f"{s['nis_updates']} updates (95 % bounds {s['nis_bounds_95'][0]:.4f}-{s['nis_bounds_95'][1]:.4f}): "
        f"{'consistent' if s['nis_consistent'] else 'NOT consistent'}"
    )
    print(
        f"{args.windows} windows in {info['wall_time_s']:.1f} s; wrote {args.out}/track.csv, samples.csv, track.json, track.png"
    )
