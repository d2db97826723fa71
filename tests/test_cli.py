"""The ``spaceid`` command (run in this process): dataset folders and clear errors without tracebacks."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spaceid_gym.cli import main
from spaceid_gym.log import load_dataset


def test_simulate_writes_a_self_contained_dataset(tmp_path: Path) -> None:
    out = tmp_path / "run1"
    code = main(
        [
            "simulate",
            "--robot",
            "quick3",
            "--duration",
            "2",
            "--fuel-consumed",
            "12",
            "--tank",
            "0.10,-0.05,0.08",
            "--seed",
            "3",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    assert {p.name for p in out.iterdir()} == {"log.csv", "robot.urdf", "truth.json"}
    header = (out / "log.csv").read_text().splitlines()[0]
    assert header == "t,q1,q2,q3,dq1,dq2,dq3,wx,wy,wz,qw,qx,qy,qz"
    truth = json.loads((out / "truth.json").read_text())
    assert truth["fuel_consumed_kg"] == 12.0 and truth["tank_position_m"] == [0.1, -0.05, 0.08]
    assert truth["base_mass_kg"] == pytest.approx(108.0)
    assert np.array(truth["base_inertia_kgm2"]).shape == (3, 3) and len(truth["base_com_m"]) == 3
    assert truth["seed"] == 3 and truth["noise"]["gyro_std_rad_s"] > 0 and truth["integration_substeps"] == 1
    dataset = load_dataset(out, n_joints=3)
    assert dataset.log.n_samples == 101
    assert '<robot name="quick3">' in (out / "robot.urdf").read_text()


def test_simulate_is_deterministic(tmp_path: Path) -> None:
    args = ["simulate", "--robot", "quick3", "--duration", "1", "--seed", "5"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "a" / "log.csv").read_text() == (tmp_path / "b" / "log.csv").read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--fuel-consumed", "200"], "not below the full-tank base mass"),
        (["--tank", "1,2"], "--tank"),
        (["--robot", "nowhere.urdf"], "not a shipped robot"),
        (["--duration", "-1"], "duration"),
        (["--rate", "0"], "--rate"),
    ],
)
def test_bad_input_exits_non_zero_without_traceback(
    tmp_path: Path, spaceid: Callable[..., Any], args: list[str], message: str
) -> None:
    result = spaceid("simulate", "--robot", "quick3", "--duration", "1", "--out", str(tmp_path / "x"), *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "x" / "log.csv").exists()


_BASE = (
    '<link name="base"><inertial><mass value="100"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
)
_ARM = (
    '<link name="l1"><inertial><mass value="5"/><inertia ixx="{ixx}" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
)
_JOINT = '<joint name="j1" type="{jtype}"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="0.1" effort="10"/></joint>'


@pytest.mark.parametrize(
    ("urdf", "message"),
    [
        ('<robot name="r"><link name="base"/></robot>', "has no <inertial>"),
        (f'<robot name="r">{_BASE}{_ARM.format(ixx=5)}{_JOINT.format(jtype="revolute")}</robot>', "triangle inequality"),
        (f'<robot name="r">{_BASE}{_ARM.format(ixx=1)}{_JOINT.format(jtype="prismatic")}</robot>', "type 'prismatic'"),
    ],
)
def test_bad_urdf_is_reported(tmp_path: Path, spaceid: Callable[..., Any], urdf: str, message: str) -> None:
    path = tmp_path / "bad.urdf"
    path.write_text(urdf)
    result = spaceid("simulate", "--robot", str(path), "--out", str(tmp_path / "x"))
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr
