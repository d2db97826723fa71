"""Off-screen RGB rendering of a free-floating space robot (satellite base + arm) with matplotlib.

Everything is drawn with matplotlib's Agg backend on a :class:`matplotlib.figure.Figure` created
directly (no pyplot, no window, no global matplotlib state is touched), so rendering works
headless and in parallel environments.

Frames and units
----------------
* The **inertial frame** is pinocchio's world frame; the **base frame** is the free-flyer
  joint's frame (the URDF root link's frame, for the shipped robots at the base box's geometric
  centre). Lengths in m, angles in the figure text in degrees.
* ``q_full`` is pinocchio's configuration ``[p_wb (3), quat_wb (x, y, z, w) (4), q_arm (n)]``,
  e.g. :meth:`spaceid_gym.sim.state.FreeFloatingState.pinocchio_configuration`.

What is drawn
-------------
* the base as a wireframe box with the given half extents, centred at the base origin, in the
  base frame's axes;
* the arm as a thick polyline through the origins of the arm joints (joints ``2 .. njoints-1``;
  the free-flyer joint 1 sits at the base origin, marked by the base triad instead, so that the
  arm visibly starts at its mounting point on the base surface), joint markers, and an
  end-effector marker at ``oMi[last] * (2 * c_last)`` with ``c_last`` the last link's CoM in its
  joint frame: for a uniform link whose CoM is at its middle this is the far end of the link;
* the base attitude triad (x red, y green, z blue; length 0.8 x the smallest half extent);
* the system centre of mass (grey cross) which is also the centre of the fixed view;
* a small inertial triad in the lower-left corner, the base attitude as roll/pitch/yaw
  (``R_wb = Rz(yaw) Ry(pitch) Rx(roll)``) in degrees and a free ``info_text`` line.
"""

from __future__ import annotations

from typing import cast

import numpy as np
import pinocchio as pin
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter
from mpl_toolkits.mplot3d.art3d import Line3D
from mpl_toolkits.mplot3d.axes3d import Axes3D
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray

#: view direction of the fixed camera, degrees
VIEW_ELEV_DEG = 25.0
VIEW_AZIM_DEG = -60.0

_BOX_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
# the 12 edges of the box, as pairs of corner indices (corners differing in exactly one sign)
_BOX_EDGES = [(i, j) for i in range(8) for j in range(i + 1, 8) if np.sum(_BOX_CORNER_SIGNS[i] != _BOX_CORNER_SIGNS[j]) == 1]
_TRIAD_COLOURS = ("tab:red", "tab:green", "tab:blue")


def base_half_extents_from_inertia(mass_kg: float, inertia_com_kgm2: FloatArray) -> FloatArray:
    """Half extents of the uniform box with the same mass and diagonal moments of inertia.

    A uniform box of mass ``m`` and half extents ``(a, b, c)`` along its axes has
    ``Ixx = m (b^2 + c^2) / 3``, ``Iyy = m (a^2 + c^2) / 3``, ``Izz = m (a^2 + b^2) / 3``, hence
    ``a^2 = 3 (Iyy + Izz - Ixx) / (2 m)`` and cyclically. Only the diagonal of the inertia is
    used (products of inertia are ignored); squared extents that come out non-positive (a body
    far from box-like, violating nothing but "box") are clipped to a small positive value.

    Args:
        mass_kg: body mass, kg (> 0).
        inertia_com_kgm2: inertia about the CoM in the body (base) frame, shape (3, 3), kg m^2.

    Returns:
        Half extents ``(a, b, c)`` along the body frame's x, y, z axes, shape (3,), m.
    """
    if not mass_kg > 0:
        raise ValueError(f"mass_kg: expected > 0, got {mass_kg}")
    inertia = np.asarray(inertia_com_kgm2, dtype=float)
    if inertia.shape != (3, 3):
        raise ValueError(f"inertia_com_kgm2: expected shape (3, 3), got {inertia.shape}")
    ixx, iyy, izz = np.diag(inertia)
    squared = 1.5 / mass_kg * np.array([iyy + izz - ixx, ixx + izz - iyy, ixx + iyy - izz])
    floor = 1e-6 * max(float(np.max(squared)), 1e-12)
    return cast(FloatArray, np.sqrt(np.maximum(squared, floor)))


