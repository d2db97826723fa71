"""Fixed-base manipulators (the UR5 and any fixed-base serial-arm URDF): model, linear dynamics, logs.

* :func:`load_arm` / :class:`ArmRobot` (:mod:`.arm_robot`): the robot, its limits and gravity.
* :class:`ArmRegressor` (:mod:`.regressor`): ``tau = Y(q, dq, ddq) p`` with per-link inertial
  parameters and per-joint friction (:class:`FrictionModel`, :mod:`.friction`);
  :class:`BaseParameterSet`: the identifiable combinations ``beta = K p``; :func:`stack`.
* :class:`ArmLog` (:mod:`.joint_log`): a joint log (torque or current) and its CSV file.
* :func:`load_ur5_movement`, :func:`list_movements` (:mod:`.real_logs`): the real UR5 logs.
* :func:`prepare_for_identification` and its parts (:mod:`.signal`): filter, differentiate,
  resample, decimate.

Typical use::

    robot = load_arm("ur5")
    log, report = load_ur5_movement(".../ur5-real/Movement_No8_Singularity_Free_1")
    log = prepare_for_identification(log, cutoff_hz=5.0, decimate_factor=5)
    model = ArmRegressor(robot, friction=("coulomb", "viscous"))
    W, y = stack(model.regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2), log.effort)
    base = BaseParameterSet.from_regressor(model, np.random.default_rng(0))
    W_b = base.base_regressor(W)  # (T n, r): solve W_b beta = y
"""

from __future__ import annotations

from spaceid_gym.arm.arm_robot import DEFAULT_DDQ_LIMIT_RAD_S2, ArmRobot, arm_from_urdf_text, available_arms, load_arm
from spaceid_gym.arm.friction import FRICTION_TERMS, FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.real_logs import UR5_TORQUE_CONSTANTS_NM_A, LoadReport, list_movements, load_ur5_movement
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet, stack
from spaceid_gym.arm.signal import decimate, differentiate, lowpass_zero_phase, prepare_for_identification, resample_uniform

__all__ = [
    "DEFAULT_DDQ_LIMIT_RAD_S2",
    "FRICTION_TERMS",
    "UR5_TORQUE_CONSTANTS_NM_A",
    "ArmLog",
    "ArmRegressor",
    "ArmRobot",
    "BaseParameterSet",
    "FrictionModel",
    "LoadReport",
    "arm_from_urdf_text",
    "available_arms",
    "decimate",
    "differentiate",
    "list_movements",
    "load_arm",
    "load_ur5_movement",
    "lowpass_zero_phase",
    "prepare_for_identification",
    "resample_uniform",
    "stack",
]
