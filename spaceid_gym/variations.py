"""The variation matrix: simulated logs whose every setting is drawn from the seed.

A log of the diagnosis suite used to have one robot, one sample rate, one sensor set, one excitation and the
effects' default sizes; a rule designed on such logs need not hold on others. Here each log (a
:class:`VariationCase`, drawn by :func:`draw_variation` from ``numpy.random.default_rng([seed, VARIATION_STREAM])``)
draws every *axis* (:data:`AXES`), so that figures measured over many seeds come from data no rule was designed on:

==============  ==========================================================================================
axis            values (drawn uniformly unless said otherwise)
==============  ==========================================================================================
robot           ``paper6``, ``quick3``, ``orbit7`` (:mod:`spaceid_gym.robots`)
rate_hz         20, 50, 100: the sample (and control) rate, Hz
attitude        ``none``, ``star_tracker_1arcsec``, ``star_tracker_5arcsec``, ``star_tracker_20arcsec``,
                ``exact``, ``fused`` (a 5 arcsec star tracker fused with the gyro); see
                :class:`~spaceid_gym.sim.sensors.SensorModel` ``attitude_source``
noise_scale     log-uniform in [0.3, 3]: the factor on every sensor noise
excitation      ``diagnostic`` (the multi-sine of :data:`DIAGNOSTIC_EXCITATION`, 0.05-0.5 Hz), ``evaluation``
                (:class:`~spaceid_gym.excitation.FourierExcitation`'s defaults, 0.025-0.125 Hz), ``smooth_random``
                (:class:`~spaceid_gym.excitation.SmoothRandomExcitation`)
size_factor     log-uniform in [0.3, 3]: the hidden effect's size over its catalogue default
                (:data:`~spaceid_gym.effects.DEFAULT_MAGNITUDES`; slosh: the mass over 30 % of the liquid left,
                capped at the liquid left); ``None`` for a clean log
slosh_model     ``spring``, ``pendulum`` (slosh logs only, else ``None``)
slosh_period_s  log-uniform over :data:`~spaceid_gym.effects.draws.SLOSH_PERIOD_RANGE_S` (2-50 s; slosh logs only)
==============  ==========================================================================================

A pendulum's rod points anywhere (uniform on the sphere, base frame: the settling acceleration of a real tank is
along a thruster's axis, which need not be a base axis) and is 0.1-1 m long (log-uniform), both drawn from the
effect's generator (they are the effect's geometry, as the other effects' directions are).

The fuel state is drawn as in the evaluation harness (``estimators.evaluation.draw_settings``, which this lower
layer does not import): fuel consumed uniform between :class:`~spaceid_gym.mission.FuelSchedule`'s
``initial_fraction`` and ``usable_fraction`` of the robot's full-tank base mass, tank position uniform in its box;
both as fractions drawn before the robot is known, so that pinning the robot leaves them (and every other axis) as
drawn. Every axis is drawn on every case in a fixed order, whatever the effect and whatever is pinned; the effect's
directions (:func:`~spaceid_gym.effects.draw_effect`) come from a generator spawned from the same one.

``fixed`` pins axes (``{"robot": "paper6", "rate_hz": 50}``, or the strings of ``spaceid diagnose-suite --matrix
--fix robot=paper6,rate_hz=50``, :func:`parse_fixed`); a pinned slosh axis is ignored on logs of other effects
(where the axis is ``None``), and a pinned size factor on clean logs.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from spaceid_gym.datasets import Excitation, simulate_episode
from spaceid_gym.effects.draws import (
    DEFAULT_MAGNITUDES,
    SLOSH_PERIOD_RANGE_S,
    draw_effect,
    draw_slosh,
    random_unit_vector,
    remaining_liquid_kg,
)
from spaceid_gym.effects.settings import EFFECT_NAMES, SLOSH_MODELS, HiddenEffects
from spaceid_gym.envs.free_floating import FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.excitation import FourierExcitation, SmoothRandomExcitation
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.robots import load_robot
from spaceid_gym.sim.sensors import ARCSEC_RAD, SensorModel

#: the second entry of the seed of :func:`draw_variation`'s generator (``default_rng([seed, VARIATION_STREAM])``),
#: so that the matrix's draws are not those of another use of the same seed
VARIATION_STREAM = 7

#: a clean log's effect name
NO_EFFECT = "none"

#: the options of the diagnosis suite's excitation (``estimators.diagnostics.suite.DIAGNOSTIC_EXCITATION``, copied
#: here because this layer does not import ``estimators``): the multi-sine at 0.05-0.5 Hz
DIAGNOSTIC_EXCITATION: dict[str, float | int] = {"base_frequency_hz": 0.05, "n_harmonics": 10}

#: the star tracker's noise of the ``star_tracker_*`` attitude values, arcsec per axis
STAR_TRACKER_ARCSEC: dict[str, float] = {"star_tracker_1arcsec": 1.0, "star_tracker_5arcsec": 5.0, "star_tracker_20arcsec": 20.0}

#: the pendulum's rod length range, natural logs of metres (drawn log-uniformly)
PENDULUM_LOG_LENGTH_M = (math.log(0.1), math.log(1.0))

#: the drawn values of each discrete axis, in the order of the tables
AXIS_VALUES: dict[str, tuple[Any, ...]] = {
    "robot": ("paper6", "quick3", "orbit7"),
    "rate_hz": (20, 50, 100),
    "attitude": ("none", *STAR_TRACKER_ARCSEC, "exact", "fused"),
    "excitation": ("diagnostic", "evaluation", "smooth_random"),
    "slosh_model": SLOSH_MODELS,
}

#: the range of each continuous axis, drawn log-uniformly
AXIS_RANGES: dict[str, tuple[float, float]] = {
    "noise_scale": (0.3, 3.0),
    "size_factor": (0.3, 3.0),
    "slosh_period_s": SLOSH_PERIOD_RANGE_S,
}

#: the bins of each continuous axis in the tables (edges, the range's ends first and last)
AXIS_BINS: dict[str, tuple[float, ...]] = {
    "noise_scale": (0.3, 0.65, 1.4, 3.0),
    "size_factor": (0.3, 0.65, 1.4, 3.0),
    "slosh_period_s": (2.0, 6.0, 17.0, 50.0),
}

#: every axis, in the order of :meth:`VariationCase.axes` and of the draw
AXES: tuple[str, ...] = (
    "robot",
    "rate_hz",
    "attitude",
    "noise_scale",
    "excitation",
    "size_factor",
    "slosh_model",
    "slosh_period_s",
)

#: the axes of one effect only (``None`` on the other logs)
_SLOSH_AXES = ("slosh_model", "slosh_period_s")


@dataclass(frozen=True)
class VariationCase:
    """One log of the variation matrix: its axes (see the module docstring), fuel state and hidden effect.

    Attributes:
        effect: the hidden effect (:data:`~spaceid_gym.effects.EFFECT_NAMES`) or ``"none"``.
        seed: the seed the case was drawn from; also seeds the simulation's noise and the excitation.
        robot, rate_hz, attitude, noise_scale, excitation, size_factor, slosh_model, slosh_period_s: the axes.
        fuel_consumed_kg: fuel consumed, kg; ``tank_position_m``: the tank (3,), m, base frame, from the full-tank CoM.
        magnitude: the effect's size in :data:`~spaceid_gym.effects.MAGNITUDE_UNITS` (slosh: kg); ``None`` when clean.
        hidden: the hidden effect with its drawn directions; ``None`` when clean.
    """

    effect: str
    seed: int
    robot: str
    rate_hz: int
    attitude: str
    noise_scale: float
    excitation: str
    size_factor: float | None
    slosh_model: str | None
    slosh_period_s: float | None
    fuel_consumed_kg: float
    tank_position_m: tuple[float, float, float]
    magnitude: float | None
    hidden: HiddenEffects | None

    def axes(self) -> dict[str, Any]:
        """Every axis's value (:data:`AXES` order), ``None`` where an axis does not apply."""
        return {axis: getattr(self, axis) for axis in AXES}

    @property
    def control_period_s(self) -> float:
        """The sample (and control) period, s."""
        return 1.0 / self.rate_hz

    def sensors(self) -> SensorModel:
        """The sensor model of the case's attitude source and noise scale (the other settings the defaults)."""
        if self.attitude in STAR_TRACKER_ARCSEC:
            arcsec = STAR_TRACKER_ARCSEC[self.attitude]
            return SensorModel(
                attitude_source="star_tracker", attitude_noise_rad=arcsec * ARCSEC_RAD, noise_scale=self.noise_scale
            )
        return SensorModel(attitude_source=self.attitude, noise_scale=self.noise_scale)

    def make_excitation(self, n_joints: int, duration_s: float) -> Excitation:
        """The case's joint-rate command for ``n_joints`` joints over ``duration_s``, seeded with the case's seed."""
        if self.excitation == "diagnostic":
            return FourierExcitation(n_joints, seed=self.seed, **DIAGNOSTIC_EXCITATION)  # type: ignore[arg-type]
        if self.excitation == "evaluation":
            return FourierExcitation(n_joints, seed=self.seed)
        return SmoothRandomExcitation(n_joints, seed=self.seed, duration_s=duration_s)


