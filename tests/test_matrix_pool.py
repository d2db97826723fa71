"""Runs of the variation matrix pooled (``spaceid pool-matrix``), and the per-cell targets the matrix's table checks."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.stats import binom
from suite_rows import matrix_row

from estimators.diagnostics import matrix
from estimators.diagnostics.matrix import fuel_z_chance, share_lower_bound, short_of_targets, summarise_matrix
from estimators.diagnostics.matrix_pool import pool_matrix_runs, read_matrix_run
from spaceid_gym.cli import main
from spaceid_gym.errors import SpaceIdInputError


def make_run(out: Path, first_seed: int, monkeypatch: pytest.MonkeyPatch, fix: str = "robot=paper6") -> Path:
    """A matrix run of 4 gyro-bias logs from ``first_seed`` (:func:`matrix_row`: no simulation) written to ``out``."""
    monkeypatch.setattr(matrix, "guarded_variation", matrix_row)
    argv = ["diagnose-suite", "--matrix", "--seeds", "4", "--first-seed", str(first_seed), "--effects", "gyro_bias"]
    main([*argv, "--fix", fix, "--out", str(out)])
    return out


def test_pooled_runs_keep_every_row_typed_name_its_run_and_count_as_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    first, second = make_run(tmp_path / "a", 0, monkeypatch), make_run(tmp_path / "b", 4, monkeypatch)
    run = read_matrix_run(first)
    written = json.loads((first / "summary.json").read_text())["summary"]
    # read back, the rows give the summary the run wrote (types as made: ints, floats, booleans, None for empty)
    assert json.loads(json.dumps(summarise_matrix(run.rows)).replace("NaN", "null")) == written
    assert run.rows[0]["seed"] == 0 and run.rows[0]["correct"] is True and run.rows[0]["slosh_model"] is None
    capsys.readouterr()
    # the first run holds an error row (seed 3): the pooled run reports it and exits 1, as a run does
    assert main(["pool-matrix", str(first), str(second), "--out", str(tmp_path / "pooled")]) == 1
    assert "gyro_bias log of seed 3 raised ValueError: broken" in capsys.readouterr().err
    with (tmp_path / "pooled" / "matrix.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["seed"], r["run"]) for r in rows] == [(str(s), "a" if s < 4 else "b") for s in range(8)]
    info = json.loads((tmp_path / "pooled" / "summary.json").read_text())
    overall = next(s for s in info["summary"] if s["axis"] == "all")
    # eligible: even seeds (power 0.95); wrong: seed 2; the error: seed 3 (not eligible)
    assert (overall["logs"], overall["eligible"], overall["correct"]) == (8, 4, 3)
    assert [r["first_seed"] for r in info["info"]["runs"]] == [0, 4] and info["info"]["pooled"] is True


def test_pooling_refuses_a_log_twice_mixed_code_and_other_lengths_naming_the_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = read_matrix_run(make_run(tmp_path / "a", 0, monkeypatch))
    with pytest.raises(SpaceIdInputError, match=r"seed 0 .* in both .*a and .*a"):
        pool_matrix_runs([first, first])
    # the same seeds with another axis pinned are other logs
    other = read_matrix_run(make_run(tmp_path / "b", 0, monkeypatch, fix="robot=quick3"))
    assert len(pool_matrix_runs([first, other])[0]) == 8
    newer = read_matrix_run(make_run(tmp_path / "c", 4, monkeypatch))
    newer.info["code_version"] = "abc1234"
    with pytest.raises(SpaceIdInputError, match=r"different code .*--mixed-code"):
        pool_matrix_runs([first, newer])
    assert pool_matrix_runs([first, newer], mixed_code=True)[1]["code_version"].startswith("mixed: ")
    newer.info["duration_s"] = 30.0
    with pytest.raises(SpaceIdInputError, match="differ in length"):
        pool_matrix_runs([first, newer], mixed_code=True)


@pytest.mark.parametrize(
    ("damage", "needle"),
    [
        (lambda d: (d / "summary.json").unlink(), "summary.json: not found"),
        (lambda d: (d / "summary.json").write_text('{"info": {"matrix": false}}'), "not a variation matrix run"),
        (lambda d: _edit_csv(d, "seed", "x"), "matrix.csv, line 2, column seed: expected an integer, got 'x'"),
        (lambda d: _edit_csv(d, "correct", "yes"), "line 2, column correct: expected True or False"),
        (lambda d: _edit_csv(d, "expected_power", "high"), "column expected_power: expected a number"),
        (lambda d: _drop_column(d, "wall_time_s"), "columns wall_time_s missing"),
    ],
)
def test_a_damaged_run_is_refused_naming_file_line_and_column(
    damage: Any, needle: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    run = make_run(tmp_path / "a", 0, monkeypatch)
    damage(run)
    capsys.readouterr()
    assert main(["pool-matrix", str(run), "--out", str(tmp_path / "pooled")]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not (tmp_path / "pooled").exists()


def _edit_csv(run: Path, column: str, value: str) -> None:
    """Set ``column`` of the first row of ``run``'s matrix.csv to ``value``."""
    with (run / "matrix.csv").open() as f:
        rows = list(csv.DictReader(f))
    rows[0][column] = value
    _write_rows(run, rows)


