"""Shared fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

from spaceid_gym.robots import Robot, load_robot

#: the shared data folder next to the repository (UR5 logs, design notes)
SHARED = Path(__file__).resolve().parents[2] / "shared"


@pytest.fixture(scope="session")
def paper6() -> Robot:
    return load_robot("paper6")


@pytest.fixture(scope="session")
def quick3() -> Robot:
    return load_robot("quick3")
