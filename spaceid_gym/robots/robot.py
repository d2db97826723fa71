"""Load and validate a free-floating robot from URDF (pinocchio model with a free-flyer root).

Frames and units
----------------
* The **base frame** is the URDF root link's frame. Base velocities are pinocchio "local":
  ``[v_lin; omega]`` of the base origin, both in the base frame (m/s, rad/s).
* Joint angles in rad, joint rates in rad/s, torques in N m, masses in kg, lengths in m.
* pinocchio's configuration is ``[p_world (3), quat (x, y, z, w) (4), q_arm (n)]``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia

_SUPPORTED_JOINTS = {"revolute", "fixed"}


def available_robots() -> list[str]:
    """Names of the robots shipped with the package (``orbit7``, ``paper6``, ``quick3``), sorted."""
    files = resources.files("spaceid_gym.robots")
    return sorted(p.name[: -len(".urdf")] for p in files.iterdir() if p.name.endswith(".urdf"))


@dataclass
class Robot:
    """A free-floating robot: pinocchio model (free-flyer root), limits and the full-tank base.

    Attributes:
        name: robot name (URDF ``<robot name>``).
        urdf_text: the URDF source, as given (written to dataset folders unchanged).
        model: pinocchio model with a free-flyer root joint and zero gravity (orbital free fall);
            ``model.inertias[1]`` is the base
            (the root link plus any links fixed to it) with a full tank.
        joint_names: the n arm joints, in configuration order.
        q_lower_rad, q_upper_rad: joint position limits, shape (n,).
        rate_limit_rad_s: joint rate limits, shape (n,).
        torque_limit_nm: joint torque limits, shape (n,).
        base_full: full-tank base mass properties in the base frame.
    """

    name: str
    urdf_text: str
    model: pin.Model
    joint_names: list[str]
    q_lower_rad: FloatArray
    q_upper_rad: FloatArray
    rate_limit_rad_s: FloatArray
    torque_limit_nm: FloatArray
    base_full: RigidBodyInertia
    source: str = field(default="")

    @property
    def n_joints(self) -> int:
        """Number of arm joints n."""
        return len(self.joint_names)

    def home_configuration(self) -> FloatArray:
        """A default arm configuration, shape (n,): the middle of each joint's range."""
        return 0.5 * (self.q_lower_rad + self.q_upper_rad)

    def model_with_base(self, base: RigidBodyInertia) -> pin.Model:
        """A copy of :attr:`model` whose base (body 1) has the given mass properties."""
        model = pin.Model(self.model)
        model.inertias[1] = pin.Inertia(base.mass_kg, np.asarray(base.com_m, float), np.asarray(base.inertia_com_kgm2, float))
        return model

    def with_payload(self, payload: RigidBodyInertia) -> Robot:
        """The same robot holding ``payload`` rigidly on its last link (mass properties in that link's frame).

        Only the dynamics change (the last body's inertia grows); ``urdf_text`` stays the robot as
        described, without the payload, as an estimator would be given it.
        """
        payload.validate("payload")
        model = pin.Model(self.model)
        last = model.njoints - 1
        model.inertias[last] = model.inertias[last] + pin.Inertia(
            payload.mass_kg, np.asarray(payload.com_m, float), np.asarray(payload.inertia_com_kgm2, float)
        )
        return replace(self, model=model)

    def arm_mass_kg(self) -> float:
        """Total mass of the arm links (everything but the base), kg."""
        return float(sum(self.model.inertias[i].mass for i in range(2, self.model.njoints)))


def load_robot(spec: str | Path) -> Robot:
    """Load a shipped robot by name (see :func:`available_robots`) or a URDF file by path.

    Shipped robots (each URDF's header comment gives its full design):

    * ``paper6``: the source paper's robot, a 550 kg base (full tank) and a 6-joint arm of 60 kg
      with axes along its links' x, y or z axes.
    * ``quick3``: a 120 kg base and a 3-joint arm of 10 kg, for fast tests and examples.
    * ``orbit7``: a different satellite, an 820 kg base (full tank; box 2.2 x 1.9 x 2.4 m, CoM
      (-0.054, 0.025, -0.066) m, principal moments 459, 533, 605 kg m^2) whose 215 kg propellant
      tank (205 kg usable) sits at bf = (-0.266, 0.155, -0.354) m from the full-tank CoM, and a
      7-joint arm of 79 kg (links of 5-19 kg) whose joint axes are tilted 12-28 deg off their
      parent link's axes: consecutive axes are 52-74 deg apart, none parallel or orthogonal.

    The tank position and the fuel consumed are not part of a robot: they are the fuel model's
    unknowns (:mod:`spaceid_gym.physics.fuel`), drawn per satellite by
    :class:`~spaceid_gym.mission.FuelSchedule` (usable fuel 25 % of the wet base mass) unless given.

    Raises:
        SpaceIdInputError: unknown name, missing file, malformed XML, a link without
            ``<inertial>``, a non-physical inertia, an unsupported joint type, missing limits.
    """
    spec_str = str(spec)
    if spec_str in available_robots():
        text = resources.files("spaceid_gym.robots").joinpath(f"{spec_str}.urdf").read_text()
        source = f"{spec_str} (shipped)"
    else:
        path = Path(spec_str)
        if not path.is_file():
            raise SpaceIdInputError(
                f"robot '{spec_str}': not a shipped robot ({', '.join(available_robots())}) and no such URDF file"
            )
        text = path.read_text()
        source = str(path)
    return robot_from_urdf_text(text, source)


