"""Effect terms of the identification model: physical effects the paper's model leaves out.

The paper's model (:mod:`estimators.models.momentum_model`) assumes zero system momentum, a perfect gyro
sampled with the encoders, a rigid base and an empty gripper. Each :class:`EffectTerm` removes one of these
assumptions with its own unknowns (names with units, a nominal value that switches it off, a documented
search range) and acts in one of three places of the prediction:

* **body** — ``payload``: an object held by the last link adds its 10 inertial parameters to the
  composite (the payload maps of the momentum model);
* **momentum** — the momentum the base and arm carry is not ``-h_arm``:

  - ``initial_momentum``: a constant system angular momentum ``l0`` (residual spin, stored wheel momentum),
    expressed in the base frame at the log's first sample, so ``L_body(t) = R_rel(t)^T l0``;
  - ``external_torque``: ``L(t) = l0 + tau t`` (+ ``tau_rate t^2 / 2`` with ``drift=True``), the
    momentum is not conserved (thruster leak, gravity gradient); frames as for ``initial_momentum``;
  - ``slosh``: a point mass ``m_s`` on an isotropic spring-damper (``f``, ``zeta``) at the tank, or on a
    pendulum whose rod direction is fitted (``slosh[model=pendulum]``), driven by the tank's inertial
    acceleration; its momentum relative to the base is taken from the rigid bodies (see :class:`Slosh`);

* **measurement** — the gyro does not read the base rate at the encoders' sample time:
  ``omega_meas(t) = (I + E) omega(t - d) + b`` with ``delay`` ``d``, ``gyro_scale`` ``E`` (scale factors on
  the diagonal, misalignments off it) and ``gyro_bias`` ``b``.

``R_rel(t) = R(t0)^T R(t)`` is the base attitude relative to the first sample, from the log's quaternions
or, in a log without them, by integrating the logged gyro rate (its angle random walk, ~2e-4 rad over a
minute for the default gyro, is negligible here).

Search range and plausibility are two things. Each term searches a physically *wide* range (stated in its
docstring: a momentum up to what spins the satellite at :data:`MAX_BASE_RATE_RAD_S`, a delay up to
:data:`MAX_DELAY_S`, a slosh mass up to the usable fuel, frequencies 0.02-2 Hz), far beyond the sizes
expected in flight, so that a real effect larger than expected is still fitted where it is. Plausibility
(:meth:`EffectTerm.implausible`) is a physical judgement only: a payload must be a physical body with a
positive mass, the slosh mass cannot exceed the liquid left in the tank. A value on its search bound is no
reason: the range is not a limit of reality. Each term also has a typical size (:attr:`EffectTerm.scale`,
the sizes expected in flight), which scales its unknowns in the local fits.

The simulator implements the same effects independently as physics (:mod:`spaceid_gym.effects`); tests
compare the two. Both share the field names of ``truth.json``'s ``hidden_effects``:
:meth:`EffectTerm.from_truth` reads a term's unknowns from a simulated truth.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

# the shared base and the mass terms, importable from the catalogue as before the split
from estimators.models.effect_base import MAX_BASE_RATE_RAD_S as MAX_BASE_RATE_RAD_S
from estimators.models.effect_base import (
    MAX_DELAY_S,
    TORQUE_RANGE_WINDOW_S,
    EffectContext,
    EffectTerm,
    _in_base_axes,
    _VectorTerm,
    momentum_range_nms,
)
from estimators.models.fractional_delay import delay_samples
from estimators.models.mass_effects import PAYLOAD_GRID_ARM_FRACTIONS as PAYLOAD_GRID_ARM_FRACTIONS
from estimators.models.mass_effects import PAYLOAD_MAX_FRACTION_OF_ROBOT as PAYLOAD_MAX_FRACTION_OF_ROBOT
from estimators.models.mass_effects import PAYLOAD_NAMES as PAYLOAD_NAMES
from estimators.models.mass_effects import PAYLOAD_SIZE_M as PAYLOAD_SIZE_M
from estimators.models.mass_effects import TYPICAL_PAYLOAD_SIZE_M as TYPICAL_PAYLOAD_SIZE_M
from estimators.models.mass_effects import Payload, Slosh, _point_mass10
from estimators.models.mass_effects import payload_box as payload_box
from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.settings import SLOSH_MODELS
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.robots import Robot
from spaceid_gym.specs import parse_setting, split_outside_brackets


class InitialMomentum(_VectorTerm):
    """``l0`` (3,), N m s, base frame at the first sample.

    Range ``+-`` :func:`momentum_range_nms` (5 deg/s of the full-tank base: 35 N m s on ``paper6``); typical size
    2 N m s (0.3 deg/s of the base of ``paper6``)."""

    name = "initial_momentum"
    stage = "momentum"
    unit, bound, prefix, typical = "Nms", math.nan, "momentum", 2.0

    @classmethod
    def range_of(cls, robot: Robot) -> float:
        return momentum_range_nms(robot)

    def angular_momentum(self, theta: FloatArray, context: EffectContext) -> FloatArray:
        """System angular momentum in base axes (P, T, 3) for ``theta`` (P, 3)."""
        return _in_base_axes(context.rot_rel, np.ascontiguousarray(theta[:, None, :], dtype=float))


class ExternalTorque(EffectTerm):
    """``[l0 (3) N m s, tau (3) N m]`` (+ ``tau_rate`` (3) N m/s with ``drift``): ``L(t) = l0 + tau t + tau_rate t^2 / 2``.

    Ranges: ``l0`` as :class:`InitialMomentum`, ``tau`` up to the torque that brings that momentum in
    :data:`TORQUE_RANGE_WINDOW_S` (0.6 N m on ``paper6``: a thruster, not only gravity gradient), ``tau_rate`` up to
    that torque per :data:`TORQUE_RANGE_WINDOW_S`. Typical sizes 2 N m s, 0.01 N m (two orders above gravity
    gradient on ``paper6``) and 1e-4 N m/s.
    """

    name = "external_torque"
    stage = "momentum"
    nests = ("initial_momentum",)

    def __init__(self, robot: Robot, drift: bool = False) -> None:
        momentum = momentum_range_nms(robot)
        torque = momentum / TORQUE_RANGE_WINDOW_S
        names = [f"momentum_{a}_Nms" for a in "xyz"] + [f"torque_{a}_Nm" for a in "xyz"]
        bounds, typical = [momentum] * 3 + [torque] * 3, [2.0] * 3 + [0.01] * 3
        fields = [("initial_momentum_Nms", 3), ("external_torque_Nm", 3)]
        if drift:
            names += [f"torque_rate_{a}_Nm_s" for a in "xyz"]
            bounds += [torque / TORQUE_RANGE_WINDOW_S] * 3
            typical += [1e-4] * 3
            fields.append(("external_torque_rate_Nm_s", 3))
        self.names, self.drift, self.truth_fields = tuple(names), drift, tuple(fields)
        super().__init__(np.zeros(len(names)), -np.array(bounds), np.array(bounds), np.array(typical))

    def angular_momentum(self, theta: FloatArray, context: EffectContext) -> FloatArray:
        """System angular momentum in base axes (P, T, 3) for ``theta`` (P, k_e)."""
        t = context.t_s
        inertial = theta[:, None, 0:3] + theta[:, None, 3:6] * t[None, :, None]
        if self.drift:
            inertial = inertial + 0.5 * theta[:, None, 6:9] * (t * t)[None, :, None]
        return _in_base_axes(context.rot_rel, np.ascontiguousarray(inertial, dtype=float))

    @property
    def spec(self) -> str:
        return f"{self.name}[drift=true]" if self.drift else self.name

    def describes(self, hidden: Mapping[str, Any]) -> bool:
        """Whether the truth's torque drifts exactly when this term does (no ``external_torque_rate_Nm_s``, or a zero
        one: a constant torque)."""
        rate = hidden.get("external_torque_rate_Nm_s")
        return self.drift == (rate is not None and bool(np.any(np.asarray(rate, dtype=float) != 0.0)))

    def grid_from_variant(self, fitted: FloatArray) -> list[FloatArray]:
        """With ``drift``: the other variant's momentum and torque (its first six values) with no drift; the drift's
        own momentum and torque when this is the variant without it. A drifting torque is nested in the constant one's
        extension, so the constant's fit is the drift model's nearest start."""
        fitted = np.asarray(fitted, dtype=float)
        return [np.concatenate((fitted[:6], np.zeros(3)))] if self.drift else [fitted[:6].copy()]

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        out = {"initial_momentum_Nms": theta[0:3].copy(), "external_torque_Nm": theta[3:6].copy()}
        if self.drift:
            out["external_torque_rate_Nm_s"] = theta[6:9].copy()
        return out


class GyroBias(_VectorTerm):
    """``b`` (3,), rad/s, base body frame; range +-0.05 rad/s (3 deg/s, beyond an uncalibrated MEMS gyro); typical
    size 1e-3 rad/s (200 deg/h, far beyond any navigation gyro)."""

    name = "gyro_bias"
    stage = "measurement"
    additive = True
    unit, bound, prefix, typical = "rad_s", 0.05, "bias", 1e-3

    def measure(self, omega: FloatArray, theta: FloatArray, context: EffectContext) -> FloatArray:
        """``omega + b``: (P, T, 3)."""
        return omega + theta[:, None, :]


class GyroScale(EffectTerm):
    """``E`` (3x3, row-major, 9 unknowns): ``omega_meas = (I + E) omega``; range +-0.2 (20 % scale, 200 mrad
    misalignment: a gyro unit mounted wrongly), typical size 0.02 (2 % scale, 20 mrad misalignment)."""

    name = "gyro_scale"
    stage = "measurement"

    def __init__(self, robot: Robot) -> None:
        self.names = tuple(f"scale_{r}{c}" for r in "xyz" for c in "xyz")
        self.truth_fields = (("gyro_scale_misalignment", 9),)
        super().__init__(np.zeros(9), np.full(9, -0.2), np.full(9, 0.2), np.full(9, 0.02))

    def measure(self, omega: FloatArray, theta: FloatArray, context: EffectContext) -> FloatArray:
        """``(I + E) omega``: (P, T, 3)."""
        return _scaled(np.ascontiguousarray(omega), np.ascontiguousarray(theta.reshape(-1, 3, 3)))

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        return {"gyro_scale_misalignment": np.asarray(theta, dtype=float).reshape(3, 3).copy()}


@njit(cache=True)
def _scaled(omega: FloatArray, scale: FloatArray) -> FloatArray:
    """``omega + E omega`` (P, T, 3) for rates ``omega`` (P, T, 3) and ``E`` (P, 3, 3).

    The products are summed in the order numpy's ``einsum`` sums them (first and third, then the second), so that
    the rates are bit for bit those of the ``einsum`` this replaces."""
    out = np.empty_like(omega)
    for p in range(omega.shape[0]):
        for t in range(omega.shape[1]):
            w0, w1, w2 = omega[p, t, 0], omega[p, t, 1], omega[p, t, 2]
            for i in range(3):
                out[p, t, i] = omega[p, t, i] + ((scale[p, i, 0] * w0 + scale[p, i, 2] * w2) + scale[p, i, 1] * w1)
    return out


#: the band the delay acts on, Hz: all of it below the first value, none above the second, a raised cosine between
#: (see :class:`Delay`)
DELAY_BAND_HZ = (10.0, 20.0)


class Delay(EffectTerm):
    """``d`` (1,), s: the gyro reads the rate at ``t - d``; range ``+-`` :data:`MAX_DELAY_S`, typical size 0.1 s.

    The prediction is delayed by an all-pass phase ramp (:func:`~estimators.models.fractional_delay.delay_samples`),
    not by interpolation between samples: an interpolator also smooths the white noise the prediction carries from
    the joint-rate sensors, and a fit would take that smoothing for a delay of a fraction of a sample. Before the
    first sample the rate is held at its first value (a log that starts at rest).

    Only the content below :data:`DELAY_BAND_HZ` is delayed (a raised-cosine blend to none between its two values;
    the whole band at sample rates of 40 Hz and less). Above it the prediction is the joint sensors' noise, and even
    the phase ramp is not all-pass there: at the Nyquist frequency a real series cannot be shifted by a fraction of a
    sample (its bin keeps only the real part, ``cos(pi lag)``), so the delay smoothed the noise near it and a fit
    found sub-millisecond delays on clean logs (paper6 at 100 Hz, no attitude: mean likelihood ratio 3.8 over 12 clean
    logs, 1 expected; 0.73 with the band). The signal of the base rate (excitation and effects) lies far below it.

    The ramp is exact for a band-limited rate; at 20 Hz the joint servos change the rate within a step, and a named
    delay's fit is made again with the reading between samples from the joints' samples held at it
    (:mod:`estimators.gyro_between_samples`).
    """

    name = "delay"
    stage = "measurement"
    names = ("delay_s",)
    truth_fields = (("delay_s", 1),)

    def __init__(self, robot: Robot) -> None:
        super().__init__(np.zeros(1), np.array([-MAX_DELAY_S]), np.array([MAX_DELAY_S]), np.array([0.1]))

    def measure(self, omega: FloatArray, theta: FloatArray, context: EffectContext) -> FloatArray:
        """``omega(t - d)``: (P, T, 3), for a uniformly sampled log."""
        t = context.t_s
        dt = (t[-1] - t[0]) / (len(t) - 1)
        band = (DELAY_BAND_HZ[0] * dt, DELAY_BAND_HZ[1] * dt)
        return delay_samples(omega, theta[:, 0] / dt, band if band[1] < 0.5 else None)

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        return {"delay_s": float(theta[0])}


#: the catalogue: effect name -> term class
EFFECT_TERMS: dict[str, type[EffectTerm]] = {
    cls.name: cls for cls in (InitialMomentum, GyroBias, GyroScale, Payload, Slosh, Delay, ExternalTorque)
}

#: the order in which measurement effects apply: ``(I + E) omega(t - d) + b``
_MEASUREMENT_ORDER = ("delay", "gyro_scale", "gyro_bias")


#: the options of :func:`parse_effects`: effect -> (its one option, the values it takes)
_EFFECT_OPTIONS = {"external_torque": ("drift", ("true", "false")), "slosh": ("model", SLOSH_MODELS)}
_OPTIONS_TEXT = "external_torque[drift=true|false] and slosh[model=spring|pendulum]"


def parse_effects(spec: str | list[str] | tuple[str, ...] | None) -> list[tuple[str, dict[str, Any]]]:
    """``"slosh,external_torque[drift=true]"`` or a list of names -> ``[(name, options), ...]`` (validated, no duplicates)."""
    if spec is None:
        return []
    items = split_outside_brackets(spec, "effects") if isinstance(spec, str) else [str(s) for s in spec]
    out: list[tuple[str, dict[str, Any]]] = []
    for item in items:
        name, pairs = parse_setting(item, "effects")
        if name not in EFFECT_TERMS:
            raise SpaceIdInputError(f"effects: unknown effect {name!r}; expected one of {', '.join(EFFECT_TERMS)}")
        if any(n == name for n, _ in out):
            raise SpaceIdInputError(f"effects: {name!r} given twice")
        options: dict[str, Any] = {}
        for pair in pairs or []:
            key, eq, value = (part.strip() for part in pair.partition("="))
            if not eq or key != _EFFECT_OPTIONS.get(name, (None,))[0]:
                raise SpaceIdInputError(f"effects: {item!r}: the options are {_OPTIONS_TEXT}")
            choices = _EFFECT_OPTIONS[name][1]
            if value.lower() not in choices:
                raise SpaceIdInputError(f"effects: {item!r}: {key} must be one of {', '.join(choices)}")
            options[key] = value.lower() == "true" if key == "drift" else value.lower()
        out.append((name, options))
    return out


def make_terms(
    spec: str | list[str] | tuple[str, ...] | None,
    robot: Robot,
    tank_of: Callable[[FloatArray], FloatArray] | None = None,
    liquid_of: Callable[[FloatArray], FloatArray] | None = None,
) -> list[EffectTerm]:
    """The effect terms of ``spec`` (see :func:`parse_effects`) for ``robot``; ``tank_of`` places the slosh mass and
    ``liquid_of`` gives the liquid left to slosh (see :class:`Slosh`)."""
    terms: list[EffectTerm] = []
    for name, options in parse_effects(spec):
        if name == "slosh":
            terms.append(Slosh(robot, tank_of, liquid_of, **options))
        else:
            terms.append(EFFECT_TERMS[name](robot, **options))  # type: ignore[call-arg]
    return terms


class EffectPrediction:
    """The base-rate prediction with effect terms (what :class:`~estimators.problem.IdentificationProblem` uses).

    Args:
        momentum_model: the per-log momentum model.
        terms: the effect terms, in any order.
        context: the log's :class:`EffectContext`.
    """

    def __init__(self, momentum_model: Any, terms: list[EffectTerm], context: EffectContext) -> None:
        self.momentum_model = momentum_model
        self.terms = terms
        self.context = context
        self.momentum_terms = [t for t in terms if t.stage == "momentum"]
        self.slosh = next((t for t in terms if isinstance(t, Slosh)), None)
        order = {name: i for i, name in enumerate(_MEASUREMENT_ORDER)}
        self.measurement_terms = sorted((t for t in terms if t.stage == "measurement"), key=lambda t: order[t.name])
        #: the prediction needs the whole log (not a sample subset) when a term looks across samples
        self.needs_whole_log = self.slosh is not None or any(t.name == "delay" for t in terms)

    def predict(
        self,
        base10: FloatArray,
        payload10: FloatArray | None,
        effect_thetas: dict[EffectTerm, FloatArray],
        theta_base: FloatArray,
        samples: slice | NDArray[np.intp],
    ) -> tuple[FloatArray, FloatArray]:
        """For composite parameters, each term's ``theta`` (P, k_e) and the base parameterisation's unknowns
        ``theta_base`` (P, k_base) (they place a slosh mass and bound it by the liquid left): the base's own rate
        (base body frame) and what the gyro reads (after the measurement effects), each (P, T', 3), rad/s.

        Parameter sets that differ only in the measurement effects' unknowns (a difference Jacobian's columns of
        those) share one base rate, computed once."""
        span = slice(None) if self.needs_whole_log else samples
        sharing = self._sharing(base10, payload10, effect_thetas, theta_base)
        if sharing is None:
            true_rate = self._base_rate(base10, payload10, effect_thetas, theta_base, span)
        else:
            rows, shared = sharing
            chosen = {term: theta[rows] for term, theta in effect_thetas.items()}
            payload = None if payload10 is None else payload10[rows]
            true_rate = self._base_rate(base10[rows], payload, chosen, theta_base[rows], span)[shared]
        measured = true_rate
        for term in self.measurement_terms:
            measured = term.measure(measured, effect_thetas[term], self.context)  # type: ignore[attr-defined]
        if self.needs_whole_log:
            return true_rate[:, samples], measured[:, samples]
        return true_rate, measured

    def _sharing(
        self,
        base10: FloatArray,
        payload10: FloatArray | None,
        effect_thetas: dict[EffectTerm, FloatArray],
        theta_base: FloatArray,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
        """For parameter sets (see :meth:`predict`) of which some differ only in the measurement effects' unknowns:
        the first of each group (G,) and each set's group (P,); ``None`` when each needs its own base rate."""
        if not self.measurement_terms:
            return None
        rotating = [effect_thetas[t] for t in self.terms if t.stage != "measurement"]
        return _groups(np.hstack([base10, *([] if payload10 is None else [payload10]), *rotating, theta_base]))

    def _base_rate(
        self,
        base10: FloatArray,
        payload10: FloatArray | None,
        effect_thetas: dict[EffectTerm, FloatArray],
        theta_base: FloatArray,
        span: slice | NDArray[np.intp],
    ) -> FloatArray:
        """The base's own rate (P, T', 3) over ``span`` (see :meth:`predict`)."""
        n_p = base10.shape[0]
        extra = None
        for term in self.momentum_terms:
            angular = term.angular_momentum(effect_thetas[term], self.context)[:, span]  # type: ignore[attr-defined]
            extra = np.zeros((n_p, angular.shape[1], 6)) if extra is None else extra
            extra[..., 3:] += angular
        if self.slosh is None:
            twist = self.momentum_model.predict_twist(base10, payload10, extra, span)
        else:
            # only the liquid left can slosh (Slosh.moving_part); the mass sits at the tank of these base parameters
            theta_slosh = self.slosh.moving_part(effect_thetas[self.slosh], theta_base)
            tank_m = np.ascontiguousarray(self.slosh.tank_of(theta_base), dtype=float)
            # the slosh is driven by the motion of the rest of the robot (the slosh mass not attached)
            rest10 = base10 - _point_mass10(theta_slosh[:, 0], tank_m)
            # the rest's motion depends on the slosh mass, not on its frequency, damping or rod: sets that share it
            # (a scan of frequencies) share one prediction
            momenta = [effect_thetas[t] for t in self.momentum_terms]
            groups = _groups(np.hstack([rest10, *([] if payload10 is None else [payload10]), *momenta]))
            if groups is None:
                rest_twist = self.momentum_model.predict_twist(rest10, payload10, extra, span)
            else:
                rows, shared = groups
                payload = None if payload10 is None else payload10[rows]
                rest_twist = self.momentum_model.predict_twist(
                    rest10[rows], payload, None if extra is None else extra[rows], span
                )[shared]
            composite = self.momentum_model.mean_composite10(base10, payload10)
            relative, moved = self.slosh.momentum(rest_twist, theta_slosh, tank_m, composite, self.context)
            carried = -relative if extra is None else extra - relative
            twist = self.momentum_model.predict_twist(base10, payload10, carried, span, moved)
        return np.ascontiguousarray(twist[..., 3:])


def _groups(keys: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
    """Rows of ``keys`` (P, n) that are equal: the first of each group (G,) and each row's group (P,); ``None`` when
    every row is different."""
    first: dict[bytes, int] = {}
    rows, shared = [], []
    for i, row in enumerate(np.ascontiguousarray(keys)):
        group = first.setdefault(row.tobytes(), len(rows))
        if group == len(rows):
            rows.append(i)
        shared.append(group)
    return None if len(rows) == len(keys) else (np.array(rows), np.array(shared))
