"""Every example runs (on short inputs)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_quickstart_runs() -> None:
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / "quickstart.py"), "--robot", "quick3", "--duration", "3"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "Cramér-Rao bound" in result.stdout and "residual RMS" in result.stdout


def test_demo_runs(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "spaceid_gym.cli", "demo", "--robot", "quick3", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    assert {"overlay.png", "frame.png", "summary.json", "run1"} <= {p.name for p in tmp_path.iterdir()}


def test_identify_fuel_runs() -> None:
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / "identify_fuel.py"), "--robot", "quick3", "--duration", "20"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    assert "hybrid: mdf" in result.stdout and "env loop (hybrid)" in result.stdout
