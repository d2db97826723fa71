"""Hidden physical effects: the truth-side settings of effects the nominal model leaves out.

Each effect exists twice in the project: here and in the simulator as *physics* (the truth), and
in the identification model as an optional term with its own unknowns (``estimators``, written
independently). This module holds the truth settings only, in one frozen dataclass,
:class:`HiddenEffects`, whose field names and conventions both sides share.

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
  surface tension) is a torsional spring-damper on each hinge angle,
  ``k_theta = m_s L^2 (2 pi f)^2`` (N m/rad), ``c_theta = 2 zeta m_s L^2 (2 pi f)`` (N m s/rad): for
  small angles this is exactly a pendulum under the effective acceleration ``g_eff = L (2 pi f)^2``
  along ``a`` (``f = sqrt(g_eff / L) / (2 pi)``), and its lateral force on the mass is the spring
  model's ``k``, ``c``. The two models differ beyond the small-angle limit and in the rod: the
  pendulum mass cannot move along ``a``. ``slosh_length_m`` and ``slosh_axis`` are only for the
  pendulum (they default when it is chosen, so truth.json always holds them).
* ``delay``: ``delay_s`` >= 0: the gyro stream lags the encoders, ``omega_meas(t_k) = omega(t_k - delay_s)``
  (any real delay, not only whole samples).
* ``external_torque``: ``external_torque_Nm`` (3,) constant torque and ``external_torque_rate_Nm_s``
  (3,) its linear drift, inertial frame: ``L(t) = L0 + tau0 t + tau1 t^2 / 2``; a pure torque (the
  linear momentum is unchanged). Either may be omitted (zero).

Default magnitudes (:data:`DEFAULT_MAGNITUDES`) and their sources
-----------------------------------------------------------------
A draw (:func:`draw_effect`) has a fixed size, the default or ``magnitude``, and random directions
(uniform on the sphere) or orientations from the generator passed in. ``magnitude`` units:

================  ==========================  =============================================================
effect            magnitude (default)         source / reasoning
================  ==========================  =============================================================
initial_momentum  ``|L0|``, N m s (0.2)       residual base rates after detumbling / rate damping,
                                              0.01-0.05 deg/s, times the paper6 base inertia
                                              (principal moments 330-406 kg m^2): 0.06-0.35 N m s.
gyro_bias         ``|b|``, rad/s (10 deg/h    bias repeatability of an LN-200S-class fibre-optic gyro,
                  = 4.85e-5)                  1-10 deg/h (Northrop Grumman LN-200S datasheet); the
                                              upper end, as an on-orbit bias after switch-on.
gyro_scale        Frobenius norm of ``E``     FOG scale-factor stability ~100 ppm (LN-200-class
                  (1e-3)                      datasheets) plus an uncalibrated mounting misalignment of
                                              the gyro unit to the base of order 1 mrad (our assumption
                                              for a mechanical alignment tolerance of ~0.05 deg). A
                                              MEMS IMU of the STIM300 class (Safran Sensonor datasheet:
                                              scale factor accuracy 500 ppm, misalignment 1 mrad) is up
                                              to 2.6e-3 (500 ppm on the 3 diagonal entries, 1 mrad on
                                              the 6 others).
payload           mass, kg (10)               an orbital-replacement-unit-sized object of 5-20 kg: a
                                              uniform 0.3 x 0.2 x 0.2 m box, random orientation, CoM
                                              0.15 m from the last joint's origin in a random direction.
slosh             mass, kg (30 % of the       first lateral slosh mode's equivalent mass 20-40 % of the
                  remaining liquid)           liquid, frequency 0.2-0.5 Hz, damping ratio 0.02-0.1
                                              (Abramson, NASA SP-106, 1966; Dodge, "The New Dynamic
                                              Behavior of Liquids in Moving Containers", SwRI, 2000);
                                              defaults 30 %, 0.3 Hz, 0.05. The remaining liquid is the
                                              usable fuel (``FuelSchedule().usable_fraction`` of the
                                              full-tank base mass) minus the fuel consumed. Model: the
                                              spring-mass by default; :func:`draw_slosh` also draws the
                                              pendulum (Abramson, NASA SP-106, ch. 6; the other
                                              standard equivalent model of lateral slosh), default rod
                                              0.3 m (a 37 kg pendulum of 0.3 m with a period of about
                                              15 s is another simulator's case), and the period
                                              log-uniform over 2-50 s on request
                                              (:data:`SLOSH_PERIOD_RANGE_S`: the low frequencies of
                                              large, partly filled tanks under a small residual
                                              acceleration).
delay             s (0.02)                    sensor processing and data-bus latency between the gyro
                                              and the joint encoders, 10-40 ms; one sample at 50 Hz.
external_torque   ``|tau0|``, N m (5e-4)      gravity gradient in LEO, ``3 n^2 c x (I c)``, at most
                                              ``1.5 n^2 (I_max - I_min)``: 1.1e-3 N m for paper6 with the
                                              arm at home (n = 1.1e-3 rad/s, a 95 min orbit), a few 1e-4
                                              at typical attitudes; or a thruster leak (1 mN at 0.5 m).
                                              Drift ``|tau1| = 2 n |tau0|`` (1.1e-6 N m/s), random
                                              direction: the gravity-gradient torque of an inertially
                                              held body turns at twice the orbital rate.
================  ==========================  =============================================================

Stored reaction-wheel momentum is fixed in the *base* frame; over a window whose base rotation is
small it acts like ``initial_momentum`` (fixed in the inertial frame), which is the model used here.

Spec strings (:func:`parse_hidden_effects`, used by the env and ``spaceid simulate
--hidden-effects``): comma-separated effect names, each optionally followed by ``[key=value,...]``
with ``magnitude`` or the effect's field names; vector and matrix values separate their numbers with
``;`` (row-major for the 3x3 matrix), and ``slosh_model`` is a word, e.g.
``"slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"``,
``"external_torque[external_torque_Nm=1e-4;0;0,external_torque_rate_Nm_s=0;0;0]"`` or
``"slosh[slosh_model=pendulum,slosh_length_m=0.3,slosh_axis=0;0;1,slosh_frequency_hz=0.067,magnitude=37]"``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.robots.robot import Robot
from spaceid_gym.specs import parse_setting, split_outside_brackets

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

#: orbital rate of a 95 min low Earth orbit, rad/s (sets the gravity-gradient torque and its drift)
ORBITAL_RATE_RAD_S = 1.1e-3

#: default size of each effect in the unit of its ``magnitude`` (see the module docstring); slosh: fraction of the remaining liquid
DEFAULT_MAGNITUDES: dict[str, float] = {
    "initial_momentum": 0.2,
    "gyro_bias": math.radians(10.0) / 3600.0,
    "payload": 10.0,
    "slosh": 0.3,
    "delay": 0.02,
    "external_torque": 5e-4,
    "gyro_scale": 1e-3,
}

#: the unit of each effect's ``magnitude`` argument ("" for the dimensionless Frobenius norm of ``gyro_scale``; a
#: ``slosh`` magnitude is a mass, while its default is a fraction of the remaining liquid)
MAGNITUDE_UNITS: dict[str, str] = {
    "initial_momentum": "N m s",
    "gyro_bias": "rad/s",
    "payload": "kg",
    "slosh": "kg",
    "delay": "s",
    "external_torque": "N m",
    "gyro_scale": "",
}

SLOSH_FREQUENCY_HZ = 0.3
SLOSH_DAMPING_RATIO = 0.05
#: the equivalent mechanical models of the first lateral slosh mode (``slosh_model``; unset means the first)
SLOSH_MODELS = ("spring", "pendulum")
#: the pendulum's default rod length, m
SLOSH_PENDULUM_LENGTH_M = 0.3
#: the pendulum's default axis (hinge to mass at rest), base frame: the base +z axis
SLOSH_PENDULUM_AXIS = (0.0, 0.0, 1.0)
#: the slosh periods :func:`draw_slosh` draws from (log-uniform), s
SLOSH_PERIOD_RANGE_S = (2.0, 50.0)
#: accepted slosh frequencies ``(0, max]`` (Hz) and damping ratios ``[0, max)``
SLOSH_MAX_FREQUENCY_HZ = 5.0
SLOSH_MAX_DAMPING_RATIO = 2.0
#: how far from 1 the norm of ``slosh_axis`` may be
SLOSH_AXIS_NORM_TOLERANCE = 1e-9
PAYLOAD_BOX_M = (0.3, 0.2, 0.2)
PAYLOAD_DISTANCE_M = 0.15

#: field name -> shape (``()`` for scalars)
_SHAPES: dict[str, tuple[int, ...]] = {
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
        for name, shape in _SHAPES.items():
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

        For the pendulum these are the lateral stiffness and damping at the mass; its torsional spring-damper at
        the hinge is ``k L^2`` (N m/rad) and ``c L^2`` (N m s/rad).
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


# ---------------------------------------------------------------------- drawing defaults
def random_unit_vector(rng: np.random.Generator, size: int = 3) -> FloatArray:
    """A direction uniform on the unit sphere in R^size (normalised standard normal)."""
    v = rng.standard_normal(size)
    return v / np.linalg.norm(v)


def _random_rotation(rng: np.random.Generator) -> FloatArray:
    """A rotation matrix uniform on SO(3) (from a unit quaternion uniform on S^3)."""
    w, x, y, z = random_unit_vector(rng, 4)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def remaining_liquid_kg(robot: Robot, fuel_consumed_kg: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
    """Usable fuel still in the tank (kg): ``FuelSchedule().usable_fraction`` of the full-tank base mass minus the fuel
    consumed, at least 0; for one value (a float) or many (an array of the same shape)."""
    left = FuelSchedule().usable_fraction * robot.base_full.mass_kg - np.asarray(fuel_consumed_kg, dtype=float)
    return np.maximum(left, 0.0) if left.ndim else max(float(left), 0.0)


def draw_effect(
    name: str, rng: np.random.Generator, robot: Robot, fuel_consumed_kg: float, magnitude: float | None = None
) -> HiddenEffects:
    """One effect with a realistic default size (or ``magnitude``) and random directions.

    Args:
        name: one of :data:`EFFECT_NAMES`.
        rng: the seeded generator every random direction/orientation is drawn from.
        robot: the robot (its full-tank base mass sets the remaining liquid for ``slosh``).
        fuel_consumed_kg: fuel consumed so far (kg), for ``slosh``.
        magnitude: the effect's size in the unit given in the module docstring's table (``|L0|`` N m s,
            ``|b|`` rad/s, Frobenius norm of ``E``, payload kg, slosh kg, delay s, ``|tau0|`` N m);
            default :data:`DEFAULT_MAGNITUDES` (for ``slosh``: 30 % of the remaining liquid).

    Returns:
        A :class:`HiddenEffects` with only ``name`` set.
    """
    if name not in EFFECT_NAMES:
        raise SpaceIdInputError(f"hidden effect '{name}': unknown; expected one of {', '.join(EFFECT_NAMES)}")
    if magnitude is not None and not (math.isfinite(magnitude) and magnitude >= 0.0):
        raise SpaceIdInputError(f"hidden effect '{name}': magnitude must be a finite number >= 0, got {magnitude!r}")
    size = DEFAULT_MAGNITUDES[name] if magnitude is None else float(magnitude)
    if name == "initial_momentum":
        return HiddenEffects(initial_momentum_Nms=size * random_unit_vector(rng))
    if name == "gyro_bias":
        return HiddenEffects(gyro_bias_rad_s=size * random_unit_vector(rng))
    if name == "gyro_scale":
        return HiddenEffects(gyro_scale_misalignment=size * random_unit_vector(rng, 9).reshape(3, 3))
    if name == "delay":
        return HiddenEffects(delay_s=size)
    if name == "external_torque":
        return HiddenEffects(
            external_torque_Nm=size * random_unit_vector(rng),
            external_torque_rate_Nm_s=2.0 * ORBITAL_RATE_RAD_S * size * random_unit_vector(rng),
        )
    if name == "slosh":
        return draw_slosh(rng, robot, fuel_consumed_kg, None if magnitude is None else size)
    # payload: a uniform box, random orientation, CoM at PAYLOAD_DISTANCE_M in a random direction
    if size <= 0.0:
        raise SpaceIdInputError(f"hidden effect 'payload': magnitude (mass) must be > 0 kg, got {magnitude!r}")
    a, b, c = PAYLOAD_BOX_M
    box = size / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    rot = _random_rotation(rng)
    com = PAYLOAD_DISTANCE_M * random_unit_vector(rng)
    return HiddenEffects(payload_params10=RigidBodyInertia(size, com, rot @ box @ rot.T).to_params10())


def draw_slosh(
    rng: np.random.Generator,
    robot: Robot,
    fuel_consumed_kg: float,
    mass_kg: float | None = None,
    model: str = "spring",
    period_s: float | tuple[float, float] | None = None,
    length_m: float = SLOSH_PENDULUM_LENGTH_M,
    axis_base: tuple[float, float, float] = SLOSH_PENDULUM_AXIS,
) -> HiddenEffects:
    """A slosh effect: its mass, model and period (:func:`draw_effect` ``("slosh", ...)`` with the defaults).

    Args:
        rng: the generator a drawn period comes from (nothing is drawn with a fixed or default period).
        robot, fuel_consumed_kg: set the remaining liquid (:func:`remaining_liquid_kg`), kg.
        mass_kg: the slosh mass, kg, at most the remaining liquid; default 30 % of it.
        model: ``"spring"`` or ``"pendulum"`` (:data:`SLOSH_MODELS`); the spring leaves ``slosh_model`` unset.
        period_s: the natural period, s: a number, a ``(low, high)`` range to draw it from log-uniformly (e.g.
            :data:`SLOSH_PERIOD_RANGE_S`), or ``None`` for :data:`SLOSH_FREQUENCY_HZ`.
        length_m, axis_base: the pendulum's rod length (m) and axis (unit vector, base frame); pendulum only.

    Returns:
        A :class:`HiddenEffects` with only ``slosh`` set, damping ratio :data:`SLOSH_DAMPING_RATIO`.
    """
    if model not in SLOSH_MODELS:
        raise SpaceIdInputError(f"hidden effect 'slosh': model {model!r} unknown; expected one of {', '.join(SLOSH_MODELS)}")
    liquid = remaining_liquid_kg(robot, fuel_consumed_kg)
    mass = DEFAULT_MAGNITUDES["slosh"] * liquid if mass_kg is None else float(mass_kg)
    if not (math.isfinite(mass) and mass >= 0.0):
        raise SpaceIdInputError(f"hidden effect 'slosh': mass expected a finite number >= 0 kg, got {mass_kg!r}")
    if mass > liquid:
        raise SpaceIdInputError(
            f"hidden effect 'slosh': magnitude {mass:g} kg exceeds the remaining liquid {liquid:g} kg "
            f"(usable fuel minus the {fuel_consumed_kg:g} kg consumed)"
        )
    if period_s is None:
        frequency = SLOSH_FREQUENCY_HZ
    elif isinstance(period_s, tuple | list):
        low, high = (float(x) for x in period_s)
        if not 0.0 < low <= high < math.inf:
            raise SpaceIdInputError(f"hidden effect 'slosh': period range expected 0 < low <= high s, got {period_s!r}")
        frequency = 1.0 / math.exp(rng.uniform(math.log(low), math.log(high)))
    else:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise SpaceIdInputError(f"hidden effect 'slosh': period expected > 0 s, got {period_s!r}")
        frequency = 1.0 / float(period_s)
    pendulum: dict[str, Any] = {}
    if model == "pendulum":
        pendulum = {"slosh_model": model, "slosh_length_m": length_m, "slosh_axis": axis_base}
    return HiddenEffects(slosh_mass_kg=mass, slosh_frequency_hz=frequency, slosh_damping_ratio=SLOSH_DAMPING_RATIO, **pendulum)


# ---------------------------------------------------------------------- spec strings
def _parse_value(spec: str, name: str, key: str, text: str) -> float | str | FloatArray:
    if key == "slosh_model":
        if text not in SLOSH_MODELS:
            raise SpaceIdInputError(
                f"hidden effects '{spec}': {name}[{key}=...] expected one of {', '.join(SLOSH_MODELS)}, got {text!r}"
            )
        return text
    try:
        values = [float(x) for x in text.split(";")]
    except ValueError:
        raise SpaceIdInputError(
            f"hidden effects '{spec}': {name}[{key}=...] expected a number or numbers separated by ';', got {text!r}"
        ) from None
    if not _SHAPES.get(key, ()):
        if len(values) != 1:
            raise SpaceIdInputError(f"hidden effects '{spec}': {name}[{key}=...] expected one number, got {text!r}")
        return values[0]
    shape = _SHAPES[key]
    if len(values) != math.prod(shape):
        raise SpaceIdInputError(
            f"hidden effects '{spec}': {name}[{key}=...] expected {math.prod(shape)} numbers separated by ';', got {text!r}"
        )
    return np.array(values).reshape(shape)


def parse_effect_spec(spec: str) -> list[tuple[str, dict[str, Any]]]:
    """The syntax of a spec string: ``[(effect name, {key: value})]``, checked, nothing drawn.

    Raises:
        SpaceIdInputError: unknown effect names or keys (listing the valid ones), malformed values,
            an effect given twice.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise SpaceIdInputError(f"hidden effects: expected a spec such as 'slosh,delay[delay_s=0.03]', got {spec!r}")
    out: list[tuple[str, dict[str, Any]]] = []
    for item in split_outside_brackets(spec, f"hidden effects '{spec}'"):
        name, options = parse_setting(item, f"hidden effects '{spec}'")
        if name not in EFFECT_NAMES:
            raise SpaceIdInputError(
                f"hidden effects '{spec}': unknown effect '{name}'; expected one of {', '.join(EFFECT_NAMES)}"
            )
        if any(name == seen for seen, _ in out):
            raise SpaceIdInputError(f"hidden effects '{spec}': effect '{name}' given twice")
        valid = ("magnitude", *EFFECT_FIELDS[name])
        settings: dict[str, Any] = {}
        for pair in options or []:
            key, sep, text = (part.strip() for part in pair.partition("="))
            if not sep or key not in valid:
                raise SpaceIdInputError(
                    f"hidden effects '{spec}': {name}[{pair.strip()}] is not key=value with a valid key; "
                    f"expected keys {', '.join(valid)}"
                )
            settings[key] = _parse_value(spec, name, key, text)
        out.append((name, settings))
    return out


def parse_hidden_effects(spec: str, rng: np.random.Generator, robot: Robot, fuel_consumed_kg: float) -> HiddenEffects:
    """Draw the effects a spec string names (see the module docstring); given field values replace the draw's.

    Example: ``"slosh,delay[delay_s=0.03],gyro_bias[magnitude=1e-4]"``.
    """
    effects = HiddenEffects()
    for name, settings in parse_effect_spec(spec):
        magnitude = settings.pop("magnitude", None)
        drawn = draw_effect(name, rng, robot, fuel_consumed_kg, magnitude)
        effects = effects.combine(dataclasses.replace(drawn, **settings) if settings else drawn)
    return effects