def rpy_from_matrix(rot: FloatArray) -> FloatArray:
    """Roll, pitch, yaw (rad) with ``rot = Rz(yaw) Ry(pitch) Rx(roll)``, shape (3,); ``rot`` is (3, 3)."""
    pitch = np.arctan2(-rot[2, 0], np.hypot(rot[0, 0], rot[1, 0]))
    if np.hypot(rot[0, 0], rot[1, 0]) < 1e-12:  # gimbal lock: put everything into yaw
        return np.array([0.0, pitch, np.arctan2(-rot[0, 1], rot[1, 1])])
    return np.array([np.arctan2(rot[2, 1], rot[2, 2]), pitch, np.arctan2(rot[1, 0], rot[0, 0])])


def view_half_range(model: pin.Model, base_half_extents_m: FloatArray) -> float:
    """Half side (m) of a cube centred on the system CoM that contains the robot in any configuration.

    Every point of the robot lies within ``r = max(|half extents|, reach)`` of the base origin,
    where ``reach`` is the sum of the arm's joint placement offsets (mounting point included)
    plus the end-effector extension ``2 |c_last|``. The system CoM lies within
    ``(m_base |c_base| + m_arm reach) / M`` of the base origin, so the sum of both bounds the
    distance from the CoM to any drawn point; 5 % margin is added. Fixed per model, so the view
    does not jump between frames.
    """
    reach = sum(float(np.linalg.norm(model.jointPlacements[i].translation)) for i in range(2, model.njoints))
    reach += 2.0 * float(np.linalg.norm(model.inertias[model.njoints - 1].lever))
    radius = max(float(np.linalg.norm(base_half_extents_m)), reach)
    masses = [float(model.inertias[i].mass) for i in range(1, model.njoints)]
    total = sum(masses)
    com_bound = (masses[0] * float(np.linalg.norm(model.inertias[1].lever)) + (total - masses[0]) * reach) / total
    return 1.05 * (radius + com_bound)


