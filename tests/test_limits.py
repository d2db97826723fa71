"""Absurd sizes are refused before anything runs, naming the option and what fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spaceid_gym.cli import main
from spaceid_gym.datasets import simulate_episode
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation
from spaceid_gym.limits import check_count, check_log_size, max_log_samples
from spaceid_gym.robots import Robot


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["simulate", "--duration", "1e12"], "--duration: 1e+12 s at 50 Hz is 5e+13 samples; this machine holds at most"),
        (["simulate", "--duration", "nan"], "--duration: expected a positive number of seconds"),
        (["simulate", "--rate", "0"], "--rate: expected a positive rate"),
        (["evaluate", "--settings", "0"], "--settings: expected an integer from 1 to"),
        (["evaluate", "--settings", "10", "--duration", "1e10"], "--duration: 1e+10 s at 50 Hz"),
        (["diagnose-suite", "--seeds", "100000000"], "--seeds: expected an integer from 1 to 1000000"),
        (["diagnose-suite", "--jobs", "100000"], "--jobs: expected an integer from 1 to"),
        (["diagnose-suite", "--first-seed", "-3"], "--first-seed: expected an integer >= 0"),
        (["diagnose-suite", "--duration", "1e9"], "--duration: 1e+09 s at 100 Hz"),
    ],
)
def test_absurd_sizes_exit_2_naming_the_option_and_write_nothing(
    argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    assert needle in capsys.readouterr().err
    assert not out.exists()


def test_the_library_refuses_a_log_that_cannot_fit(quick3: Robot) -> None:
    limit = max_log_samples(quick3.n_joints)
    assert 100_000 < limit <= 20_000_000  # hours of log at 50 Hz fit, a year does not
    with pytest.raises(SpaceIdInputError, match=r"duration: .* samples; this machine holds at most"):
        simulate_episode(quick3, 1e9, 10.0, np.zeros(3), FourierExcitation(3, seed=0), seed=0)
    assert check_log_size(60.0, 0.02, 3) == 3000
    with pytest.raises(SpaceIdInputError, match="sample period"):
        check_log_size(60.0, -0.02, 3)
    assert check_count(5, "--seeds") == 5
    for bad in (0, 2.5, True, 10**7):
        with pytest.raises(SpaceIdInputError, match="--seeds: expected an integer from 1 to"):
            check_count(bad, "--seeds")  # type: ignore[arg-type]
