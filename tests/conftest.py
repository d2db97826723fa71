"""Shared fixtures."""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot, load_robot

#: the shared data folder next to the repository (UR5 logs, design notes)
SHARED = Path(__file__).resolve().parents[2] / "shared"


@pytest.fixture(autouse=True)
def _environment_left_as_found() -> object:
    """Fails a test that leaves ``os.environ`` changed: a variable left behind (a Dask cluster's OPENBLAS_NUM_THREADS=1
    was) changes how every later test's fresh processes compute, so results came to depend on the tests' order.
    ``PYTEST_CURRENT_TEST`` is pytest's own, set for each phase of a test."""
    before = dict(os.environ)
    yield
    after = dict(os.environ)
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k) and k != "PYTEST_CURRENT_TEST")
    assert not changed, f"the test left environment variables changed: {changed}"


@pytest.fixture(scope="session")
def paper6() -> Robot:
    return load_robot("paper6")


@pytest.fixture(scope="session")
def quick3() -> Robot:
    return load_robot("quick3")


@dataclass(frozen=True)
class FuelEpisode:
    """A simulated identification window with known fuel parameters (paper6, Fourier excitation, documented noise)."""

    robot: Robot
    log: MeasurementLog
    theta_true: np.ndarray  # [mdf kg, bf m (3)]
    noise_std_rad_s: float  # gyro noise per sample


def _fuel_episode(robot: Robot, duration_s: float, seed: int) -> FuelEpisode:
    theta = np.array([60.0, 0.25, -0.2, 0.1])
    env = simulate_episode(robot, duration_s, theta[0], theta[1:], FourierExcitation(robot.n_joints, seed=seed), seed=seed)
    return FuelEpisode(robot, env.measurement_log(), theta, env.sensors.gyro_std_rad_s(env.control_period_s))


@pytest.fixture(scope="session")
def fuel_episode(paper6: Robot) -> FuelEpisode:
    """60 s at 50 Hz (3001 samples), mdf 60 kg, tank (0.25, -0.2, 0.1) m."""
    return _fuel_episode(paper6, 60.0, seed=0)


@pytest.fixture(scope="session")
def short_fuel_episode(paper6: Robot) -> FuelEpisode:
    """As :func:`fuel_episode` but 20 s (1001 samples), for quick checks."""
    return _fuel_episode(paper6, 20.0, seed=1)


@dataclass(frozen=True)
class CliRun:
    """What one ``spaceid`` command left: its exit code and what it printed."""

    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def spaceid(capsys: pytest.CaptureFixture[str]) -> Callable[..., CliRun]:
    """Runs ``spaceid ARGS`` in this process, as ``python -m spaceid_gym.cli ARGS`` runs it, without the 4 s import
    of a new interpreter. An exception the command does not handle propagates (the test fails, as a traceback would);
    argparse's usage errors end in SystemExit, whose code is the exit code; a warning the command emits is appended
    to ``stderr``, where the interpreter prints it. Tests of the interpreter's own output (``-m``, import-time
    messages) keep a subprocess."""

    def run(*args: str) -> CliRun:
        capsys.readouterr()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            try:
                code: object = main(list(args))
            except SystemExit as exc:
                code = exc.code
        out, err = capsys.readouterr()
        err += "".join(warnings.formatwarning(w.message, w.category, w.filename, w.lineno) for w in caught)
        assert isinstance(code, int), code
        return CliRun(code, out, err)

    return run
