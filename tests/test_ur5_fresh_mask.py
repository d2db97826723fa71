"""The push mask of ``benchmarks/ur5_fresh_movements.py`` on the real UR5 logs: it leaves the undisturbed recordings of
the test trajectories alone and masks a push injected into one of them.

The limit comes from the six other undisturbed movements (the twin itself left out), so the check is not in-sample.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from ur5_colony_vs_sdp import UNDISTURBED
from ur5_fresh_movements import TWIN, PushThreshold, deviation_log, intervals, push_mask, push_threshold

from estimators.arm.identification import Preparation, load_movements
from spaceid_gym.arm.joint_log import ArmLog

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
pytestmark = pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"the real UR5 logs are not at {UR5_REAL}")


@dataclass(frozen=True)
class Undisturbed:
    """The raw current and ``i_target`` logs of the 7 undisturbed movements and their prepared deviation."""

    currents: dict[str, ArmLog]
    commands: dict[str, ArmLog]
    prepared: dict[str, ArmLog]

    def limit(self, name: str) -> PushThreshold:
        """The limit of the six movements other than ``name``."""
        return push_threshold([self.prepared[other].effort for other in UNDISTURBED if other != name])


@pytest.fixture(scope="module")
def undisturbed() -> Undisturbed:
    currents = load_movements(UR5_REAL, list(UNDISTURBED))
    commands = load_movements(UR5_REAL, list(UNDISTURBED), effort="i_target")
    prepared = {name: deviation_log(currents[name], commands[name], Preparation()) for name in UNDISTURBED}
    return Undisturbed(currents, commands, prepared)


@pytest.mark.parametrize("twin", sorted(TWIN.values()))
def test_the_undisturbed_twin_of_a_test_movement_is_not_masked(undisturbed: Undisturbed, twin: str) -> None:
    prepared = undisturbed.prepared[twin]
    masked = push_mask(prepared.t_s, prepared.effort, undisturbed.limit(twin))
    assert not masked.any(), intervals(prepared.t_s, masked)


def test_an_injected_push_is_masked_and_nothing_else(undisturbed: Undisturbed) -> None:
    """A 1 s half-sine of 1.5 times joint 2's limit added to the measured current (the pushes of the disturbed
    movements reach 1.5-2.9 times the limit, ``docs/results.md``): the mask covers it and nothing far from it."""
    name = "Movement_No9_Singularity_Free_NoDist"
    current, threshold = undisturbed.currents[name], undisturbed.limit(name)
    start_s = current.t_s[0] + 8.0
    phase = (current.t_s - start_s) / 1.0
    bump = np.where((phase > 0) & (phase < 1), np.sin(np.pi * np.clip(phase, 0, 1)), 0.0) * 1.5 * threshold.limit_A[1]
    pushed = dataclasses.replace(current, effort=current.effort + np.outer(bump, np.eye(current.n_joints)[1]))
    prepared = deviation_log(pushed, undisturbed.commands[name], Preparation())
    masked = push_mask(prepared.t_s, prepared.effort, threshold)
    during = (prepared.t_s >= start_s) & (prepared.t_s <= start_s + 1.0)
    far = (prepared.t_s < start_s - 1.0) | (prepared.t_s > start_s + 2.0)
    assert masked[during].all(), intervals(prepared.t_s, masked)
    assert not masked[far].any(), intervals(prepared.t_s, masked)
