"""``spaceid compare / diagnose / report / identify --effects`` from the command line (run in this process)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from spaceid_gym.cli import main


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run1"
    assert (
        main(["simulate", "--duration", "15", "--seed", "3", "--hidden-effects", "delay[delay_s=0.04]", "--out", str(out)]) == 0
    )
    return out


def test_identify_compare_diagnose_report(dataset: Path, tmp_path: Path, spaceid: Callable[..., Any]) -> None:
    urdf, log = str(dataset / "robot.urdf"), str(dataset / "log.csv")
    estimate = tmp_path / "estimate.json"
    assert spaceid("identify", "--robot", urdf, "--log", log, "--estimator", "lm", "--out", str(estimate)).returncode == 0
    result = spaceid("compare", "--robot", urdf, "--log", log, "--estimate", str(estimate), "--out", str(tmp_path / "cmp"))
    assert result.returncode == 0, result.stderr
    assert "x noise floor" in result.stdout and (tmp_path / "cmp" / "overlay.png").is_file()
    candidates = "delay,initial_momentum,gyro_bias"
    diag = spaceid(
        "diagnose", "--robot", urdf, "--log", log, "--candidates", candidates, "--apply", "best", "--out", str(tmp_path / "d")
    )
    assert diag.returncode == 0, diag.stderr
    saved = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert saved["verdict"] == "delay" and saved["candidates"][0]["effect"] == "delay"
    after = json.loads((tmp_path / "d" / "estimate_after.json").read_text())
    assert after["parameterisation"] == "fuel+delay" and abs(after["delay_s"] - 0.04) < 0.005
    with_effect = tmp_path / "estimate2.json"
    ident = spaceid(
        "identify", "--robot", urdf, "--log", log, "--effects", "delay", "--estimator", "lm", "--out", str(with_effect)
    )
    assert ident.returncode == 0, ident.stderr
    report = spaceid("report", "--robot", urdf, "--log", log, "--candidates", candidates, "--out", str(tmp_path / "r.html"))
    assert report.returncode == 0, report.stderr
    assert "fuel unknowns" in report.stdout  # truth.json next to the log: errors before and after
    assert (tmp_path / "r.html").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["identify", "--effects", "sloshing"], "unknown effect 'sloshing'"),
        (["diagnose", "--candidates", "wind", "--out", "x"], "unknown effects ['wind']"),
        (["compare", "--estimate", "missing.json", "--out", "x"], "cannot read the estimate file"),
    ],
)
def test_bad_input_exits_2_with_one_line(
    dataset: Path, tmp_path: Path, spaceid: Callable[..., Any], args: list[str], message: str
) -> None:
    command, *rest = args
    base = ["--robot", str(dataset / "robot.urdf"), "--log", str(dataset / "log.csv")]
    if command == "identify":
        rest += ["--out", str(tmp_path / "e.json")]
    result = spaceid(command, *base, *[str(tmp_path / r) if r in ("x", "missing.json") else r for r in rest])
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
