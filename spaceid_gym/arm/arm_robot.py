"""Fixed-base serial arms (the UR5 and any user URDF of a fixed-base revolute chain).

Frames and units
----------------
* The **base frame** is the URDF root link's frame, fixed in the world; gravity is a constant
  vector in it (``gravity_m_s2``; the shipped UR5 stands upright: ``(0, 0, -9.81)`` m/s^2).
* Each moving body ``k`` (1-based, ``k = 1..n``) is the link moved by joint ``k`` together with
  every link fixed to it (pinocchio merges fixed joints); its frame is pinocchio's joint frame
  ``k`` (the URDF child link frame of joint ``k``).
* Joint angles in rad, rates in rad/s, accelerations in rad/s^2, torques in N m, masses in kg,
  lengths in m. pinocchio's configuration is the joint-angle vector itself (nq = nv = n).

The pinocchio ``model`` is shared and never modified; every user of it creates their own
``pinocchio.Data`` (:meth:`ArmRobot.create_data`), so several estimators can work on one robot.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.robots.robot import build_pinocchio_model, parse_urdf_root

#: Standard gravity used for the arms (pinocchio's default magnitude), m/s^2, along -z of the base.
GRAVITY_M_S2: tuple[float, float, float] = (0.0, 0.0, -9.81)

#: Joint acceleration limit used when none is given, rad/s^2. An ASSUMPTION, not a datasheet value:
#: the UR5 datasheet gives no joint acceleration limit (URScript's default joint acceleration for
#: ``movej`` is 1.4 rad/s^2, and the real logs in ``shared/data/ur5-real`` command at most
#: 1.396 rad/s^2 = 80 deg/s^2). 15 rad/s^2 bounds random samples and excitation design; it is
#: ten times what the logs use, and with the shipped (approximate) inertias 15 rad/s^2 on every
#: joint at rest needs at most 132 of the 150 N m at the shoulder, gravity included.
DEFAULT_DDQ_LIMIT_RAD_S2 = 15.0

_SHIPPED = {"ur5": "ur5.urdf"}
_MOVING_JOINT_TYPES = {"revolute"}
_UNSUPPORTED_JOINT_HINTS = {
    "floating": "a free-floating root; load free-floating robots with spaceid_gym.robots.load_robot",
    "planar": "a planar (mobile) root; only fixed-base arms are supported",
    "prismatic": "prismatic joints are not supported (friction and parameter units assume revolute joints)",
    "continuous": "continuous joints are not supported: give the joint type 'revolute' with <limit lower upper>",
}


def available_arms() -> list[str]:
    """Names of the arms shipped with the package (``["ur5"]``)."""
    return sorted(_SHIPPED)


@dataclass(frozen=True, eq=False)
class ArmRobot:
    """A fixed-base serial arm with n revolute joints.

    Attributes:
        name: robot name (URDF ``<robot name>``).
        source: where it came from (``"ur5 (shipped)"`` or the URDF path); starts error messages.
        urdf_text: the URDF source, unchanged.
        model: pinocchio model, fixed base (no root joint), gravity set to ``gravity_m_s2``.
            Shared: do not modify it; use :meth:`create_data` for a private ``pinocchio.Data``.
        joint_names: the n joints in configuration order, shape (n,).
        link_names: URDF child link of each joint (the moving body k), shape (n,).
        q_lower_rad, q_upper_rad: joint position limits, shape (n,), rad.
        dq_limit_rad_s: joint rate limits (symmetric), shape (n,), rad/s.
        ddq_limit_rad_s2: joint acceleration limits (symmetric), shape (n,), rad/s^2 (not in URDF:
            :data:`DEFAULT_DDQ_LIMIT_RAD_S2` unless given to :func:`load_arm`).
        torque_limit_Nm: joint torque limits (symmetric), shape (n,), N m.
        gravity_m_s2: gravity in the base frame, shape (3,), m/s^2.
    """

    name: str
    source: str
    urdf_text: str
    model: pin.Model
    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    q_lower_rad: FloatArray
    q_upper_rad: FloatArray
    dq_limit_rad_s: FloatArray
    ddq_limit_rad_s2: FloatArray
    torque_limit_Nm: FloatArray
    gravity_m_s2: FloatArray

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return len(self.joint_names)

    def create_data(self) -> pin.Data:
        """A new pinocchio ``Data`` for :attr:`model` (one per user / thread)."""
        return self.model.createData()

    def sample_states(self, rng: np.random.Generator, n_samples: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Random joint states, uniform within the limits: ``(q, dq, ddq)``, each shape (T, n).

        Angles are drawn in ``[max(lower, -pi), min(upper, pi)]`` (a revolute joint's dynamics
        repeat every 2 pi), rates in ``+-dq_limit_rad_s``, accelerations in ``+-ddq_limit_rad_s2``.

        Args:
            rng: the seeded generator every draw comes from.
            n_samples: T >= 1.
        """
        if n_samples < 1:
            raise SpaceIdInputError(f"sample_states: n_samples must be >= 1, got {n_samples}")
        lo = np.maximum(self.q_lower_rad, -np.pi)
        hi = np.minimum(self.q_upper_rad, np.pi)
        shape = (n_samples, self.n_joints)
        q = rng.uniform(lo, hi, size=shape)
        dq = rng.uniform(-self.dq_limit_rad_s, self.dq_limit_rad_s, size=shape)
        ddq = rng.uniform(-self.ddq_limit_rad_s2, self.ddq_limit_rad_s2, size=shape)
        return q, dq, ddq


