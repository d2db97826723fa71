"""The diagnosis suite's bookkeeping: a log whose diagnosis raises is recorded, not lost, and fails the command."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest

from estimators.diagnostics import suite
from spaceid_gym.cli import main


def _row(effect: str, seed: int) -> dict[str, Any]:
    """A diagnosed log's row as :func:`suite.run_case` returns it (correct verdict, figures at the noise)."""
    row: dict[str, Any] = {"effect": effect, "seed": seed, "verdict": effect, "correct": True, "runner_up": ""}
    row.update(rms_over_noise_before=1.5, rms_over_noise_after=1.02, wall_time_s=0.1)
    for name in ("mdf", "bx", "by", "bz"):
        for when in ("before", "after"):
            row[f"z_{name}_{when}"] = row[f"z_{name}_{when}_at_estimate"] = 1.0
    return row


def _fake_case(robot_name: str, effect: str, seed: int, duration_s: float = 60.0) -> dict[str, Any]:
    if seed == 1:
        raise ZeroDivisionError("division by zero")
    return _row(effect, seed)


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
    monkeypatch.setattr(suite, "run_case", lambda robot, effect, seed, duration_s=60.0: _row(effect, seed))
    assert main(["diagnose-suite", "--seeds", "2", "--effects", "none,delay", "--out", str(tmp_path)]) == 0
    assert "| delay | 2 | 100 % |" in (tmp_path / "table.md").read_text()