def _drop_column(run: Path, column: str) -> None:
    """Remove ``column`` from ``run``'s matrix.csv."""
    with (run / "matrix.csv").open() as f:
        rows = [{k: v for k, v in r.items() if k != column} for r in csv.DictReader(f)]
    _write_rows(run, rows)


def _write_rows(run: Path, rows: list[dict[str, str]]) -> None:
    with (run / "matrix.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


@pytest.mark.parametrize(("successes", "trials"), [(10, 10), (20, 20), (9, 10), (45, 50), (1, 7)])
def test_the_lower_bound_is_the_share_at_which_so_many_right_verdicts_have_probability_five_percent(
    successes: int, trials: int
) -> None:
    bound = share_lower_bound(successes, trials)
    assert binom.sf(successes - 1, trials, bound) == pytest.approx(0.05, rel=1e-6)
    if successes == trials:
        assert bound == pytest.approx(0.05 ** (1.0 / trials), rel=1e-9)  # p^n = 0.05
    assert share_lower_bound(0, 5) == 0.0 and math.isnan(share_lower_bound(0, 0))
    with pytest.raises(ValueError, match="successes <= trials"):
        share_lower_bound(6, 5)


def test_the_chance_of_a_fuel_z_rms_is_a_chi_square_tail_with_the_unknowns_independent_or_moving_as_one() -> None:
    """Monte Carlo of standard normal z: four unknowns per log over five logs, independent and identical within a
    log; the share of draws whose RMS reaches 1.5 matches each tail (binomial std of 20,000 draws about 0.001)."""
    rng = np.random.default_rng(20261129)
    independent_z = rng.standard_normal((20_000, 5, 4))
    as_one_z = np.repeat(rng.standard_normal((20_000, 5, 1)), 4, axis=2)
    independent, as_one = fuel_z_chance(1.5, 20, 5)
    for z, chance in ((independent_z, independent), (as_one_z, as_one)):
        share = np.mean(np.sqrt(np.mean(z**2, axis=(1, 2))) >= 1.5)
        assert share == pytest.approx(chance, abs=4.0 * np.sqrt(chance * (1.0 - chance) / 20_000) + 1e-4)
    assert independent < 0.01 < as_one  # correlation within a log makes a high RMS far likelier
    assert all(math.isnan(c) for c in fuel_z_chance(1.6, 0, 0))


def test_cells_short_of_a_target_are_listed_with_what_they_miss() -> None:
    def cell(effect: str, axis: str, correct: int, eligible: int, residual: float = 1.05, z: float = 1.0) -> dict[str, Any]:
        where = {"effect": effect, "axis": axis, "value": "all" if axis == "all" else "20", "logs": eligible + 1}
        measured = {"rms_over_noise_after_max": residual, "fuel_z_rms_after": z, "fuel_z_values_after": 4 * correct}
        measured["fuel_z_logs_after"] = correct
        return where | {"eligible": eligible, "correct": correct} | measured

    summary = [
        cell("none", "all", 19, 20),  # 95 %: meets the clean target
        cell("none", "rate_hz", 18, 20),  # 90 %: misses it
        cell("delay", "all", 9, 10, z=1.6),  # 90 %, but fuel z over 1.5
        cell("delay", "rate_hz", 9, 10, residual=1.15),
        cell("slosh", "rate_hz", 0, 0, residual=math.nan, z=math.nan),  # nothing eligible: misses nothing
    ]
    short = short_of_targets(summary)
    assert len(short) == 3
    assert short[0].startswith("none, rate_hz 20 (21 logs, 20 eligible): named right 18/20 (target 95 %;")
    assert f"{binom.cdf(18, 20, 0.95):.2g} at the target share" in short[0]
    assert short[1].startswith("delay, every log (11 logs, 10 eligible): fuel z RMS 1.60 (target 1.5; as large has")
    independent, as_one = fuel_z_chance(1.6, 36, 9)
    assert f"probability {independent:.2g} at a calibrated bound with the unknowns independent, {as_one:.2g} with" in short[1]
    assert "residual after naming up to 1.150 x noise (target 1.1)" in short[2]
