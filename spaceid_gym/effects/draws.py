"""Default sizes of the hidden effects, with their sources, and random draws of them (directions, orientations, periods).

A draw (:func:`draw_effect`) has a fixed size, the default or ``magnitude``, and random directions
(uniform on the sphere) or orientations from the generator passed in. The effects' fields, frames and
units: :mod:`spaceid_gym.effects.settings`.

Default magnitudes (:data:`DEFAULT_MAGNITUDES`) and their sources; ``magnitude`` units:

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
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import EFFECT_NAMES, SLOSH_MODELS, SLOSH_PENDULUM_AXIS, SLOSH_PENDULUM_LENGTH_M, HiddenEffects
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.physics.inertia import RigidBodyInertia
from spaceid_gym.robots.robot import Robot

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
#: the slosh periods :func:`draw_slosh` draws from (log-uniform), s
SLOSH_PERIOD_RANGE_S = (2.0, 50.0)
PAYLOAD_BOX_M = (0.3, 0.2, 0.2)
PAYLOAD_DISTANCE_M = 0.15


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


def remaining_liquid_kg(robot: Robot, fuel_consumed_kg: float | FloatArray) -> float | FloatArray:
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
