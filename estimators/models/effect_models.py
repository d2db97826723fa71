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
  - ``slosh``: a point mass ``m_s`` on an isotropic spring-damper (``f``, ``zeta``) at the tank,
    driven by the tank's inertial acceleration; its momentum relative to the base is taken from the
    rigid bodies (see :class:`Slosh`);

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
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimators.models.fractional_delay import delay_samples
from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects import remaining_liquid_kg
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.physics.inertia import PARAMS10_NAMES, RigidBodyInertia, skew, spatial_inertia_matrix
from spaceid_gym.robots import Robot
from spaceid_gym.sim.lie import matrix_from_quat, so3_exp
from spaceid_gym.specs import parse_setting, split_outside_brackets

#: the base rate (rad/s) that sets the momentum search range: 5 deg/s, a tumbling satellite (a detumbled one
#: keeps 0.01-0.05 deg/s)
MAX_BASE_RATE_RAD_S = math.radians(5.0)

#: the window over which the largest torque searched brings that momentum, s
TORQUE_RANGE_WINDOW_S = 60.0

#: the largest gyro-to-encoder delay searched, s (a badly synchronised data bus, far beyond 10-40 ms)
MAX_DELAY_S = 2.0


def momentum_range_nms(robot: Robot) -> float:
    """``MAX_BASE_RATE_RAD_S`` times the full-tank base's largest principal moment of inertia, N m s."""
    inertia = np.asarray(robot.base_full.inertia_com_kgm2, dtype=float)
    return float(MAX_BASE_RATE_RAD_S * np.linalg.eigvalsh(0.5 * (inertia + inertia.T))[-1])


@dataclass(frozen=True)
class EffectContext:
    """What the effect terms need from the log and the robot.

    Attributes:
        t_s: sample times from the first sample (T,), s.
        rot_rel: base attitude relative to the first sample, ``R(t0)^T R(t)`` (T, 3, 3).
        attitude_source: ``"quaternion"`` (logged) or ``"integrated gyro"``.
    """

    t_s: FloatArray
    rot_rel: FloatArray
    attitude_source: str

    @classmethod
    def from_log(cls, log: MeasurementLog) -> EffectContext:
        """The context of ``log`` (attitude from its quaternions, else from its gyro)."""
        t = np.asarray(log.t_s, dtype=float) - float(log.t_s[0])
        if log.quat_base_to_inertial_wxyz is not None:
            rot = np.stack([matrix_from_quat(qt) for qt in log.quat_base_to_inertial_wxyz])
            rot_rel = np.einsum("ji,tjk->tik", rot[0], rot)
            source = "quaternion"
        else:
            rot_rel = _integrate_attitude(t, np.asarray(log.omega_base_body_rad_s, dtype=float))
            source = "integrated gyro"
        return cls(t, rot_rel, source)


def _integrate_attitude(t_s: FloatArray, omega_body: FloatArray) -> FloatArray:
    """``R_rel`` (T, 3, 3) from body rates (T, 3) by the midpoint rule on SO(3)."""
    rot = np.empty((len(t_s), 3, 3))
    rot[0] = np.eye(3)
    for k in range(1, len(t_s)):
        rot[k] = rot[k - 1] @ so3_exp(0.5 * (omega_body[k - 1] + omega_body[k]) * (t_s[k] - t_s[k - 1]))
    return rot