def checked_fixed(fixed: Mapping[str, Any] | None) -> dict[str, Any]:
    """``fixed`` with each value as its axis's type (strings such as ``"50"`` are read), checked.

    Raises:
        SpaceIdInputError: an unknown axis (listing :data:`AXES`), a value outside the axis's values (listing them)
            or range.
    """
    out: dict[str, Any] = {}
    for axis, value in (fixed or {}).items():
        if axis not in AXES:
            raise SpaceIdInputError(f"variation axis {axis!r}: unknown; expected one of {', '.join(AXES)}")
        out[axis] = _axis_value(axis, value)
    return out


def _axis_value(axis: str, value: Any) -> Any:
    """``value`` (or its text) as a value of ``axis``; raises naming the axis and what it allows."""
    if axis in AXIS_VALUES:
        allowed = AXIS_VALUES[axis]
        for candidate in allowed:
            if value == candidate or str(value).strip() == str(candidate):
                return candidate
        raise SpaceIdInputError(f"variation axis {axis!r}: expected one of {', '.join(map(str, allowed))}, got {value!r}")
    low, high = AXIS_RANGES[axis]
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not low <= number <= high:
        raise SpaceIdInputError(f"variation axis {axis!r}: expected a number in [{low:g}, {high:g}], got {value!r}")
    return number