def parse_urdf_root(text: str, source: str) -> ET.Element:
    """The ``<robot>`` element of URDF text; a clear error naming ``source`` if it is not URDF XML."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise SpaceIdInputError(f"{source}: not valid URDF XML ({exc})") from None
    if root.tag != "robot":
        raise SpaceIdInputError(f"{source}: the root element is <{root.tag}>, expected <robot>")
    return root


def build_pinocchio_model(text: str, source: str, root_joint: pin.JointModel | None = None) -> pin.Model:
    """pinocchio's model of URDF text (with ``root_joint`` if given); the parser's refusal becomes a clear error."""
    try:
        return pin.buildModelFromXML(text) if root_joint is None else pin.buildModelFromXML(text, root_joint)
    except (ValueError, RuntimeError) as exc:
        raise SpaceIdInputError(f"{source}: the URDF parser rejected it ({exc})") from None


def robot_from_urdf_text(text: str, source: str = "<string>") -> Robot:
    """Build a :class:`Robot` from URDF text; ``source`` names it in error messages."""
    root = parse_urdf_root(text, source)
    _check_links_and_joints(root, source)
    model = build_pinocchio_model(text, source, pin.JointModelFreeFlyer())
    model.gravity = pin.Motion.Zero()  # orbital free fall: no gravity in the orbiting frame
    if model.njoints < 3:
        raise SpaceIdInputError(f"{source}: no movable joint found; expected an arm with at least one revolute joint")
    names = [model.names[i] for i in range(2, model.njoints)]
    idx_q = [model.joints[i].idx_q for i in range(2, model.njoints)]
    lower = np.array(model.lowerPositionLimit[idx_q], dtype=float)
    upper = np.array(model.upperPositionLimit[idx_q], dtype=float)
    idx_v = [model.joints[i].idx_v for i in range(2, model.njoints)]
    rate = np.array(model.velocityLimit[idx_v], dtype=float)
    effort = np.array(model.effortLimit[idx_v], dtype=float)
    for name, v, e, lo, hi in zip(names, rate, effort, lower, upper, strict=True):
        if not (v > 0 and np.isfinite(v) and e > 0 and np.isfinite(e)):
            raise SpaceIdInputError(f"{source}: joint '{name}' needs <limit> with velocity > 0 and effort > 0")
        if not lo < hi:
            raise SpaceIdInputError(f"{source}: joint '{name}' has lower limit {lo:g} >= upper limit {hi:g}")
    base = model.inertias[1]
    base_full = RigidBodyInertia(float(base.mass), np.array(base.lever), np.array(base.inertia)).validate(
        f"{source}: base (root link) inertial"
    )
    for i in range(2, model.njoints):
        inertia = model.inertias[i]
        RigidBodyInertia(float(inertia.mass), np.array(inertia.lever), np.array(inertia.inertia)).validate(
            f"{source}: link moved by joint '{model.names[i]}'"
        )
    return Robot(
        name=root.get("name", "robot"),
        urdf_text=text,
        model=model,
        joint_names=names,
        q_lower_rad=lower,
        q_upper_rad=upper,
        rate_limit_rad_s=rate,
        torque_limit_nm=effort,
        base_full=base_full,
        source=source,
    )


def _check_links_and_joints(root: ET.Element, source: str) -> None:
    """Checks pinocchio does not make: every link has a mass, every joint type is supported."""
    for joint in root.iter("joint"):
        jtype = joint.get("type")
        if jtype not in _SUPPORTED_JOINTS:
            raise SpaceIdInputError(f"{source}: joint '{joint.get('name')}' has type '{jtype}'; supported: revolute, fixed")
        axis = joint.find("axis")
        if jtype == "revolute" and axis is not None:
            try:
                values = [float(x) for x in axis.get("xyz", "1 0 0").split()]
            except ValueError:
                values = []
            if len(values) != 3 or not any(values):
                raise SpaceIdInputError(
                    f"{source}: joint '{joint.get('name')}' has axis {axis.get('xyz')!r}; expected a non-zero 3-vector"
                )
        if jtype == "revolute" and joint.find("limit") is None:
            raise SpaceIdInputError(f"{source}: joint '{joint.get('name')}' needs <limit> with lower, upper, velocity and effort")
    for link in root.iter("link"):
        inertial = link.find("inertial")
        mass = None if inertial is None else inertial.find("mass")
        if inertial is None or mass is None or inertial.find("inertia") is None:
            raise SpaceIdInputError(
                f"{source}: link '{link.get('name')}' has no <inertial> with <mass> and <inertia>; "
                "every link needs mass properties"
            )
        try:
            value = float(mass.get("value", "nan"))
        except ValueError:
            value = float("nan")
        if not value > 0:
            raise SpaceIdInputError(f"{source}: link '{link.get('name')}' has mass {mass.get('value')!r}; expected > 0 kg")