class EffectTerm(ABC):
    """One effect: its unknowns and how it changes the prediction (see the module docstring).

    Attributes:
        name: the catalogue name.
        names: its unknowns with units (k_e,); ``nominal`` (switches the effect off), ``lower``, ``upper`` (k_e,),
            the search range; ``scale`` (k_e,), the size expected in flight, which scales the unknowns in a fit.
        stage: ``"body"``, ``"momentum"``, ``"slosh"`` or ``"measurement"``: where it acts.
    """

    name: ClassVar[str]
    stage: ClassVar[str]
    names: tuple[str, ...]
    #: effects this one contains as a special case (nested models)
    nests: ClassVar[tuple[str, ...]] = ()
    #: the ``hidden_effects`` fields of ``truth.json`` (:mod:`spaceid_gym.effects`) that hold this term's unknowns,
    #: in order, each with its number of values (see :meth:`from_truth`)
    truth_fields: tuple[tuple[str, int], ...]

    def __init__(self, nominal: FloatArray, lower: FloatArray, upper: FloatArray, scale: FloatArray | None = None) -> None:
        self.nominal = np.asarray(nominal, dtype=float)
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.scale = (
            self.upper - self.lower if scale is None else np.broadcast_to(np.asarray(scale, dtype=float), self.nominal.shape)
        )

    @property
    def n_params(self) -> int:
        """k_e."""
        return len(self.names)

    @property
    def spec(self) -> str:
        """The term as :func:`parse_effects` reads it (its name, with options if any)."""
        return self.name

    def starts(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """Starting points (k_e,) for a local fit of this term from a fit without it whose base parameters are
        ``theta_base`` (k_base,) (default: the nominal)."""
        return [self.nominal.copy()]

    def grid(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """Candidate starts (k_e,) to score in one batched evaluation, the best of which start the local fits;
        by default :meth:`starts` (a term whose cost is multimodal offers a scan)."""
        return self.starts(theta_base)

    def from_truth(self, hidden: Mapping[str, Any]) -> FloatArray:
        """This term's unknowns (k_e,) in a simulated truth: ``hidden`` is ``truth.json``'s ``hidden_effects``.

        Each of :attr:`truth_fields` is flattened (row-major) into its place; a field the truth does not have
        is off there (its part of the nominal), as is the whole term for a log without the effect.
        """
        theta, offset = self.nominal.copy(), 0
        for field, size in self.truth_fields:
            if field in hidden:
                value = np.ravel(np.asarray(hidden[field], dtype=float))
                if value.size != size:
                    raise SpaceIdInputError(
                        f"hidden_effects: {field} has {value.size} values, the {self.name} term expects {size}"
                    )
                theta[offset : offset + size] = value
            offset += size
        return theta

    @abstractmethod
    def physical(self, theta: FloatArray) -> dict[str, Any]:
        """The fitted effect as physical quantities at ``theta`` (k_e,) (keys as in ``truth.json``'s ``hidden_effects``)."""

    def implausible(
        self, theta: FloatArray, covariance: FloatArray | None = None, theta_base: FloatArray | None = None
    ) -> list[str]:
        """Reasons why ``theta`` (k_e,) is not physically plausible (empty if it is); none by default.

        Only physics counts, never the search range. ``covariance`` (k_e, k_e), the fit's Cramér-Rao covariance,
        lets a term allow for the uncertainty of its test (a barely informed inertia can be slightly unphysical by
        noise alone); ``theta_base`` (k_base,), the base parameters of the same fit, lets a term check against
        them (the slosh's liquid).
        """
        return []


class _VectorTerm(EffectTerm):
    """A 3-vector effect, nominal zero, symmetric range ``+-bound``."""

    unit: ClassVar[str]
    bound: ClassVar[float]
    prefix: ClassVar[str]

    #: the size expected in flight (see :attr:`EffectTerm.scale`)
    typical: ClassVar[float]

    def __init__(self, robot: Robot) -> None:
        self.names = tuple(f"{self.prefix}_{axis}_{self.unit}" for axis in "xyz")
        self.truth_fields = ((f"{self.name}_{self.unit}", 3),)
        bound = self.range_of(robot)
        super().__init__(np.zeros(3), -np.full(3, bound), np.full(3, bound), np.full(3, self.typical))

    @classmethod
    def range_of(cls, robot: Robot) -> float:
        """The search range ``+-bound`` of each component."""
        return cls.bound

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        return {f"{self.name}_{self.unit}": np.asarray(theta, dtype=float).copy()}


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


@njit(cache=True)
def _in_base_axes(rot_rel: FloatArray, vectors: FloatArray) -> FloatArray:
    """``R_rel(t)^T v`` (P, T, 3) for ``R_rel`` (T, 3, 3) and vectors in the first sample's axes (P, T, 3), or (P, 1, 3)
    for the same vector at every sample. The products are summed in the order of the ``einsum`` this replaces (bit
    for bit the same)."""
    n_p, n_t = vectors.shape[0], rot_rel.shape[0]
    out = np.empty((n_p, n_t, 3))
    for p in range(n_p):
        for t in range(n_t):
            s = t if vectors.shape[1] > 1 else 0
            v0, v1, v2 = vectors[p, s, 0], vectors[p, s, 1], vectors[p, s, 2]
            for i in range(3):
                out[p, t, i] = (rot_rel[t, 0, i] * v0 + rot_rel[t, 1, i] * v1) + rot_rel[t, 2, i] * v2
    return out


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


class Delay(EffectTerm):
    """``d`` (1,), s: the gyro reads the rate at ``t - d``; range ``+-`` :data:`MAX_DELAY_S`, typical size 0.1 s.

    The prediction is delayed by an all-pass phase ramp (:func:`~estimators.models.fractional_delay.delay_samples`),
    not by interpolation between samples: an interpolator also smooths the white noise the prediction carries from
    the joint-rate sensors, and a fit would take that smoothing for a delay of a fraction of a sample. Before the
    first sample the rate is held at its first value (a log that starts at rest).
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
        return delay_samples(omega, theta[:, 0] / dt)

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        return {"delay_s": float(theta[0])}


#: the payload's search range: mass up to this fraction of the robot's (base full of fuel and arm)
PAYLOAD_MAX_FRACTION_OF_ROBOT = 1.0

#: the payload's search range: first moments and inertias of an object up to this size, m
PAYLOAD_SIZE_M = 1.0

#: the masses of the payload's grid of starts, as fractions of the arm's mass
PAYLOAD_GRID_ARM_FRACTIONS = (0.05, 0.2, 0.5, 1.0, 2.0, 4.0)


#: the payload's unknowns: its params10 (pinocchio order) about the last joint's origin, in its frame
PAYLOAD_NAMES = tuple(f"payload_{n}" for n in PARAMS10_NAMES)

#: the size (m) of the typical payload that scales the fits: an object as heavy as the arm and this size across
TYPICAL_PAYLOAD_SIZE_M = 0.5


def payload_box(payload_max_kg: float, payload_size_m: float) -> tuple[FloatArray, FloatArray]:
    """The search box (lower, upper), each (10,), of a payload's params10 up to ``payload_max_kg`` and ``payload_size_m``.

    Mass in ``[0, m]``; first moments within ``+-m s`` (kg m); diagonal inertia in ``[0, 2 m s^2]`` and off-diagonal
    within ``+-m s^2`` (kg m^2), with ``m = payload_max_kg`` and ``s = payload_size_m``.
    """
    m_max, size = float(payload_max_kg), float(payload_size_m)
    if not (np.isfinite(m_max) and m_max > 0.0 and np.isfinite(size) and size > 0.0):
        raise SpaceIdInputError("payload parameters: payload_max_kg and payload_size_m must be positive numbers")
    h, j = m_max * size, m_max * size**2
    return np.array([0.0, -h, -h, -h, 0.0, -j, 0.0, -j, -j, 0.0]), np.array([m_max, h, h, h, 2 * j, j, 2 * j, j, j, 2 * j])


class Payload(EffectTerm):
    """10 inertial parameters of an object held by the last link (about the last joint's origin, its frame).

    Search range: a mass up to the whole robot's (:data:`PAYLOAD_MAX_FRACTION_OF_ROBOT` of base and arm: the arm may
    hold a captured satellite as heavy as its own), first moments and inertia entries for an object up to
    :data:`PAYLOAD_SIZE_M` across (the box of :class:`~estimators.parameters.PayloadParameters` for that mass and
    size). The typical size, which scales the local fits, is that of an object as heavy as the arm and 0.5 m across
    (the payload parameterisation's default box). The fit's starts scan masses of :data:`PAYLOAD_GRID_ARM_FRACTIONS`
    of the arm's mass (:meth:`grid`): one light start does not reach a payload heavier than the arm.
    """

    name = "payload"
    stage = "body"

    def __init__(self, robot: Robot) -> None:
        self.arm_mass_kg = robot.arm_mass_kg()
        robot_kg = robot.base_full.mass_kg + self.arm_mass_kg
        lower, upper = payload_box(PAYLOAD_MAX_FRACTION_OF_ROBOT * robot_kg, PAYLOAD_SIZE_M)
        typical_lower, typical_upper = payload_box(self.arm_mass_kg, TYPICAL_PAYLOAD_SIZE_M)
        self.names = PAYLOAD_NAMES
        self.truth_fields = (("payload_params10", 10),)
        super().__init__(np.zeros(10), lower, upper, typical_upper - typical_lower)

    def starts(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """A light compact object at the last joint (a zero mass sits on the bound, where the rest has no effect)."""
        return [self._compact(0.05 * self.arm_mass_kg)]

    def grid(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """Compact objects at the last joint of :data:`PAYLOAD_GRID_ARM_FRACTIONS` of the arm's mass."""
        return [self._compact(fraction * self.arm_mass_kg) for fraction in PAYLOAD_GRID_ARM_FRACTIONS]

    @staticmethod
    def _compact(mass_kg: float) -> FloatArray:
        """A compact object (radius of gyration 5 cm) of ``mass_kg`` at the last joint's origin (10,)."""
        start = np.zeros(10)
        start[0] = mass_kg
        start[[4, 6, 9]] = mass_kg * 0.05**2
        return start

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        out: dict[str, Any] = {"payload_mass_kg": float(theta[0])}
        if theta[0] > 0.0:
            body = RigidBodyInertia.from_params10(theta)
            out.update(payload_com_m=body.com_m, payload_inertia_kgm2=body.inertia_com_kgm2)
        return out

    def implausible(
        self, theta: FloatArray, covariance: FloatArray | None = None, theta_base: FloatArray | None = None
    ) -> list[str]:
        """Besides the bounds: the mass must be positive and the pseudo-inertia positive definite, each beyond
        3 standard deviations of its estimate when ``covariance`` is given (a small object's inertia is barely
        informed, and noise alone can make its estimate slightly unphysical)."""
        # mass >= 0 is the physics below
        reasons = [r for r in super().implausible(theta, covariance) if not r.startswith(self.names[0])]
        cov = np.zeros((10, 10)) if covariance is None else covariance
        if theta[0] <= -3.0 * np.sqrt(max(cov[0, 0], 0.0)) or theta[0] == 0.0:
            return [*reasons, f"payload mass {theta[0]:.3g} kg is not positive"]
        eigenvalues, vectors = np.linalg.eigh(_pseudo_inertia(theta))
        v = vectors[:, 0]
        # d lambda_min / d params10 = v^T (d J / d params10) v (J is linear in the parameters)
        gradient = np.array([v @ _pseudo_inertia(e) @ v for e in np.eye(10)])
        std = float(np.sqrt(max(gradient @ cov @ gradient, 0.0)))
        if eigenvalues[0] < -3.0 * std or (covariance is None and eigenvalues[0] <= 0.0):
            reasons.append(
                f"payload inertia is not that of a physical body (pseudo-inertia eigenvalue {eigenvalues[0]:.3g}, std {std:.2g})"
            )
        return reasons


def _pseudo_inertia(params10: FloatArray) -> FloatArray:
    """4x4 pseudo-inertia ``[[tr(I)/2 E - I, h], [h^T, m]]``: positive definite iff the parameters are a physical body."""
    m, h = params10[0], params10[1:4]
    xx, xy, yy, xz, yz, zz = params10[4:10]
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    out = np.empty((4, 4))
    out[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    out[:3, 3] = out[3, :3] = h
    out[3, 3] = m
    return out


class Slosh(EffectTerm):
    """``[m_s kg, f Hz, zeta]``: part of the liquid moves as a point mass on an isotropic spring-damper at the tank.

    Equivalent-mechanical model of the first slosh mode (Abramson, NASA SP-106; Dodge 2000). The mass sits
    at the tank ``r`` (base frame; from the fuel parameters, else the full-tank CoM) when at rest and is
    part of the rigid base there; its displacement ``x`` (base axes) obeys
    ``x'' = -A (k x + c x') - a_tank(t)`` with ``k = m_s w^2``, ``c = 2 zeta m_s w``, ``w = 2 pi f``, driven by the
    tank's inertial acceleration ``a_tank = dv/dt + omega x v + domega/dt x r + omega x (omega x r)`` (base axes)
    of the prediction without the slosh mass (the rest of the robot); ``A = E / m_s + Lambda^-1`` because the spring force also pushes the rest of the
    robot (``Lambda^-1``: its inverse operational mass at the tank, from the log's mean composite), which raises
    the relative frequency above ``f`` (the mass's frequency against a fixed wall).
    Its momentum relative to the base, ``[m_s x'; m_s (r + x) x x']``, is then carried by the rest, the
    displaced mass changes the composite's first moment and inertia (a point mass at ``r + x`` instead of
    ``r``), and the prediction is made again with both. Neglected: Coriolis on ``x'``, the coupling's change
    with the arm's configuration, and the slosh's feedback on its own forcing beyond ``Lambda^-1``.
    Integrated with RK4 at the log's sample period, starting at rest.

    Ranges: ``m_s`` in ``[0, usable fuel]``, ``f`` in ``[0.02, 2]`` Hz (periods 0.5-50 s: the first lateral mode of
    tanks from 0.1 m to several metres, whichever equivalent model, pendulum or spring-mass, describes it),
    ``zeta`` in ``[0.001, 1]``; nominal ``m_s = 0`` (off). The cost is multimodal in the frequency: :meth:`grid`
    offers a log-spaced scan of the whole band to choose the local fits' starts from. Only liquid still in the tank can slosh: ``liquid_of`` gives it for the base parameters
    (with the fuel parameters, the usable fuel minus the fuel consumed; else the usable fuel). A larger ``m_s``
    moves only the liquid there is (:meth:`moving_part`; the prediction is flat in ``m_s`` beyond it) and such a
    fit is implausible: subtracting more than the liquid from the base leaves a "rest" that is not a body, whose
    coupling makes the oscillator unstable (the prediction overflowed before this limit).
    """

    name = "slosh"
    stage = "slosh"
    names = ("slosh_mass_kg", "slosh_frequency_hz", "slosh_damping_ratio")
    truth_fields = tuple((field, 1) for field in names)
    #: starting frequencies (Hz) of the local fits without a scan (:meth:`starts`)
    START_FREQUENCIES_HZ = (0.15, 0.3, 0.6)
    #: the scan of :meth:`grid`: frequencies (Hz, log-spaced over the search range) and sloshing fractions of the liquid
    GRID_FREQUENCIES_HZ = tuple(float(f) for f in np.geomspace(0.02, 2.0, 19))
    GRID_MASS_FRACTIONS = (0.05, 0.2, 0.5)

    def __init__(
        self,
        robot: Robot,
        tank_of: Callable[[FloatArray], FloatArray] | None = None,
        liquid_of: Callable[[FloatArray], FloatArray] | None = None,
    ) -> None:
        liquid_max_kg = float(remaining_liquid_kg(robot, 0.0))  # the usable fuel, as the simulator has it
        super().__init__(
            np.array([0.0, 0.3, 0.05]),
            np.array([0.0, 0.02, 0.001]),
            np.array([liquid_max_kg, 2.0, 1.0]),
            np.array([0.1 * liquid_max_kg, 0.3, 0.1]),
        )
        full_com = np.asarray(robot.base_full.com_m, dtype=float)
        self.tank_of = tank_of if tank_of is not None else (lambda theta_base: np.broadcast_to(full_com, (len(theta_base), 3)))
        self.liquid_of = liquid_of if liquid_of is not None else (lambda theta_base: np.full(len(theta_base), liquid_max_kg))

    def moving_part(self, theta: FloatArray, theta_base: FloatArray) -> FloatArray:
        """``theta`` (P, 3) with the slosh mass limited to the liquid left in the tank for ``theta_base`` (P, k_base)."""
        out = np.array(theta, dtype=float)
        out[:, 0] = np.minimum(out[:, 0], self.liquid_of(np.atleast_2d(theta_base)))
        return out

    def starts(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """One per :attr:`START_FREQUENCIES_HZ`, with a tenth of the usable fuel sloshing, or half the liquid left
        for ``theta_base`` if that is less: beyond the liquid left the prediction is flat in the mass, and a fit
        started there cannot find its way back."""
        mass = 0.1 * self.upper[0]
        if theta_base is not None:
            mass = min(mass, 0.5 * float(self.liquid_of(np.atleast_2d(theta_base))[0]))
        return [np.array([mass, f, 0.05]) for f in self.START_FREQUENCIES_HZ]

    def grid(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """:data:`GRID_FREQUENCIES_HZ` x :data:`GRID_MASS_FRACTIONS` of the liquid left for ``theta_base`` (or of the
        usable fuel), damping 0.05: candidates to score in one batched evaluation before the local fits."""
        liquid = self.upper[0] if theta_base is None else float(self.liquid_of(np.atleast_2d(theta_base))[0])
        return [np.array([fraction * liquid, f, 0.05]) for f in self.GRID_FREQUENCIES_HZ for fraction in self.GRID_MASS_FRACTIONS]

    def momentum(
        self, twist: FloatArray, theta: FloatArray, tank_m: FloatArray, composite10: FloatArray, context: EffectContext
    ) -> tuple[FloatArray, FloatArray]:
        """For rigid twists (P, T, 6): the slosh mass's momentum relative to the base, ``[P; L]`` about the base
        origin (P, T, 6), and the change of the composite's 10 parameters (P, T, 10) from its displacement.

        ``composite10`` (P, 10) is the robot's mean composite (base and arm, slosh mass included) over the log,
        whose inverse inertia at the tank couples the slosh back to the base.
        """
        omega_n = 2.0 * np.pi * theta[:, 1]
        rest = composite10 - _point_mass10(theta[:, 0], tank_m)
        coupling = np.eye(3) + theta[:, 0, None, None] * _inverse_mass_at(rest, tank_m)  # m_s A, finite at m_s = 0
        return _slosh_momentum(
            np.ascontiguousarray(twist),
            context.t_s,
            np.ascontiguousarray(tank_m),
            theta[:, 0],
            omega_n,
            theta[:, 2],
            np.ascontiguousarray(coupling),
        )

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        return {"slosh_mass_kg": float(theta[0]), "slosh_frequency_hz": float(theta[1]), "slosh_damping_ratio": float(theta[2])}

    def implausible(
        self, theta: FloatArray, covariance: FloatArray | None = None, theta_base: FloatArray | None = None
    ) -> list[str]:
        reasons = super().implausible(theta, covariance, theta_base)
        if theta[0] <= 0.0:
            reasons.append("slosh mass is zero")
        if theta_base is not None:
            liquid = float(self.liquid_of(np.atleast_2d(theta_base))[0])
            if theta[0] > liquid + 1e-6 * self.upper[0]:  # not for a fit on the cap by rounding
                reasons.append(f"slosh mass {theta[0]:.4g} kg exceeds the {liquid:.4g} kg of liquid left in the tank")
        return reasons


def _point_mass10(mass_kg: FloatArray, position_m: FloatArray) -> FloatArray:
    """10 parameters (P, 10) of point masses (P,) at positions (P, 3), about the origin."""
    x, y, z = position_m[:, 0], position_m[:, 1], position_m[:, 2]
    return mass_kg[:, None] * np.stack(
        (np.ones_like(x), x, y, z, y * y + z * z, -x * y, x * x + z * z, -x * z, -y * z, x * x + y * y), axis=1
    )


def _inverse_mass_at(params10: FloatArray, point_m: FloatArray) -> FloatArray:
    """Inverse operational mass (P, 3, 3) of bodies (P, 10) at points (P, 3): ``G M^-1 G^T``, ``G = [E, -[p]x]``."""
    inverse = np.linalg.inv(spatial_inertia_matrix(params10))  # (P, 6, 6), twist <- wrench, base origin
    g = np.zeros((len(point_m), 3, 6))
    g[:, :, :3] = np.eye(3)
    g[:, :, 3:] = -skew(point_m)
    return g @ inverse @ np.swapaxes(g, 1, 2)


@njit(cache=True, inline="always")
def _cross(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> tuple[float, float, float]:
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def _oscillator_slope(
    coupling: FloatArray,
    p: int,
    stiff: float,
    damp: float,
    point: FloatArray,
    force: FloatArray,
    row: int,
    slopes: FloatArray,
    s: int,
) -> None:
    """``slopes[s]`` = the derivative ``[x'; -A (stiff x + damp x') - f]`` of the slosh oscillator at ``point`` = ``[x; x']``
    (6,), with ``A = coupling[p]`` and the forcing ``f = force[row]`` (see :func:`_slosh_momentum`)."""
    s0 = stiff * point[0] + damp * point[3]
    s1 = stiff * point[1] + damp * point[4]
    s2 = stiff * point[2] + damp * point[5]
    for c in range(3):
        slopes[s, c] = point[3 + c]
        slopes[s, 3 + c] = -(coupling[p, c, 0] * s0 + coupling[p, c, 1] * s1 + coupling[p, c, 2] * s2) - force[row, c]


@njit(cache=True)
def _slosh_momentum(
    twist: FloatArray,
    t_s: FloatArray,
    tank: FloatArray,
    mass: FloatArray,
    omega_n: FloatArray,
    zeta: FloatArray,
    coupling: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """See :meth:`Slosh.momentum`; RK4 with the forcing linear between samples (each axis is the same scalar oscillator)."""
    n_p, n_t = twist.shape[0], twist.shape[1]
    out = np.zeros((n_p, n_t, 6))
    moved = np.zeros((n_p, n_t, 10))
    accel = np.empty((n_t, 3))
    # RK4 scratch: the state [x; x'], the point of a stage, the four slopes, the forcing at a step's start/middle/end
    state, stage, slopes, force = np.empty(6), np.empty(6), np.empty((4, 6)), np.empty((3, 3))
    for p in range(n_p):
        rx, ry, rz = tank[p, 0], tank[p, 1], tank[p, 2]
        # tank acceleration (base axes) from the twist, derivatives by central differences
        for k in range(n_t):
            lo, hi = max(k - 1, 0), min(k + 1, n_t - 1)
            inv = 1.0 / (t_s[hi] - t_s[lo])
            vx, vy, vz, wx, wy, wz = (
                twist[p, k, 0],
                twist[p, k, 1],
                twist[p, k, 2],
                twist[p, k, 3],
                twist[p, k, 4],
                twist[p, k, 5],
            )
            dwx = (twist[p, hi, 3] - twist[p, lo, 3]) * inv
            dwy = (twist[p, hi, 4] - twist[p, lo, 4]) * inv
            dwz = (twist[p, hi, 5] - twist[p, lo, 5]) * inv
            a1 = _cross(wx, wy, wz, vx, vy, vz)
            a2 = _cross(dwx, dwy, dwz, rx, ry, rz)
            wr = _cross(wx, wy, wz, rx, ry, rz)
            a3 = _cross(wx, wy, wz, wr[0], wr[1], wr[2])
            for c in range(3):
                accel[k, c] = (twist[p, hi, c] - twist[p, lo, c]) * inv + a1[c] + a2[c] + a3[c]
        # x'' = -A (k x + c x') - a_tank: the spring-damper force F also accelerates the rest of the robot at
        # the tank, by Lambda^-1 F, so the relative motion sees the inverse mass A = E / m_s + Lambda^-1;
        # with k = m_s w^2 and c = 2 zeta m_s w: A (k x + c x') = (E + m_s Lambda^-1) (w^2 x + 2 zeta w x')
        stiff, damp = omega_n[p] ** 2, 2.0 * zeta[p] * omega_n[p]
        state[:] = 0.0
        out[p, 0, :] = 0.0
        for k in range(1, n_t):
            h = t_s[k] - t_s[k - 1]
            for c in range(3):  # the forcing at the step's start, middle and end
                force[0, c], force[2, c] = accel[k - 1, c], accel[k, c]
                force[1, c] = 0.5 * (force[0, c] + force[2, c])
            _oscillator_slope(coupling, p, stiff, damp, state, force, 0, slopes, 0)
            for s in range(1, 4):
                fraction = 1.0 if s == 3 else 0.5
                for i in range(6):
                    stage[i] = state[i] + fraction * h * slopes[s - 1, i]
                _oscillator_slope(coupling, p, stiff, damp, stage, force, 1 if s < 3 else 2, slopes, s)
            for i in range(6):
                state[i] = state[i] + (h / 6.0) * (slopes[0, i] + 2.0 * slopes[1, i] + 2.0 * slopes[2, i] + slopes[3, i])
                out[p, k, i] = state[i]  # displacement and its rate for now; momentum below
        for k in range(n_t):
            x0, x1, x2_ = out[p, k, 0], out[p, k, 1], out[p, k, 2]
            v0, v1, v2_ = out[p, k, 3], out[p, k, 4], out[p, k, 5]
            ang = _cross(rx + x0, ry + x1, rz + x2_, v0, v1, v2_)
            m = mass[p]
            out[p, k, 0], out[p, k, 1], out[p, k, 2] = m * v0, m * v1, m * v2_
            out[p, k, 3], out[p, k, 4], out[p, k, 5] = m * ang[0], m * ang[1], m * ang[2]
            # point mass at r + x instead of r: first moment and inertia about the origin (xx, xy, yy, xz, yz, zz)
            px, py, pz = rx + x0, ry + x1, rz + x2_
            moved[p, k, 1], moved[p, k, 2], moved[p, k, 3] = m * x0, m * x1, m * x2_
            moved[p, k, 4] = m * ((py * py + pz * pz) - (ry * ry + rz * rz))
            moved[p, k, 5] = -m * (px * py - rx * ry)
            moved[p, k, 6] = m * ((px * px + pz * pz) - (rx * rx + rz * rz))
            moved[p, k, 7] = -m * (px * pz - rx * rz)
            moved[p, k, 8] = -m * (py * pz - ry * rz)
            moved[p, k, 9] = m * ((px * px + py * py) - (rx * rx + ry * ry))
    return out, moved


#: the catalogue: effect name -> term class
EFFECT_TERMS: dict[str, type[EffectTerm]] = {
    cls.name: cls for cls in (InitialMomentum, GyroBias, GyroScale, Payload, Slosh, Delay, ExternalTorque)
}

#: the order in which measurement effects apply: ``(I + E) omega(t - d) + b``
_MEASUREMENT_ORDER = ("delay", "gyro_scale", "gyro_bias")


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
            key, eq, value = pair.partition("=")
            if not eq or key.strip() != "drift" or name != "external_torque":
                raise SpaceIdInputError(f"effects: {item!r}: the only option is external_torque[drift=true|false]")
            if value.strip().lower() not in ("true", "false"):
                raise SpaceIdInputError(f"effects: {item!r}: drift must be true or false")
            options["drift"] = value.strip().lower() == "true"
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
            terms.append(Slosh(robot, tank_of, liquid_of))
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
        keys = np.hstack([base10, *([] if payload10 is None else [payload10]), *rotating, theta_base])
        first: dict[bytes, int] = {}
        rows, shared = [], []
        for i, row in enumerate(keys):
            group = first.setdefault(row.tobytes(), len(rows))
            if group == len(rows):
                rows.append(i)
            shared.append(group)
        return None if len(rows) == len(keys) else (np.array(rows), np.array(shared))

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
            rest_twist = self.momentum_model.predict_twist(rest10, payload10, extra, span)
            composite = self.momentum_model.mean_composite10(base10, payload10)
            relative, moved = self.slosh.momentum(rest_twist, theta_slosh, tank_m, composite, self.context)
            carried = -relative if extra is None else extra - relative
            twist = self.momentum_model.predict_twist(base10, payload10, carried, span, moved)
        return np.ascontiguousarray(twist[..., 3:])