class RobotRenderer:
    """Renders a free-floating robot to RGB arrays, reusing one matplotlib figure.

    Args:
        model: pinocchio model with a free-flyer root joint (joint 1) and revolute arm joints.
        base_half_extents_m: half extents of the base box along the base frame's x, y, z, shape (3,), m
            (e.g. from :func:`base_half_extents_from_inertia`).
        width, height: image size in pixels.
    """

    def __init__(self, model: pin.Model, base_half_extents_m: FloatArray, width: int = 480, height: int = 480) -> None:
        if width < 16 or height < 16:
            raise ValueError(f"image size: expected at least 16 x 16 pixels, got {width} x {height}")
        self.model = model
        self.data = model.createData()
        self.half_extents_m = np.asarray(base_half_extents_m, dtype=float).reshape(3)
        if not np.all(self.half_extents_m > 0):
            raise ValueError(f"base_half_extents_m: expected positive values, got {self.half_extents_m}")
        self.width = int(width)
        self.height = int(height)
        self.half_range_m = view_half_range(model, self.half_extents_m)
        self._triad_length_m = 0.8 * float(np.min(self.half_extents_m))
        self._ee_offset = 2.0 * np.array(model.inertias[model.njoints - 1].lever)
        self._box_corners = _BOX_CORNER_SIGNS * self.half_extents_m

        dpi = 100.0
        self.figure = Figure(figsize=(self.width / dpi, self.height / dpi), dpi=dpi, facecolor="white")
        self.canvas = FigureCanvasAgg(self.figure)
        font = max(5.0, 9.0 * min(self.width, self.height) / 480.0)
        ax = cast(Axes3D, self.figure.add_axes((0.0, 0.0, 1.0, 0.92), projection="3d"))
        ax.view_init(elev=VIEW_ELEV_DEG, azim=VIEW_AZIM_DEG)
        ax.set_proj_type("ortho")
        ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.2)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # the grid gives depth; the scale is in the text
            axis.set_pane_color((0.95, 0.95, 0.97, 1.0))
            axis.set_major_formatter(NullFormatter())
        self.ax = ax
        lw = max(1.0, min(self.width, self.height) / 480.0)
        empty: list[float] = []
        self._box = cast(Line3D, ax.plot(empty, empty, empty, color="0.25", lw=1.2 * lw)[0])
        self._arm = cast(Line3D, ax.plot(empty, empty, empty, color="tab:orange", lw=4.0 * lw, solid_capstyle="round")[0])
        self._joints = cast(Line3D, ax.plot(empty, empty, empty, ls="none", marker="o", ms=5 * lw, mfc="navy", mec="white")[0])
        self._ee = cast(Line3D, ax.plot(empty, empty, empty, ls="none", marker="D", ms=6 * lw, mfc="magenta", mec="black")[0])
        self._com = cast(Line3D, ax.plot(empty, empty, empty, ls="none", marker="x", ms=6 * lw, color="0.5")[0])
        self._triad = [cast(Line3D, ax.plot(empty, empty, empty, color=c, lw=2.0 * lw)[0]) for c in _TRIAD_COLOURS]

        # inertial triad in the lower-left corner: a second 3D axes with the same fixed view
        inset = cast(Axes3D, self.figure.add_axes((0.0, 0.02, 0.2, 0.2), projection="3d"))
        inset.view_init(elev=VIEW_ELEV_DEG, azim=VIEW_AZIM_DEG)
        inset.set_proj_type("ortho")
        inset.set_box_aspect((1.0, 1.0, 1.0))
        inset.set_axis_off()
        inset.patch.set_alpha(0.0)
        for k, (colour, label) in enumerate(zip(_TRIAD_COLOURS, "xyz", strict=True)):
            tip = np.zeros(3)
            tip[k] = 1.0
            inset.plot([0.0, tip[0]], [0.0, tip[1]], [0.0, tip[2]], color=colour, lw=1.5 * lw)
            inset.text(1.2 * tip[0], 1.2 * tip[1], 1.2 * tip[2], label, color=colour, fontsize=0.8 * font, ha="center")
        inset.set_xlim(-0.2, 1.2)
        inset.set_ylim(-0.2, 1.2)
        inset.set_zlim(-0.2, 1.2)
        box = {"facecolor": "white", "alpha": 0.85, "edgecolor": "none", "pad": 1.0}
        self.figure.text(0.01, 0.01, "inertial", fontsize=0.7 * font, color="0.3", bbox=box)
        scale = f"view: \u00b1{self.half_range_m:.1f} m about the system CoM (x)"
        self.figure.text(0.99, 0.01, scale, fontsize=0.7 * font, color="0.3", ha="right", bbox=box)
        self._attitude_text = self.figure.text(0.02, 0.975, "", fontsize=font, va="top", family="monospace", bbox=box)
        self._info_text = self.figure.text(0.02, 0.935, "", fontsize=font, va="top", family="monospace", bbox=box)

    def render(self, q_full: FloatArray, info_text: str = "", data: pin.Data | None = None) -> NDArray[np.uint8]:
        """Draw the robot in configuration ``q_full`` and return the image.

        Args:
            q_full: pinocchio configuration ``[p_wb (3), quat_wb (x, y, z, w) (4), q_arm (n)]``, shape (nq,).
            info_text: one line of free text (e.g. time and fuel) shown under the attitude.
            data: pinocchio data to use for the kinematics (default: the renderer's own).

        Returns:
            RGB image, shape (height, width, 3), dtype uint8.
        """
        q = np.asarray(q_full, dtype=float).reshape(-1)
        if q.shape[0] != self.model.nq:
            raise ValueError(f"q_full: expected {self.model.nq} values, got {q.shape[0]}")
        data = self.data if data is None else data
        pin.forwardKinematics(self.model, data, q)
        com = np.array(pin.centerOfMass(self.model, data, q, False))
        base = data.oMi[1]
        rot_wb = np.array(base.rotation)
        p_wb = np.array(base.translation)

        corners = p_wb + self._box_corners @ rot_wb.T
        edges = np.full((3 * len(_BOX_EDGES), 3), np.nan)  # NaN rows separate the edges
        for k, (i, j) in enumerate(_BOX_EDGES):
            edges[3 * k] = corners[i]
            edges[3 * k + 1] = corners[j]
        self._box.set_data_3d(edges[:, 0], edges[:, 1], edges[:, 2])

        joints = np.array([data.oMi[i].translation for i in range(2, self.model.njoints)])
        ee = data.oMi[self.model.njoints - 1].act(self._ee_offset)
        arm = np.vstack((joints, ee))
        self._arm.set_data_3d(arm[:, 0], arm[:, 1], arm[:, 2])
        self._joints.set_data_3d(joints[:, 0], joints[:, 1], joints[:, 2])
        self._ee.set_data_3d([ee[0]], [ee[1]], [ee[2]])
        self._com.set_data_3d([com[0]], [com[1]], [com[2]])
        for k, line in enumerate(self._triad):
            tip = p_wb + self._triad_length_m * rot_wb[:, k]
            line.set_data_3d([p_wb[0], tip[0]], [p_wb[1], tip[1]], [p_wb[2], tip[2]])

        r = self.half_range_m
        self.ax.set_xlim(com[0] - r, com[0] + r)
        self.ax.set_ylim(com[1] - r, com[1] + r)
        self.ax.set_zlim(com[2] - r, com[2] + r)
        roll, pitch, yaw = np.degrees(rpy_from_matrix(rot_wb)) + 0.0  # + 0.0: no "-0.00"
        self._attitude_text.set_text(f"base roll {roll:7.2f}  pitch {pitch:7.2f}  yaw {yaw:7.2f} deg")
        self._info_text.set_text(info_text)

        self.canvas.draw()
        rgba = np.asarray(self.canvas.buffer_rgba())
        return _fit(rgba[..., :3], self.height, self.width)


