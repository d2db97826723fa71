"""Tests for the off-screen renderer :mod:`spaceid_gym.envs.render`."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.arrays import FloatArray
from spaceid_gym.envs.render import RobotRenderer, base_half_extents_from_inertia, render_rgb, rpy_from_matrix
from spaceid_gym.robots.robot import Robot, load_robot

WIDTH, HEIGHT = 240, 200


def _q_full(robot: Robot, q_arm: FloatArray, rot_wb: FloatArray | None = None) -> FloatArray:
    """pinocchio configuration with the base at the origin, attitude ``rot_wb`` (default identity)."""
    rot = np.eye(3) if rot_wb is None else rot_wb
    quat = pin.Quaternion(rot)  # coeffs are (x, y, z, w)
    return np.concatenate((np.zeros(3), quat.coeffs(), q_arm))


def _renderer(robot: Robot) -> RobotRenderer:
    he = base_half_extents_from_inertia(robot.base_full.mass_kg, robot.base_full.inertia_com_kgm2)
    return RobotRenderer(robot.model, he, WIDTH, HEIGHT)


@pytest.fixture(scope="module")
def paper6() -> Robot:
    return load_robot("paper6")


@pytest.fixture(scope="module")
def paper6_renderer(paper6: Robot) -> RobotRenderer:
    return _renderer(paper6)


@pytest.mark.parametrize("name", ["quick3", "paper6"])
def test_image_shape_dtype_and_not_blank(name: str) -> None:
    robot = load_robot(name)
    he = base_half_extents_from_inertia(robot.base_full.mass_kg, robot.base_full.inertia_com_kgm2)
    img = render_rgb(
        robot.model,
        robot.model.createData(),
        _q_full(robot, robot.home_configuration()),
        base_half_extents_m=he,
        width=WIDTH,
        height=HEIGHT,
        info_text="t = 0.0 s",
    )
    assert img.shape == (HEIGHT, WIDTH, 3)
    assert img.dtype == np.uint8
    colours = np.unique(img.reshape(-1, 3), axis=0)
    assert len(colours) > 20
    # the arm (orange), the base triad (red, green, blue) are drawn: strongly saturated pixels exist
    saturation = img.max(axis=2).astype(int) - img.min(axis=2).astype(int)
    assert np.count_nonzero(saturation > 100) > 50


def test_arm_configuration_changes_image(paper6: Robot, paper6_renderer: RobotRenderer) -> None:
    home = paper6.home_configuration()
    img_a = paper6_renderer.render(_q_full(paper6, home))
    img_b = paper6_renderer.render(_q_full(paper6, home + np.array([0.8, -0.6, 1.0, 0.3, 0.5, 0.2])))
    img_a2 = paper6_renderer.render(_q_full(paper6, home))
    assert np.count_nonzero(np.any(img_a != img_b, axis=2)) > 100
    np.testing.assert_array_equal(img_a, img_a2)  # the reused figure holds no state from earlier frames


def test_base_rotation_changes_image(paper6: Robot, paper6_renderer: RobotRenderer) -> None:
    home = paper6.home_configuration()
    rot_z90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    img_a = paper6_renderer.render(_q_full(paper6, home))
    img_b = paper6_renderer.render(_q_full(paper6, home, rot_z90))
    assert np.count_nonzero(np.any(img_a != img_b, axis=2)) > 100


def test_info_text_is_drawn(paper6: Robot, paper6_renderer: RobotRenderer) -> None:
    q = _q_full(paper6, paper6.home_configuration())
    assert not np.array_equal(paper6_renderer.render(q, "t = 1.0 s"), paper6_renderer.render(q, "fuel 12.5 kg"))


def test_wrong_configuration_size_rejected(paper6_renderer: RobotRenderer) -> None:
    with pytest.raises(ValueError, match="q_full"):
        paper6_renderer.render(np.zeros(5))


def test_half_extents_from_box_inertia() -> None:
    mass = 550.0
    a, b, c = 1.0, 0.9, 1.1
    inertia = mass / 3.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    np.testing.assert_allclose(base_half_extents_from_inertia(mass, inertia), [a, b, c], rtol=0, atol=1e-12)


def test_half_extents_of_shipped_paper6_base(paper6: Robot) -> None:
    # the paper6 base is documented as a 2.0 x 1.8 x 2.2 m box (plus small products of inertia)
    he = base_half_extents_from_inertia(paper6.base_full.mass_kg, paper6.base_full.inertia_com_kgm2)
    np.testing.assert_allclose(he, [1.0, 0.9, 1.1], atol=1e-4)


def test_half_extents_clipped_positive() -> None:
    he = base_half_extents_from_inertia(1.0, np.diag([1.0, 1.0, 3.0]))  # a^2 + b^2 < 0 is impossible for a box
    assert np.all(he > 0) and np.all(np.isfinite(he))


def test_rpy_from_matrix_round_trip() -> None:
    roll, pitch, yaw = 0.3, -0.4, 2.0
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    np.testing.assert_allclose(rpy_from_matrix(rz @ ry @ rx), [roll, pitch, yaw], atol=1e-12)