def parse_fixed(text: str | None) -> dict[str, Any]:
    """``"robot=paper6,rate_hz=50"`` -> ``{"robot": "paper6", "rate_hz": 50}`` (``None``: nothing pinned), checked
    (:func:`checked_fixed`).

    Raises:
        SpaceIdInputError: an empty text, a pair that is not ``axis=value``, an axis given twice, or what
            :func:`checked_fixed` refuses.
    """
    if text is None:
        return {}
    pairs = [p.strip() for p in text.split(",") if p.strip()]
    if not pairs:
        raise SpaceIdInputError(f"expected axis=value pairs such as 'robot=paper6,rate_hz=50', got {text!r}")
    out: dict[str, str] = {}
    for pair in pairs:
        axis, sep, value = (part.strip() for part in pair.partition("="))
        if not sep or not value:
            raise SpaceIdInputError(f"expected axis=value (axes: {', '.join(AXES)}), got {pair!r}")
        if axis in out:
            raise SpaceIdInputError(f"variation axis {axis!r} given twice")
        out[axis] = value
    return checked_fixed(out)


def _log_uniform(rng: np.random.Generator, axis: str) -> float:
    """A draw log-uniform over the axis's range."""
    low, high = AXIS_RANGES[axis]
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def draw_variation(effect: str, seed: int, fixed: Mapping[str, Any] | None = None) -> VariationCase:
    """The case of ``effect`` (``"none"``: clean) and ``seed``, with the axes in ``fixed`` pinned.

    Every axis, the fuel fraction and the tank's place in its box are drawn from
    ``numpy.random.default_rng([seed, VARIATION_STREAM])`` in a fixed order, whatever is pinned or hidden; the
    effect's directions from a generator spawned from it (see the module docstring).

    Raises:
        SpaceIdInputError: an unknown effect, a seed that is not an integer >= 0, a bad ``fixed``
            (:func:`checked_fixed`).
    """
    if effect != NO_EFFECT and effect not in EFFECT_NAMES:
        raise SpaceIdInputError(f"variation effect {effect!r}: unknown; expected one of {NO_EFFECT}, {', '.join(EFFECT_NAMES)}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise SpaceIdInputError(f"variation seed: expected an integer >= 0, got {seed!r}")
    pinned = checked_fixed(fixed)
    rng = np.random.default_rng([int(seed), VARIATION_STREAM])
    drawn: dict[str, Any] = {}
    for axis in AXES:  # every axis drawn, in order, so that pinning one leaves the others as they were
        if axis in AXIS_VALUES:
            drawn[axis] = AXIS_VALUES[axis][int(rng.integers(len(AXIS_VALUES[axis])))]
        else:
            drawn[axis] = _log_uniform(rng, axis)
    fuel_fraction = float(rng.uniform())
    tank_fraction = rng.uniform(-1.0, 1.0, size=3)
    effect_rng = rng.spawn(1)[0]
    drawn.update(pinned)
    if effect != "slosh":
        drawn.update(dict.fromkeys(_SLOSH_AXES))
    if effect == NO_EFFECT:
        drawn["size_factor"] = None

    robot = load_robot(drawn["robot"])
    schedule = FuelSchedule()
    base = robot.base_full
    fuel_kg = (schedule.initial_fraction + fuel_fraction * (schedule.usable_fraction - schedule.initial_fraction)) * base.mass_kg
    tank = tuple(float(x) for x in tank_fraction * schedule.tank_half_width_m(base))
    magnitude, hidden = None, None
    if effect == "slosh":
        liquid_kg = float(remaining_liquid_kg(robot, fuel_kg))
        magnitude = min(drawn["size_factor"] * DEFAULT_MAGNITUDES["slosh"] * liquid_kg, liquid_kg)
        pendulum = {}
        if drawn["slosh_model"] == "pendulum":  # the rod: any direction, 0.1-1 m (drawn only here: nothing else moves)
            pendulum = {
                "axis_base": tuple(random_unit_vector(effect_rng)),
                "length_m": math.exp(effect_rng.uniform(*PENDULUM_LOG_LENGTH_M)),
            }
        hidden = draw_slosh(effect_rng, robot, fuel_kg, magnitude, drawn["slosh_model"], drawn["slosh_period_s"], **pendulum)
    elif effect != NO_EFFECT:
        magnitude = drawn["size_factor"] * DEFAULT_MAGNITUDES[effect]
        hidden = draw_effect(effect, effect_rng, robot, fuel_kg, magnitude)
    return VariationCase(
        effect=effect,
        seed=int(seed),
        fuel_consumed_kg=float(fuel_kg),
        tank_position_m=tank,  # type: ignore[arg-type]
        magnitude=magnitude,
        hidden=hidden,
        **drawn,
    )


def simulate_variation(
    case: VariationCase, duration_s: float = 60.0, noise_seed: int | None = None, integration_substeps: int | None = None
) -> FreeFloatingIDEnv:
    """Simulate the case's log of ``duration_s`` at its rate: the env after the window (its ``measurement_log()``,
    ``truth()``, ``sensors`` and ``hidden_effects``; :func:`truth_of` for truth.json's fields). ``noise_seed``: the
    same motion measured with noise from a generator of its own (default: the case's seed draws both);
    ``integration_substeps``: the simulator's steps per control period (the env's)."""
    if not isinstance(case, VariationCase):
        raise SpaceIdInputError(f"simulate_variation: expected a VariationCase, got {type(case).__name__}")
    robot = load_robot(case.robot)
    return simulate_episode(
        robot,
        duration_s,
        case.fuel_consumed_kg,
        np.array(case.tank_position_m),
        case.make_excitation(robot.n_joints, duration_s),
        seed=case.seed,
        sensors=case.sensors(),
        control_period_s=case.control_period_s,
        hidden_effects=case.hidden,
        noise_seed=noise_seed,
        integration_substeps=integration_substeps,
    )


def truth_of(env: FreeFloatingIDEnv) -> dict[str, Any]:
    """The env's truth with the sensor settings under ``noise`` (as truth.json has them, see
    :func:`spaceid_gym.datasets.write_episode_dataset`): ``noise["gyro_std_rad_s"]`` is the per-sample gyro std."""
    return {**env.truth(), "noise": env.sensors.as_dict(env.control_period_s)}


def axis_label(axis: str, value: Any) -> str | None:
    """The column of ``value`` in the tables: the value of a discrete axis, the bin of a continuous one
    (``"0.3-0.65"``); ``None`` where the axis does not apply."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    if axis in AXIS_VALUES:
        return str(_axis_value(axis, value))
    return _bin_label(AXIS_BINS[axis], float(value))


def axis_labels(axis: str) -> list[str]:
    """Every column of ``axis`` in the tables, in order."""
    if axis in AXIS_VALUES:
        return [str(v) for v in AXIS_VALUES[axis]]
    edges = AXIS_BINS[axis]
    return [_bin_label(edges, 0.5 * (a + b)) for a, b in itertools.pairwise(edges)]


def _bin_label(edges: tuple[float, ...], value: float) -> str:
    """``"low-high"`` of the bin holding ``value`` (the last bin holds its upper edge)."""
    index = min(max(int(np.searchsorted(edges, value, side="right")) - 1, 0), len(edges) - 2)
    return f"{edges[index]:g}-{edges[index + 1]:g}"
