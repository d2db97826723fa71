"""Robot descriptions: shipped URDFs are physical and match the paper; bad URDFs are named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.robots import Robot, available_robots, load_robot


def test_shipped_robots_are_listed() -> None:
    assert {"paper6", "quick3"} <= set(available_robots())


def test_paper6_matches_the_paper(paper6: Robot) -> None:
    assert paper6.n_joints == 6
    assert paper6.base_full.mass_kg == pytest.approx(550.0)
    assert paper6.arm_mass_kg() == pytest.approx(60.0)
    # base about 2 m across: box-equivalent extent from the principal moments
    moments = np.linalg.eigvalsh(paper6.base_full.inertia_com_kgm2)
    m = paper6.base_full.mass_kg
    extents = np.sqrt(12.0 * (moments.sum() / 2.0 - moments) / m)  # edge lengths of the same-inertia box
    assert np.all((extents > 1.5) & (extents < 2.5))
    # reach of a few metres: distance from joint 1 to the last joint plus the last link's CoM x2
    data = paper6.model.createData()
    q = pin.neutral(paper6.model)
    pin.forwardKinematics(paper6.model, data, q)
    reach = np.linalg.norm(data.oMi[paper6.model.njoints - 1].translation - data.oMi[2].translation)
    assert 2.5 < reach < 5.0


@pytest.mark.parametrize("name", ["paper6", "quick3"])
def test_every_link_is_a_physical_body(name: str) -> None:
    robot = load_robot(name)
    for i in range(1, robot.model.njoints):
        inertia = robot.model.inertias[i]
        moments = np.linalg.eigvalsh(inertia.inertia)
        assert inertia.mass > 0 and moments[0] > 0
        assert moments[0] + moments[1] >= moments[2]


def test_user_urdf_from_a_file(tmp_path: Path, quick3: Robot) -> None:
    path = tmp_path / "mine.urdf"
    path.write_text(quick3.urdf_text)
    robot = load_robot(path)
    assert robot.n_joints == 3 and robot.source == str(path)


_LINK = (
    '<link name="{name}"><inertial><origin xyz="0 0 0"/><mass value="{mass}"/>'
    '<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
)
_JOINT = '<joint name="j1" type="{jtype}"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>{limit}</joint>'
_LIMIT = '<limit lower="-1" upper="1" velocity="0.1" effort="10"/>'


def _urdf(base: str | None = None, link: str | None = None, joint: str | None = None) -> str:
    base = base if base is not None else _LINK.format(name="base", mass=100, ixx=1)
    link = link if link is not None else _LINK.format(name="l1", mass=5, ixx=1)
    joint = joint if joint is not None else _JOINT.format(jtype="revolute", limit=_LIMIT)
    return f'<?xml version="1.0"?><robot name="t">{base}{link}{joint}</robot>'


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (_urdf(link='<link name="l1"/>'), "link 'l1' has no <inertial>"),
        (_urdf(link=_LINK.format(name="l1", mass=0, ixx=1)), "link 'l1' has mass '0'"),
        (_urdf(link=_LINK.format(name="l1", mass=5, ixx=3)), "triangle inequality"),
        (_urdf(link=_LINK.format(name="l1", mass=5, ixx=-1)), "not positive definite"),
        (_urdf(joint=_JOINT.format(jtype="prismatic", limit=_LIMIT)), "type 'prismatic'; supported"),
        (_urdf(joint=_JOINT.format(jtype="continuous", limit="")), "type 'continuous'; supported"),
        (_urdf(joint=_JOINT.format(jtype="revolute", limit="")), "needs <limit>"),
        ("<robot><link", "not valid URDF XML"),
        (
            _urdf(joint=_JOINT.format(jtype="revolute", limit=_LIMIT).replace('xyz="0 0 1"', 'xyz="0 0 0"')),
            "expected a non-zero 3-vector",
        ),
        ("<model/>", "expected <robot>"),
    ],
)
def test_bad_urdf_is_named(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    with pytest.raises(SpaceIdInputError, match=message) as err:
        load_robot(path)
    assert str(path) in str(err.value)


def test_unknown_robot_name() -> None:
    with pytest.raises(SpaceIdInputError, match="not a shipped robot"):
        load_robot("paper7")


def test_good_minimal_urdf_loads(tmp_path: Path) -> None:
    path = tmp_path / "ok.urdf"
    path.write_text(_urdf())
    assert load_robot(path).n_joints == 1
