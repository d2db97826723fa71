"""The fixed-base arm's joint sensors: encoders, joint rates and motor current, with white noise.

White Gaussian noise from the generator passed in, defaults an ASSUMPTION of the order the real
UR5 logs (``shared/data/ur5-real``, movements No5 and No8) show: a robust per-sample noise estimate
(median absolute third difference / 0.6745 / sqrt(20), which removes smooth motion) gives
1e-5 - 1e-4 rad on ``q_actual`` (printed to 1e-6 rad), 1e-3 - 4e-2 rad/s on ``qd_actual`` and
0.03 - 0.25 A on ``i_actual``. Defaults: encoders 1e-5 rad, joint rates 2e-3 rad/s (about an
encoder difference at 125 Hz: sqrt(2) 1e-5 rad * 125 Hz = 1.8e-3 rad/s), current 0.07 A per joint,
i.e. torque noise ``0.07 A * k_t`` = 0.53, 0.48, 0.50, 0.20, 0.22, 0.24 N m with the UR5's
approximate torque constants :data:`~spaceid_gym.arm.real_logs.UR5_TORQUE_CONSTANTS_NM_A`.
The effort is logged as torque ``u`` (N m) or current ``u / k_t`` (A).

Units: rad, rad/s, N m, A.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spaceid_gym.arm.joint_log import EFFORT_KINDS
from spaceid_gym.arm.real_logs import UR5_TORQUE_CONSTANTS_NM_A
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


@dataclass(frozen=True)
class ArmSensorModel:
    """White measurement noise of the joint sensors (defaults and their basis: module docstring).

    Attributes:
        q_std_rad: joint-angle (encoder) noise std, rad.
        dq_std_rad_s: joint-rate noise std, rad/s.
        current_std_A: motor-current noise std, A, one value or one per joint.
        effort_kind: what the log holds, ``"torque_Nm"`` (``u``) or ``"current_A"`` (``u / k_t``).
        torque_constants_Nm_A: ``k_t`` per joint (torque per current, gear included), N m/A; default
            the UR5's approximate values. The torque noise std is ``current_std_A * k_t`` in both kinds.
    """

    q_std_rad: float = 1e-5
    dq_std_rad_s: float = 2e-3
    current_std_A: float | tuple[float, ...] = 0.07
    effort_kind: str = "torque_Nm"
    torque_constants_Nm_A: tuple[float, ...] = UR5_TORQUE_CONSTANTS_NM_A

    def __post_init__(self) -> None:
        for name in ("q_std_rad", "dq_std_rad_s", "current_std_A"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim > 1 or not (np.isfinite(value).all() and (value >= 0).all()):
                raise SpaceIdInputError(f"sensors: {name} must be finite and >= 0, got {getattr(self, name)!r}")
        if self.effort_kind not in EFFORT_KINDS:
            raise SpaceIdInputError(f"sensors: effort_kind must be one of {sorted(EFFORT_KINDS)}, got {self.effort_kind!r}")
        k_t = np.asarray(self.torque_constants_Nm_A, dtype=float)
        if k_t.ndim != 1 or not (np.isfinite(k_t).all() and (k_t > 0).all()):
            raise SpaceIdInputError(
                f"sensors: torque_constants_Nm_A must be positive numbers, got {self.torque_constants_Nm_A!r}"
            )

    @classmethod
    def noise_free(cls, effort_kind: str = "torque_Nm", torque_constants_Nm_A: Sequence[float] | None = None) -> ArmSensorModel:
        """Exact measurements (the torque constants still convert torque to current)."""
        k_t = UR5_TORQUE_CONSTANTS_NM_A if torque_constants_Nm_A is None else tuple(float(k) for k in torque_constants_Nm_A)
        return cls(q_std_rad=0.0, dq_std_rad_s=0.0, current_std_A=0.0, effort_kind=effort_kind, torque_constants_Nm_A=k_t)

    @classmethod
    def coerce(cls, sensors: ArmSensorModel | str | None) -> ArmSensorModel:
        """``sensors`` as a model: ``None`` gives the defaults, ``"noise_free"`` :meth:`noise_free`, a model itself."""
        if sensors is None:
            return cls()
        if isinstance(sensors, ArmSensorModel):
            return sensors
        if sensors == "noise_free":
            return cls.noise_free()
        raise SpaceIdInputError(f"sensors: expected an ArmSensorModel, None or 'noise_free', got {sensors!r}")

    def check(self, n_joints: int) -> None:
        """Raise if the per-joint settings do not have ``n_joints`` entries."""
        if len(self.torque_constants_Nm_A) != n_joints:
            raise SpaceIdInputError(
                f"sensors: torque_constants_Nm_A has {len(self.torque_constants_Nm_A)} values, the robot {n_joints} joints"
            )
        if np.ndim(self.current_std_A) == 1 and len(self.current_std_A) != n_joints:  # type: ignore[arg-type]
            raise SpaceIdInputError(f"sensors: current_std_A has {len(self.current_std_A)} values, the robot {n_joints} joints")  # type: ignore[arg-type]

    @property
    def k_t(self) -> FloatArray:
        """Torque constants, shape (n,), N m/A."""
        return np.asarray(self.torque_constants_Nm_A, dtype=float)

    def torque_std_Nm(self) -> FloatArray:
        """Torque-equivalent noise std per joint, ``current_std_A * k_t``, shape (n,), N m."""
        return np.asarray(self.current_std_A, dtype=float) * self.k_t

    def effort_std(self) -> FloatArray:
        """Noise std of the logged effort per joint (N m or A, see ``effort_kind``), shape (n,)."""
        return self.torque_std_Nm() if self.effort_kind == "torque_Nm" else np.broadcast_to(self.current_std_A, self.k_t.shape)

    def effort_from_torque(self, tau_Nm: FloatArray) -> FloatArray:
        """The noise-free effort for motor torques of shape (..., n): the torque, or the current ``tau / k_t``."""
        return np.asarray(tau_Nm, dtype=float) if self.effort_kind == "torque_Nm" else np.asarray(tau_Nm) / self.k_t

    def measure(
        self, q_rad: FloatArray, dq_rad_s: FloatArray, tau_Nm: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Measured ``(q, dq, effort)`` for true values of shape (..., n); one draw of shape (..., 3, n) from ``rng``."""
        q = np.asarray(q_rad, dtype=float)
        noise = rng.standard_normal((*q.shape[:-1], 3, q.shape[-1]))
        return (
            q + self.q_std_rad * noise[..., 0, :],
            np.asarray(dq_rad_s, dtype=float) + self.dq_std_rad_s * noise[..., 1, :],
            self.effort_from_torque(tau_Nm) + self.effort_std() * noise[..., 2, :],
        )

    def as_dict(self) -> dict[str, Any]:
        """The settings for ``truth.json`` (torque std derived)."""
        return {
            "q_std_rad": float(self.q_std_rad),
            "dq_std_rad_s": float(self.dq_std_rad_s),
            "current_std_A": np.broadcast_to(np.asarray(self.current_std_A, dtype=float), self.k_t.shape).tolist(),
            "torque_std_Nm": np.broadcast_to(self.torque_std_Nm(), self.k_t.shape).tolist(),
            "effort_kind": self.effort_kind,
            "torque_constants_Nm_A": list(self.torque_constants_Nm_A),
        }
