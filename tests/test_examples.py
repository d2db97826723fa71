"""Every example runs (on short inputs)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    result = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    return result


def test_quickstart_runs() -> None:
    result = _run(str(EXAMPLES / "quickstart.py"), "--robot", "quick3", "--duration", "3")
    assert "Cramér-Rao bound" in result.stdout and "residual RMS" in result.stdout


def test_demo_runs(tmp_path: Path) -> None:
    _run("-m", "spaceid_gym.cli", "demo", "--out", str(tmp_path))  # the built-in robot, as `make demo` runs it
    assert {"overlay.png", "frame.png", "summary.json", "run1", "loop-report.html"} <= {p.name for p in tmp_path.iterdir()}
    assert (tmp_path / "run1" / "estimate.json").is_file()
    loop = json.loads((tmp_path / "summary.json").read_text())["loop"]
    assert loop["verdict"] == loop["hidden"]  # the demo's loop names the effect its window hides


def test_identify_fuel_runs() -> None:
    result = _run(str(EXAMPLES / "identify_fuel.py"), "--robot", "quick3", "--duration", "20")
    assert "hybrid: mdf" in result.stdout and "env loop (hybrid)" in result.stdout


def test_find_missing_effect_runs(tmp_path: Path) -> None:
    """The whole loop on a short log with a hidden system momentum: named, added, the residual back at the noise."""
    report = tmp_path / "report.html"
    result = _run(str(EXAMPLES / "find_missing_effect.py"), "--duration", "20", "--out", str(report))
    assert "diagnosis: initial_momentum" in result.stdout and "after adding initial_momentum" in result.stdout
    assert report.is_file() and "data:image/png;base64," in report.read_text()
