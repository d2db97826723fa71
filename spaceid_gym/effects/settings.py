"""The truth settings of the hidden effects: what each effect is, its fields, frames and units, in one frozen dataclass.

Each effect exists twice in the project: here and in the simulator as *physics* (the truth), and
in the identification model as an optional term with its own unknowns (``estimators``, written
independently). This module holds the truth settings only, in one frozen dataclass,
:class:`HiddenEffects`, whose field names and conventions both sides share. Their default sizes and
random draws: :mod:`spaceid_gym.effects.draws`; the spec strings that name them:
:mod:`spaceid_gym.effects.spec_strings`.

Catalogue (field names, frames and units)
-----------------------------------------
* ``initial_momentum``: ``initial_momentum_Nms`` (3,), the system's angular momentum about the
  system CoM, **inertial** frame (the base attitude is identity at reset, so it equals the base
  frame at t = 0); the linear momentum stays zero.
* ``gyro_bias``: ``gyro_bias_rad_s`` (3,), base body frame: ``omega_meas = omega + bias``.
* ``gyro_scale``: ``gyro_scale_misalignment`` (3, 3), a matrix ``E``:
  ``omega_meas = (I + E) omega + bias`` (diagonal: scale-factor errors, off-diagonal: misalignment).
* ``payload``: ``payload_params10`` (10,), an object rigidly held by the last link: its inertial
  parameters about the last joint frame's origin, in that frame, pinocchio order
  ``[m, mc_x, mc_y, mc_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (inertia about the frame origin).
* ``slosh``: ``slosh_mass_kg``, ``slosh_frequency_hz``, ``slosh_damping_ratio``: an isotropic 3-D
  spring-mass-damper (a point mass) at the tank position (full-tank CoM + ``bf``, base frame). The
  slosh mass is part of the remaining liquid, taken out of the rigid base at the tank, so at rest
  the mass distribution is the rigid one. Spring ``k = m_s (2 pi f)^2``, damper
  ``c = 2 zeta m_s (2 pi f)``. A zero slosh mass (empty tank) adds no body. ``slosh_model`` chooses
  the equivalent mechanical model of the first lateral mode (Abramson, NASA SP-106, 1966, ch. 6):
  ``"spring"`` (the default, also when unset) is the spring-mass above; ``"pendulum"`` is the point
  mass on a massless rod of length ``slosh_length_m`` (default 0.3 m) hinged by a universal joint at
  ``tank point - L a``, ``a = slosh_axis`` (unit vector, base frame, default base +z), so that at
  rest the mass sits at the tank point as in the spring model. In free fall there is no gravity to
  pull the pendulum back; the settled liquid's restoring effect (a small residual acceleration,
  surface tension) is that of a pendulum under the effective acceleration ``g_eff = L (2 pi f)^2``
  along ``a`` (``f = sqrt(g_eff / L) / (2 pi)``): the potential ``m_s g_eff L (1 - cos phi)``, ``phi``
  the rod's angle from ``a``, at any angle, and the damper ``c`` on the mass's velocity relative to
  the base. For small angles its lateral force on the mass is the spring model's ``k``, ``c``; the
  two models differ beyond the small-angle limit (the pendulum's restoring force is ``k L sin phi``)
  and in the rod: the pendulum mass cannot move along ``a``. ``slosh_length_m`` and ``slosh_axis``
  are only for the pendulum (they default when it is chosen, so truth.json always holds them).
* ``delay``: ``delay_s`` >= 0: the gyro stream lags the encoders, ``omega_meas(t_k) = omega(t_k - delay_s)``
  (any real delay, not only whole samples).
* ``external_torque``: ``external_torque_Nm`` (3,) constant torque and ``external_torque_rate_Nm_s``
  (3,) its linear drift, inertial frame: ``L(t) = L0 + tau0 t + tau1 t^2 / 2``; a pure torque (the
  linear momentum is unchanged). Either may be omitted (zero).

Stored reaction-wheel momentum is fixed in the *base* frame; over a window whose base rotation is
small it acts like ``initial_momentum`` (fixed in the inertial frame), which is the model used here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import RigidBodyInertia

#: the catalogue's effect names (``gyro_scale``, the scale-factor/misalignment variant of ``gyro_bias``, last)
EFFECT_NAMES = ("initial_momentum", "gyro_bias", "payload", "slosh", "delay", "external_torque", "gyro_scale")

#: the :class:`HiddenEffects` fields of each effect
EFFECT_FIELDS: dict[str, tuple[str, ...]] = {
    "initial_momentum": ("initial_momentum_Nms",),
    "gyro_bias": ("gyro_bias_rad_s",),
    "payload": ("payload_params10",),
    "slosh": ("slosh_mass_kg", "slosh_frequency_hz", "slosh_damping_ratio", "slosh_model", "slosh_length_m", "slosh_axis"),
    "delay": ("delay_s",),
    "external_torque": ("external_torque_Nm", "external_torque_rate_Nm_s"),
    "gyro_scale": ("gyro_scale_misalignment",),
}

#: the equivalent mechanical models of the first lateral slosh mode (``slosh_model``; unset means the first)
SLOSH_MODELS = ("spring", "pendulum")
#: the pendulum's default rod length, m
SLOSH_PENDULUM_LENGTH_M = 0.3
#: the pendulum's default axis (hinge to mass at rest), base frame: the base +z axis
SLOSH_PENDULUM_AXIS = (0.0, 0.0, 1.0)
#: accepted slosh frequencies ``(0, max]`` (Hz) and damping ratios ``[0, max)``
SLOSH_MAX_FREQUENCY_HZ = 5.0
SLOSH_MAX_DAMPING_RATIO = 2.0
#: how far from 1 the norm of ``slosh_axis`` may be
SLOSH_AXIS_NORM_TOLERANCE = 1e-9

#: field name -> shape (``()`` for scalars)
FIELD_SHAPES: dict[str, tuple[int, ...]] = {
    "initial_momentum_Nms": (3,),
    "gyro_bias_rad_s": (3,),
    "gyro_scale_misalignment": (3, 3),
    "payload_params10": (10,),
    "slosh_mass_kg": (),
    "slosh_frequency_hz": (),
    "slosh_damping_ratio": (),
    "slosh_length_m": (),
    "slosh_axis": (3,),
    "delay_s": (),
    "external_torque_Nm": (3,),
    "external_torque_rate_Nm_s": (3,),
}


@dataclass(frozen=True)
class HiddenEffects:
    """Truth settings of the hidden effects; ``None`` means the effect is absent.

    Vectors are stored as tuples of floats, the matrix as a tuple of row tuples (hashable, JSON-able);
    the constructor accepts any array-like and validates shapes and values. Conventions: see the
    module docstring.

    Attributes:
        initial_momentum_Nms: (3,) system angular momentum about the system CoM, inertial frame, N m s.
        gyro_bias_rad_s: (3,) gyro bias, base body frame, rad/s.
        gyro_scale_misalignment: (3, 3) ``E`` in ``omega_meas = (I + E) omega + bias``.
        payload_params10: (10,) payload inertial parameters about the last joint frame's origin, in that frame.
        slosh_mass_kg, slosh_frequency_hz, slosh_damping_ratio: slosh mass (>= 0), natural frequency
            (in (0, 5] Hz) and damping ratio (in [0, 2)); all three or none.
        slosh_model: ``"spring"`` or ``"pendulum"`` (:data:`SLOSH_MODELS`); ``None`` (unset) is the spring.
        slosh_length_m: the pendulum's rod length (> 0, m); pendulum only (default 0.3 m).
        slosh_axis: (3,) unit vector from the hinge to the mass at rest, base frame; pendulum only
            (default the base +z axis).
        delay_s: gyro delay behind the encoders, s, >= 0.
        external_torque_Nm: (3,) constant external torque, inertial frame, N m.
        external_torque_rate_Nm_s: (3,) its linear drift, inertial frame, N m/s.
    """

    initial_momentum_Nms: tuple[float, ...] | None = None
    gyro_bias_rad_s: tuple[float, ...] | None = None
    gyro_scale_misalignment: tuple[tuple[float, ...], ...] | None = None
    payload_params10: tuple[float, ...] | None = None
    slosh_mass_kg: float | None = None
    slosh_frequency_hz: float | None = None
    slosh_damping_ratio: float | None = None
    slosh_model: str | None = None
    slosh_length_m: float | None = None
    slosh_axis: tuple[float, ...] | None = None
    delay_s: float | None = None
    external_torque_Nm: tuple[float, ...] | None = None
    external_torque_rate_Nm_s: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        for name, shape in FIELD_SHAPES.items():
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _checked(name, value, shape))
        self._check_slosh()
        if self.delay_s is not None:
            _require("delay_s", self.delay_s, self.delay_s >= 0.0, ">= 0 s")
        if self.payload_params10 is not None:
            mass = self.payload_params10[0]
            _require("payload_params10", self.payload_params10, mass > 0.0, "a mass (first entry) > 0 kg")
            RigidBodyInertia.from_params10(np.array(self.payload_params10)).validate("hidden effect 'payload' (payload_params10)")

    def _check_slosh(self) -> None:
        """Validate the slosh fields; a pendulum gets its default rod length and axis when they are unset."""
        unset = [getattr(self, f) is None for f in _SLOSH_REQUIRED]
        if any(unset) and not all(unset):
            raise SpaceIdInputError(
                "hidden effect 'slosh': expected slosh_mass_kg, slosh_frequency_hz and slosh_damping_ratio together"
            )
        if all(unset):
            given = [f for f in EFFECT_FIELDS["slosh"] if getattr(self, f) is not None]
            if given:
                raise SpaceIdInputError(
                    f"hidden effect 'slosh': {', '.join(given)} given without slosh_mass_kg, slosh_frequency_hz and "
                    "slosh_damping_ratio"
                )
            return
        frequency, damping = float(self.slosh_frequency_hz or 0.0), float(self.slosh_damping_ratio or 0.0)
        _require("slosh_mass_kg", self.slosh_mass_kg, float(self.slosh_mass_kg or 0.0) >= 0.0, ">= 0 kg")
        _require(
            "slosh_frequency_hz",
            self.slosh_frequency_hz,
            0.0 < frequency <= SLOSH_MAX_FREQUENCY_HZ,
            f"> 0 and <= {SLOSH_MAX_FREQUENCY_HZ:g} Hz",
        )
        _require(
            "slosh_damping_ratio",
            self.slosh_damping_ratio,
            0.0 <= damping < SLOSH_MAX_DAMPING_RATIO,
            f">= 0 and < {SLOSH_MAX_DAMPING_RATIO:g}",
        )
        model = self.slosh_model
        _require(
            "slosh_model",
            model,
            model is None or (isinstance(model, str) and model in SLOSH_MODELS),
            f"one of {', '.join(map(repr, SLOSH_MODELS))}",
        )
        if model != "pendulum":
            for field in ("slosh_length_m", "slosh_axis"):
                _require(field, getattr(self, field), getattr(self, field) is None, "no value unless slosh_model is 'pendulum'")
            return
        if self.slosh_length_m is None:
            object.__setattr__(self, "slosh_length_m", SLOSH_PENDULUM_LENGTH_M)
        if self.slosh_axis is None:
            object.__setattr__(self, "slosh_axis", SLOSH_PENDULUM_AXIS)
        _require("slosh_length_m", self.slosh_length_m, float(self.slosh_length_m or 0.0) > 0.0, "> 0 m")
        norm = float(np.linalg.norm(self.slosh_axis))
        _require(
            "slosh_axis",
            self.slosh_axis,
            abs(norm - 1.0) <= SLOSH_AXIS_NORM_TOLERANCE,
            f"a unit vector (base frame; norm 1 within {SLOSH_AXIS_NORM_TOLERANCE:g}, this one {norm:.12g})",
        )

    # ------------------------------------------------------------------ views
    @property
    def names(self) -> tuple[str, ...]:
        """The active effects, in :data:`EFFECT_NAMES` order."""
        return tuple(name for name in EFFECT_NAMES if any(getattr(self, f) is not None for f in EFFECT_FIELDS[name]))

    def __bool__(self) -> bool:
        """True when any effect is set."""
        return bool(self.names)

    def array(self, field: str) -> FloatArray | None:
        """The field ``field`` as a float array (its documented shape), or ``None`` if unset."""
        value = getattr(self, field)
        return None if value is None else np.array(value, dtype=float)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """The set fields as plain JSON values (lists, floats and the word ``slosh_model``); the ``hidden_effects`` of truth.json."""
        out: dict[str, Any] = {}
        for field in _FIELDS:
            value = getattr(self, field)
            if field == "gyro_scale_misalignment" and value is not None:
                out[field] = [list(row) for row in value]
            elif value is not None:
                out[field] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "hidden_effects") -> HiddenEffects:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`SpaceIdInputError` naming ``where``."""
        if not isinstance(data, dict):
            raise SpaceIdInputError(f"{where}: expected an object of effect fields, got {type(data).__name__}")
        unknown = sorted(set(data) - set(_FIELDS))
        if unknown:
            raise SpaceIdInputError(f"{where}: unknown keys {unknown}; expected some of {', '.join(_FIELDS)}")
        return cls(**data)

    def combine(self, other: HiddenEffects) -> HiddenEffects:
        """Both sets of effects together; an effect set in both raises :class:`SpaceIdInputError`."""
        both = sorted(set(self.names) & set(other.names), key=EFFECT_NAMES.index)
        if both:
            raise SpaceIdInputError(f"hidden effects: {', '.join(both)} set twice; give each effect once")
        changes = {f: getattr(other, f) for name in other.names for f in EFFECT_FIELDS[name]}
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ derived physics
    def slosh_stiffness_damping(self) -> tuple[float, float]:
        """Spring ``k = m (2 pi f)^2`` (N/m) and damper ``c = 2 zeta m (2 pi f)`` (N s/m) of the slosh mass.

        For the pendulum these are the lateral stiffness and damping at the mass for small angles: the effective
        acceleration along its rest axis is ``k L / m`` (:meth:`spaceid_gym.sim.slosh.SloshBody.joint_force`).
        """
        if self.slosh_mass_kg is None:
            raise SpaceIdInputError("hidden effect 'slosh' is not set")
        omega = 2.0 * math.pi * float(self.slosh_frequency_hz or 0.0)
        mass = float(self.slosh_mass_kg)
        return mass * omega * omega, 2.0 * float(self.slosh_damping_ratio or 0.0) * mass * omega

    def momentum_world(self) -> FloatArray:
        """System momentum ``[P; L]`` at t = 0 (6,), about the system CoM (the inertial origin at reset)."""
        out = np.zeros(6)
        if self.initial_momentum_Nms is not None:
            out[3:] = self.initial_momentum_Nms
        return out


def _checked(name: str, value: Any, shape: tuple[int, ...]) -> Any:
    """``value`` as a float or (nested) tuple of floats of ``shape``; raises naming the field otherwise."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != shape or not np.all(np.isfinite(array)):
        what = "a finite number" if not shape else f"{'x'.join(map(str, shape))} finite numbers"
        raise SpaceIdInputError(f"hidden effect field '{name}': expected {what}, got {value!r}")
    if not shape:
        return float(array)
    if len(shape) == 1:
        return tuple(float(x) for x in array)
    return tuple(tuple(float(x) for x in row) for row in array)


#: every :class:`HiddenEffects` field, in declaration order
_FIELDS = tuple(f.name for f in dataclasses.fields(HiddenEffects))
#: the slosh fields that come together (the others are optional)
_SLOSH_REQUIRED = EFFECT_FIELDS["slosh"][:3]


def _require(name: str, value: Any, ok: bool, expected: str) -> None:
    if not ok:
        raise SpaceIdInputError(f"hidden effect field '{name}': expected {expected}, got {value!r}")
