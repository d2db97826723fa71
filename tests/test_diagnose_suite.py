"""The diagnosis suite's bookkeeping: a log whose diagnosis raises is recorded, not lost, and fails the command."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest
from suite_rows import diagnosed_row

from estimators.diagnostics import suite
from spaceid_gym.cli import main


def _fake_case(
    robot_name: str, effect: str, seed: int, duration_s: float = 60.0, magnitude: float | None = None
) -> dict[str, Any]:
    if seed == 1:
        raise ZeroDivisionError("division by zero")
    return diagnosed_row(effect, seed)


def test_a_failing_log_is_recorded_and_the_command_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(suite, "run_case", _fake_case)
    code = main(["diagnose-suite", "--seeds", "3", "--effects", "slosh", "--out", str(tmp_path)])
    assert code == 1
    err = capsys.readouterr().err
    assert "slosh log of seed 1 raised ZeroDivisionError: division by zero (test_diagnose_suite.py:" in err
    assert "1 of 3 logs failed" in err and "Traceback" not in err
    with open(tmp_path / "suite.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["verdict"] for r in rows] == ["slosh", "error", "slosh"]
    assert rows[1]["error"].startswith("ZeroDivisionError") and rows[0]["error"] == ""
    summary = json.loads((tmp_path / "summary.json").read_text())["summary"][0]
    assert summary["logs"] == 3 and summary["verdicts"] == {"slosh": 2, "error": 1}
    assert summary["correct_percent"] == pytest.approx(200.0 / 3.0)
    assert summary["rms_over_noise_before_mean"] == pytest.approx(1.5)  # from the diagnosed logs only
    info = json.loads((tmp_path / "summary.json").read_text())["info"]
    assert info["code_version"] == suite.code_version() and info["code_version"] != ""


def test_a_suite_without_failures_exits_zero(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(
        suite, "run_case", lambda robot, effect, seed, duration_s=60.0, magnitude=None: diagnosed_row(effect, seed)
    )
    assert main(["diagnose-suite", "--seeds", "2", "--effects", "none,delay", "--out", str(tmp_path)]) == 0
    assert "| delay | 2 | 100 % |" in (tmp_path / "table.md").read_text()


def test_magnitudes_reach_the_simulation_and_name_thediagnosed_row(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    sizes: list[tuple[str, float | None]] = []

    def fake(robot: str, effect: str, seed: int, duration_s: float = 60.0, magnitude: float | None = None) -> dict[str, Any]:
        sizes.append((effect, magnitude))
        return diagnosed_row(effect, seed) | {"magnitude": "default" if magnitude is None else magnitude}

    monkeypatch.setattr(suite, "run_case", fake)
    args = ["diagnose-suite", "--seeds", "1", "--effects", "none,gyro_scale", "--magnitude", "gyro_scale=2.6e-3"]
    assert main([*args, "--out", str(tmp_path)]) == 0
    assert sizes == [("none", None), ("gyro_scale", 2.6e-3)]
    table = (tmp_path / "table.md").read_text()
    assert "| none | 1 | 100 % |" in table and "| gyro_scale (magnitude 0.0026) | 1 | 100 % |" in table
    assert json.loads((tmp_path / "summary.json").read_text())["info"]["magnitudes"] == {"gyro_scale": 2.6e-3}


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("gyro_scale", "expected effect=size"),
        ("none=1", "expected effect=size"),
        ("slosh=3", "(gyro_scale)"),
        ("gyro_scale=-1", "gyro_scale: expected a finite size > 0, got '-1'"),
        ("gyro_scale=abc", "got 'abc'"),
        ("gyro_scale=nan", "got 'nan'"),
        ("gyro_scale=1e-3,gyro_scale=2e-3", "'gyro_scale' given twice"),
        (" , ", "expected effect=size pairs"),
    ],
)
def test_bad_magnitudes_are_refused_before_anything_runs(
    text: str, named: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "never"
    code = main(["diagnose-suite", "--seeds", "1", "--effects", "none,gyro_scale", "--magnitude", text, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "--magnitude" in err and named in err and "Traceback" not in err
    assert not out.exists()


def test_the_same_seed_draws_the_same_direction_at_any_magnitude() -> None:
    """``--magnitude`` scales the suite's effect without changing its draw or the fuel state (the same logs otherwise)."""
    import numpy as np

    from spaceid_gym.effects.draws import DEFAULT_MAGNITUDES
    from spaceid_gym.robots import load_robot

    robot = load_robot("paper6")
    (setting, default), (again, larger) = (suite.draw_case(robot, "gyro_scale", 4, size) for size in (None, 2.6e-3))
    assert setting == again and default is not None and larger is not None
    np.testing.assert_allclose(
        np.asarray(larger.gyro_scale_misalignment),
        np.asarray(default.gyro_scale_misalignment) * 2.6e-3 / DEFAULT_MAGNITUDES["gyro_scale"],
        rtol=1e-12,
    )


def test_a_size_one_log_cannot_have_is_refused_before_anything_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "never"
    code = main(["diagnose-suite", "--seeds", "20", "--effects", "slosh", "--magnitude", "slosh=10", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and not out.exists()
    assert "--magnitude: slosh=10 on the log of seed 4" in err and "exceeds the remaining liquid" in err


def test_the_summary_keeps_sizes_apart_and_labels_them_with_their_unit() -> None:
    rows = [diagnosed_row("payload", 0) | {"magnitude": "default"}, diagnosed_row("payload", 1) | {"magnitude": 20.0}]
    rows[1]["correct"] = False
    summary = suite.summarise(rows)
    assert [(s["magnitude"], s["correct_percent"]) for s in summary] == [("default", 100.0), (20.0, 0.0)]
    table = suite.markdown_table(summary)
    assert "| payload | 1 | 100 % |" in table and "| payload (magnitude 20 kg) | 1 | 0 % |" in table