def load_arm(
    spec: str | Path,
    *,
    ddq_limit_rad_s2: float | FloatArray | None = None,
    gravity_m_s2: tuple[float, float, float] | FloatArray = GRAVITY_M_S2,
) -> ArmRobot:
    """Load a shipped arm by name (``"ur5"``) or a fixed-base serial-arm URDF by path.

    Args:
        spec: ``"ur5"`` or a path to a URDF file.
        ddq_limit_rad_s2: joint acceleration limit(s), scalar or shape (n,), rad/s^2; default
            :data:`DEFAULT_DDQ_LIMIT_RAD_S2` (an assumption, see there).
        gravity_m_s2: gravity in the base frame, shape (3,), m/s^2 (default upright: -9.81 z).

    The root link is taken as fixed to the world. A URDF cannot say that its root floats unless
    it has a ``floating`` joint (which is rejected): a free-floating robot's URDF (e.g. ``paper6``)
    would load here as if bolted down; load those with :func:`spaceid_gym.robots.load_robot`.

    Raises:
        SpaceIdInputError: unknown name / missing file, malformed XML, a free-floating or planar
            root, prismatic/continuous/other unsupported joints, a branching chain of moving joints,
            missing or non-positive limits, negative or non-finite masses.
    """
    spec_str = str(spec)
    if spec_str in _SHIPPED:
        text = resources.files("spaceid_gym.arm").joinpath(_SHIPPED[spec_str]).read_text()
        source = f"{spec_str} (shipped)"
    else:
        path = Path(spec_str)
        if not path.is_file():
            raise SpaceIdInputError(f"arm '{spec_str}': not a shipped arm ({', '.join(available_arms())}) and no such URDF file")
        text = path.read_text()
        source = str(path)
    return arm_from_urdf_text(text, source, ddq_limit_rad_s2=ddq_limit_rad_s2, gravity_m_s2=gravity_m_s2)