def _fit(image: NDArray[np.uint8], height: int, width: int) -> NDArray[np.uint8]:
    """Copy of ``image`` cropped or edge-padded to exactly (height, width, 3) (guards dpi rounding)."""
    out = np.array(image[:height, :width], dtype=np.uint8)  # always a copy: the canvas buffer is reused
    pad_h, pad_w = height - out.shape[0], width - out.shape[1]
    if pad_h or pad_w:
        out = np.pad(out, ((0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    return out


def render_rgb(
    model: pin.Model,
    data: pin.Data,
    q_full: FloatArray,
    *,
    base_half_extents_m: FloatArray,
    width: int = 480,
    height: int = 480,
    info_text: str = "",
) -> NDArray[np.uint8]:
    """One-off rendering; see :class:`RobotRenderer` (reuse one renderer for animations, it is faster).

    Args:
        model, data: pinocchio model (free-flyer root) and a data for it (used for the kinematics).
        q_full: pinocchio configuration, shape (nq,).
        base_half_extents_m: base box half extents in the base frame, shape (3,), m.
        width, height: image size in pixels.
        info_text: one line of free text.

    Returns:
        RGB image, shape (height, width, 3), dtype uint8.
    """
    return RobotRenderer(model, base_half_extents_m, width, height).render(q_full, info_text, data=data)
