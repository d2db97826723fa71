"""``spaceid track``: a short mission tracked by the ukf against hybrid per window; its outputs; bad input."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from spaceid_gym.cli import main
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.track_statistics import mean_bounds
from spaceid_gym.tracking import mission_random_walk, simulate_mission

#: a mission of 60 s windows (the command's design: 20 s windows at 27.5 kg consumed inform the tank position too
#: little for a Gaussian posterior); over 10 measured missions no window's NEES passed chi-square(4)'s 99.9 % point
WINDOWS = 3


@pytest.fixture(scope="module")
def mission(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("mission")
    args = ["track", "--robot", "paper6", "--windows", str(WINDOWS), "--duration", "60", "--seed", "11", "--out", str(out)]
    assert main(args) == 0
    return out


def test_the_mission_burns_fuel_between_windows_and_keeps_its_tank() -> None:
    windows = simulate_mission("paper6", 3, 5, duration_s=2.0)
    fuel = [w.theta_true[0] for w in windows]
    assert fuel[0] == pytest.approx(0.05 * 550.0) and fuel[0] < fuel[1] < fuel[2]
    np.testing.assert_array_equal(windows[0].theta_true[1:], windows[2].theta_true[1:])
    assert len({w.excitation_seed for w in windows}) == 3
    again = simulate_mission("paper6", 3, 5, duration_s=2.0)
    np.testing.assert_array_equal(again[2].log.omega_base_body_rad_s, windows[2].log.omega_base_body_rad_s)


def test_the_random_walk_adds_the_schedules_rms_burn_over_a_gap() -> None:
    walk = mission_random_walk("paper6", 3600.0)
    schedule = FuelSchedule()
    burn_kg = math.hypot(schedule.mean_step_fraction, schedule.std_step_fraction) * 550.0
    scale_kg = 1.2 * schedule.usable_fraction * 550.0  # the fuel unknown's search width
    assert (walk[0] * scale_kg) ** 2 * 3600.0 == pytest.approx(burn_kg**2)
    assert np.all(walk[1:] == 0.0)


def test_the_track_is_written_and_the_filter_is_consistent_with_the_truth(mission: Path) -> None:
    with open(mission / "track.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["window"]) for r in rows] == list(range(WINDOWS))
    error = np.array([float(r["ukf_fuel_consumed_kg"]) - float(r["true_fuel_consumed_kg"]) for r in rows])
    std = np.array([float(r["ukf_fuel_std_kg"]) for r in rows])
    # each window within 4 of the filter's own std (6e-5 per window for a consistent filter); the NEES of the 4
    # unknowns of each window below chi-square(4)'s 99.9 % point
    assert np.all(np.abs(error) < 4.0 * std), error / std
    assert all(float(r["ukf_nees"]) < chi2.ppf(0.999, 4) for r in rows)
    # the first window is taken from the posterior around hybrid's fit (its mean within the fit's std of it); the
    # later ones are the filter's own
    first = (float(rows[0][k]) for k in ("ukf_fuel_consumed_kg", "hybrid_fuel_consumed_kg", "hybrid_fuel_std_kg"))
    ukf, fit, fit_std = first
    assert abs(ukf - fit) < fit_std and rows[0]["ukf_nis_mean"] == "nan"
    summary = json.loads((mission / "track.json").read_text())["summary"]
    # the mean NIS over the streamed updates within its 99.9 % bounds
    low, high = mean_bounds(3, summary["nis_updates"], 0.999)
    assert low < summary["nis_mean"] < high, summary
    assert summary["windows"] == WINDOWS and summary["nis_updates"] == (WINDOWS - 1) * 3001
    assert {"fuel_rms_error_ukf_kg", "fuel_rms_error_hybrid_kg", "nees_bounds_95", "nis_consistent"} <= set(summary)
    with open(mission / "samples.csv", newline="") as f:
        samples = list(csv.DictReader(f))
    assert len(samples) == (WINDOWS - 1) * 60 and {int(s["window"]) for s in samples} == set(range(1, WINDOWS))
    assert (mission / "track.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--windows", "0"], "--windows: expected an integer from 1 to"),
        (["--estimator", "lm"], "--estimator: track runs the unscented Kalman filter"),
        (["--gap", "-1"], "--gap: expected a positive number of seconds"),
        (["--duration", "1e12"], "--duration"),
    ],
)
def test_bad_input_is_refused_without_a_traceback(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["track", "--windows", "1", *args, "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "m").exists()