def arm_from_urdf_text(
    text: str,
    source: str = "<string>",
    *,
    ddq_limit_rad_s2: float | FloatArray | None = None,
    gravity_m_s2: tuple[float, float, float] | FloatArray = GRAVITY_M_S2,
) -> ArmRobot:
    """Build an :class:`ArmRobot` from URDF text; ``source`` names it in error messages (see :func:`load_arm`)."""
    root = parse_urdf_root(text, source)
    _check_joints(root, source)
    model = build_pinocchio_model(text, source)
    n = model.njoints - 1
    if n < 1:
        raise SpaceIdInputError(f"{source}: no revolute joint found; expected a serial arm with at least one")
    for k in range(1, model.njoints):
        if model.parents[k] != k - 1:
            raise SpaceIdInputError(
                f"{source}: joint '{model.names[k]}' hangs from '{model.names[model.parents[k]]}', not from the previous "
                f"joint '{model.names[k - 1]}': the moving joints branch; expected a serial chain"
            )
    gravity = _vector(gravity_m_s2, 3, f"{source}: gravity_m_s2")
    model.gravity = pin.Motion(gravity, np.zeros(3))

    joint_names = tuple(model.names[k] for k in range(1, model.njoints))
    link_names = tuple(_child_links(root)[name] for name in joint_names)
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    rate = np.array(model.velocityLimit, dtype=float)
    effort = np.array(model.effortLimit, dtype=float)
    for name, v, e, lo, hi in zip(joint_names, rate, effort, lower, upper, strict=True):
        if not (np.isfinite(v) and v > 0 and np.isfinite(e) and e > 0):
            raise SpaceIdInputError(f"{source}: joint '{name}' needs <limit> with velocity > 0 and effort > 0 (got {v:g}, {e:g})")
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise SpaceIdInputError(f"{source}: joint '{name}' needs finite limits lower < upper (got {lo:g}, {hi:g})")
    for k in range(1, model.njoints):
        mass = float(model.inertias[k].mass)
        if not (np.isfinite(mass) and mass >= 0):
            raise SpaceIdInputError(f"{source}: body moved by joint '{model.names[k]}' has mass {mass!r}; expected >= 0 kg")
    ddq_default = DEFAULT_DDQ_LIMIT_RAD_S2 if ddq_limit_rad_s2 is None else ddq_limit_rad_s2
    ddq_limit = np.broadcast_to(np.asarray(ddq_default, dtype=float), (n,)).copy()
    if not (np.isfinite(ddq_limit).all() and (ddq_limit > 0).all()):
        raise SpaceIdInputError(f"{source}: ddq_limit_rad_s2 must be finite and > 0, got {ddq_default!r}")
    arrays = [lower, upper, rate, ddq_limit, effort, gravity]
    for array in arrays:
        array.flags.writeable = False
    return ArmRobot(
        name=root.get("name", "arm"),
        source=source,
        urdf_text=text,
        model=model,
        joint_names=joint_names,
        link_names=link_names,
        q_lower_rad=lower,
        q_upper_rad=upper,
        dq_limit_rad_s=rate,
        ddq_limit_rad_s2=ddq_limit,
        torque_limit_Nm=effort,
        gravity_m_s2=gravity,
    )


def _vector(value: object, size: int, what: str) -> FloatArray:
    try:
        array = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        array = np.empty(0)
    if array.shape != (size,) or not np.isfinite(array).all():
        raise SpaceIdInputError(f"{what} must be {size} finite numbers, got {value!r}")
    return array


def _child_links(root: ET.Element) -> dict[str, str]:
    """URDF joint name -> child link name."""
    out: dict[str, str] = {}
    for joint in root.iter("joint"):
        child = joint.find("child")
        out[str(joint.get("name"))] = "" if child is None else str(child.get("link", ""))
    return out


def _check_joints(root: ET.Element, source: str) -> None:
    """Joint types and limits, checked on the XML before pinocchio sees it (clearer messages)."""
    for joint in root.iter("joint"):
        name, jtype = joint.get("name"), joint.get("type")
        if jtype == "fixed":
            continue
        if jtype not in _MOVING_JOINT_TYPES:
            hint = _UNSUPPORTED_JOINT_HINTS.get(str(jtype), "supported joint types: revolute, fixed")
            raise SpaceIdInputError(f"{source}: joint '{name}' has type '{jtype}': {hint}")
        limit = joint.find("limit")
        missing = [key for key in ("lower", "upper", "velocity", "effort") if limit is None or limit.get(key) is None]
        if missing:
            raise SpaceIdInputError(
                f"{source}: joint '{name}' needs <limit> with lower, upper, velocity and effort (missing: {', '.join(missing)})"
            )
