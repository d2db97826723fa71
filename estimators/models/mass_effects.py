"""The effect terms of extra masses: a payload held by the last link (its 10 inertial parameters) and fuel that
sloshes in the tank (a point mass on a spring-damper). The catalogue: :mod:`estimators.models.effect_models`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from estimators.models.effect_base import EffectContext, EffectTerm
from estimators.models.slosh_dynamics import slosh_momentum
from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.draws import remaining_liquid_kg
from spaceid_gym.effects.settings import SLOSH_MODELS
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import PARAMS10_NAMES, RigidBodyInertia, skew, spatial_inertia_matrix
from spaceid_gym.robots import Robot

#: how close to its lower bound, in units of its scale, a slosh mass is taken for none (:meth:`Slosh.switched_off`)
OFF_TOLERANCE = 1e-9

#: the pendulum's search range of the rod's curvature, 1/m: rods from 5 cm, the hinge on either side of the mass
ROD_CURVATURE_MAX = 20.0

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
    """``[m_s kg, f Hz, zeta]``: part of the liquid moves as a point mass on a spring-damper or a pendulum at the tank.

    Equivalent-mechanical model of the first slosh mode (Abramson, NASA SP-106; Dodge 2000). The mass sits
    at the tank ``r`` (base frame; from the fuel parameters, else the full-tank CoM) when at rest and is
    part of the rigid base there; its displacement ``x`` (base axes) follows the equations of motion of
    :mod:`estimators.models.slosh_dynamics`: a spring ``k = m_s w^2``, damper ``c = 2 zeta m_s w``, ``w = 2 pi f``,
    driven by the tank's inertial acceleration from the prediction without the slosh mass (the rest of the robot) and
    by the rotating base frame's Coriolis, Euler and centripetal terms on ``x`` (without them a 40 s slosh left 5 % of
    its effect unexplained on a noise-free log). The force on the mass also pushes the rest of the robot
    (``Lambda^-1``: its inverse operational mass at the tank, from the log's mean composite), which raises the relative
    frequency above ``f`` (the mass's frequency against a fixed wall). Its momentum relative to the base, ``[m_s x';
    m_s (r + x) x x']``, is then carried by the rest, the displaced mass changes the composite's first moment and
    inertia (a point mass at ``r + x`` instead of ``r``), and the prediction is made again with both. Neglected: the
    coupling's change with the arm's configuration, and the slosh's feedback on its own forcing beyond ``Lambda^-1``.

    Two equivalent mechanical models (Abramson, NASA SP-106, ch. 6), ``model=``: ``"spring"`` (the default; the mass
    moves in every direction) and ``"pendulum"`` (``slosh[model=pendulum]``: a mass on a rod, three more unknowns: its
    direction at rest ``slosh_axis_azimuth_rad`` and ``slosh_axis_elevation_rad`` (base frame) and its signed curvature
    ``slosh_rod_curvature_per_m`` = 1 / rod length, the hinge at ``r - a / kappa``: the rod keeps the mass on a sphere,
    and ``kappa = 0`` is the small-angle limit, the mass moving in the plane normal to the rod). Their small lateral
    motions are the same; they differ in what the rod does: it carries the mass with the base along it, and beyond
    small angles it pulls the mass back along itself (a 0.1 m rod swinging 25 degrees: a quarter of the effect on a
    noise-free log). :func:`~estimators.diagnostics.diagnose.diagnose` fits both and names ``slosh`` with the better.

    Ranges: ``m_s`` in ``[0, usable fuel]``, ``f`` in ``[0.02, 2]`` Hz (periods 0.5-50 s: the first lateral mode of
    tanks from 0.1 m to several metres, whichever equivalent model, pendulum or spring-mass, describes it),
    ``zeta`` in ``[0.001, 1]``, ``kappa`` in ``[-ROD_CURVATURE_MAX, ROD_CURVATURE_MAX]`` (rods from 5 cm; the sign
    says on which side of the mass the hinge is); nominal ``m_s = 0`` (off). The cost is multimodal in the
    frequency: :meth:`grid` offers a log-spaced scan of the whole band to choose the local fits' starts from. Only
    liquid still in the tank can slosh: ``liquid_of`` gives it for the base parameters (with the fuel parameters, the
    usable fuel minus the fuel consumed; else the usable fuel). A larger ``m_s`` moves only the liquid there is
    (:meth:`moving_part`; the prediction is flat in ``m_s`` beyond it, so a fit there is reported as all the liquid
    sloshing, :meth:`equivalent`): subtracting more than the liquid from the base would leave a "rest" that is not a
    body, whose coupling makes the oscillator unstable (the prediction overflowed before this limit).
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
    #: the liquid left, as a fraction of the usable fuel, below which :meth:`grid` scans no masses (they would be below
    #: 0.05 % of the usable fuel)
    GRID_MIN_LIQUID_FRACTION = 0.01
    #: the pendulum's rod directions of the scan (azimuth, elevation; rad): the base's z, x and y axes and the four
    #: diagonals of its octants (a direction and its opposite are one rod)
    GRID_AXES = (
        (0.0, 0.5 * math.pi),
        (0.0, 0.0),
        (0.5 * math.pi, 0.0),
        *((az, math.atan(1.0 / math.sqrt(2.0))) for az in (0.25 * math.pi, 0.75 * math.pi, -0.75 * math.pi, -0.25 * math.pi)),
    )
    #: the finer set of :meth:`grid_from_variant`: those seven and the six diagonals of the base's faces
    FINE_AXES = (
        *GRID_AXES,
        *((az, 0.0) for az in (0.25 * math.pi, -0.25 * math.pi)),
        *((az, el) for az in (0.0, 0.5 * math.pi) for el in (0.25 * math.pi, -0.25 * math.pi)),
    )

    def __init__(
        self,
        robot: Robot,
        tank_of: Callable[[FloatArray], FloatArray] | None = None,
        liquid_of: Callable[[FloatArray], FloatArray] | None = None,
        model: str = "spring",
    ) -> None:
        if model not in SLOSH_MODELS:
            raise SpaceIdInputError(f"effects: slosh model {model!r} unknown; expected one of {', '.join(SLOSH_MODELS)}")
        self.model = model
        liquid_max_kg = float(remaining_liquid_kg(robot, 0.0))  # the usable fuel, as the simulator has it
        nominal, lower = [0.0, 0.3, 0.05], [0.0, 0.02, 0.001]
        upper, scale = [liquid_max_kg, 2.0, 1.0], [0.1 * liquid_max_kg, 0.3, 0.1]
        if model == "pendulum":
            # the rod's direction: periodic angles, searched over two turns so that no fit stops on a wall
            self.names = (*Slosh.names, "slosh_axis_azimuth_rad", "slosh_axis_elevation_rad", "slosh_rod_curvature_per_m")
            self.truth_fields = (*Slosh.truth_fields, ("slosh_axis", 3), ("slosh_length_m", 1))
            nominal, lower = [*nominal, 0.0, 0.5 * math.pi, 0.0], [*lower, -2.0 * math.pi, -math.pi, -ROD_CURVATURE_MAX]
            upper, scale = [*upper, 2.0 * math.pi, math.pi, ROD_CURVATURE_MAX], [*scale, 0.5, 0.5, 1.0]
        super().__init__(np.array(nominal), np.array(lower), np.array(upper), np.array(scale))
        full_com = np.asarray(robot.base_full.com_m, dtype=float)
        self.tank_of = tank_of if tank_of is not None else (lambda theta_base: np.broadcast_to(full_com, (len(theta_base), 3)))
        self.liquid_of = liquid_of if liquid_of is not None else (lambda theta_base: np.full(len(theta_base), liquid_max_kg))

    @property
    def spec(self) -> str:
        return self.name if self.model == "spring" else f"{self.name}[model={self.model}]"

    def from_truth(self, hidden: Mapping[str, Any]) -> FloatArray:
        """As :meth:`EffectTerm.from_truth`; the pendulum's axis (a unit vector in the truth) as its two angles and its
        rod length as the curvature ``1 / L``, and a spring truth read by the pendulum term with a straight rod
        (``kappa = 0``) along the nominal axis (and vice versa, the rod dropped)."""
        theta = self.nominal.copy()
        for i, field in enumerate(Slosh.names):
            if field in hidden:
                theta[i] = float(hidden[field])
        if self.has_rod and hidden.get("slosh_axis") is not None:
            axis = np.ravel(np.asarray(hidden["slosh_axis"], dtype=float))
            if axis.size != 3 or not np.linalg.norm(axis) > 0.0:
                raise SpaceIdInputError(f"hidden_effects: slosh_axis expected a non-zero 3-vector, got {hidden['slosh_axis']!r}")
            axis = axis / np.linalg.norm(axis)
            theta[3:5] = math.atan2(axis[1], axis[0]), math.asin(float(np.clip(axis[2], -1.0, 1.0)))
        if self.has_rod and hidden.get("slosh_length_m") is not None:
            length_m = float(hidden["slosh_length_m"])
            if not length_m > 0.0:
                raise SpaceIdInputError(f"hidden_effects: slosh_length_m expected > 0 m, got {hidden['slosh_length_m']!r}")
            theta[5] = 1.0 / length_m
        return theta

    def describes(self, hidden: Mapping[str, Any]) -> bool:
        """Whether the truth's ``slosh_model`` (unset: the spring) is this term's."""
        return (hidden.get("slosh_model") or "spring") == self.model

    def rod(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The pendulum's rod for ``theta`` (P, k_e): its unit axis at rest ``a = [cos el cos az, cos el sin az, sin
        el]`` (P, 3), base axes, and curvature (P,) 1/m; for the spring (no rod) ``+z`` and 0, unused."""
        if not self.has_rod:
            return np.tile([0.0, 0.0, 1.0], (len(theta), 1)), np.zeros(len(theta))
        return rod_axis(theta[:, 3], theta[:, 4]), np.array(theta[:, 5], dtype=float)

    def moving_part(self, theta: FloatArray, theta_base: FloatArray) -> FloatArray:
        """``theta`` (P, k_e) with the slosh mass limited to the liquid left in the tank for ``theta_base`` (P, k_base)."""
        out = np.array(theta, dtype=float)
        out[:, 0] = np.minimum(out[:, 0], self.liquid_of(np.atleast_2d(theta_base)))
        return out

    equivalent = moving_part  # a mass beyond the liquid left moves only that liquid: the same prediction

    def switched_off(self, theta: FloatArray) -> bool:
        """No slosh mass (its lower bound, 0 kg, to :data:`OFF_TOLERANCE` of its scale: a bounded least-squares fit
        stops strictly inside its box, 5e-13 kg): the frequency, damping and rod then move nothing."""
        return bool(theta[0] <= self.lower[0] + OFF_TOLERANCE * self.scale[0])

    def starts(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """One per :attr:`START_FREQUENCIES_HZ`, with a tenth of the usable fuel sloshing, or half the liquid left
        for ``theta_base`` if that is less: beyond the liquid left the prediction is flat in the mass, and a fit
        started there cannot find its way back."""
        mass = 0.1 * self.upper[0]
        if theta_base is not None:
            mass = min(mass, 0.5 * float(self.liquid_of(np.atleast_2d(theta_base))[0]))
        return [np.array([mass, f, 0.05, *self.GRID_AXES[0], 0.0][: self.n_params]) for f in self.START_FREQUENCIES_HZ]

    def grid(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """:data:`GRID_FREQUENCIES_HZ` x :data:`GRID_MASS_FRACTIONS` of the liquid left for ``theta_base`` (or of the
        usable fuel), damping 0.05: candidates to score in one batched evaluation before the local fits. None where
        ``theta_base`` leaves less than :data:`GRID_MIN_LIQUID_FRACTION` of the usable fuel: every candidate there
        would be all but the fit without slosh (a missing slosh can drag a fit to the fuel bound, held-out 9500)."""
        liquid = self.upper[0] if theta_base is None else float(self.liquid_of(np.atleast_2d(theta_base))[0])
        if liquid < self.GRID_MIN_LIQUID_FRACTION * self.upper[0]:
            return []
        axes = tuple((*axis, 0.0) for axis in self.GRID_AXES) if self.has_rod else ((),)
        return [
            np.array([fraction * liquid, f, 0.05, *axis])
            for f in self.GRID_FREQUENCIES_HZ
            for fraction in self.GRID_MASS_FRACTIONS
            for axis in axes
        ]

    def grid_from_variant(self, fitted: FloatArray) -> list[FloatArray]:
        """The pendulum's candidates (6,) with the mass, frequency and damping of ``fitted`` (the first three values: a
        fit of the other slosh model, whose small lateral motions are the same) and a straight rod along each of
        :data:`FINE_AXES`; none for the spring. They add to the pendulum's own scan (:meth:`grid`), not stand for it:
        the spring also moves the mass along the rod, and its best scanned masses and frequencies were not the
        pendulum's on fresh log 10755 (a 37 s pendulum, the rod tilted; see the diagnosis's candidate fits,
        ``estimators/diagnostics/diagnose.py``)."""
        if not self.has_rod:
            return []
        return [np.array([*np.asarray(fitted, dtype=float)[:3], *axis, 0.0]) for axis in self.FINE_AXES]

    def momentum(
        self, twist: FloatArray, theta: FloatArray, tank_m: FloatArray, composite10: FloatArray, context: EffectContext
    ) -> tuple[FloatArray, FloatArray]:
        """For rigid twists (P, T, 6): the slosh mass's momentum relative to the base, ``[P; L]`` about the base
        origin (P, T, 6), and the change of the composite's 10 parameters (P, T, 10) from its displacement.

        ``composite10`` (P, 10) is the robot's mean composite (base and arm, slosh mass included) over the log,
        whose inverse inertia at the tank couples the slosh back to the base.
        """
        return slosh_momentum(np.ascontiguousarray(twist), context.t_s, self.inputs(theta, tank_m, composite10), self.has_rod)

    @property
    def has_rod(self) -> bool:
        """Whether the mass is on a rod (the pendulum) or a spring."""
        return self.model == "pendulum"

    def inputs(self, theta: FloatArray, tank_m: FloatArray, composite10: FloatArray) -> FloatArray:
        """The inputs (P, :data:`~estimators.models.slosh_dynamics.N_INPUTS`) of
        :func:`~estimators.models.slosh_dynamics.slosh_momentum` for ``theta`` (P, k_e) and the tank points (P, 3):
        the tank, ``[m_s, w, zeta, kappa]`` (natural frequency rad/s, the rod's curvature 1/m, 0 without a rod), the
        coupling ``E + m_s Lambda^-1`` (Lambda^-1 of the rest of ``composite10`` at the tank) and the rod's axis."""
        rest = composite10 - _point_mass10(theta[:, 0], tank_m)
        coupling = np.eye(3) + theta[:, 0, None, None] * _inverse_mass_at(rest, tank_m)  # m_s A, finite at m_s = 0
        axis, kappa = self.rod(theta)
        oscillator = np.stack((theta[:, 0], 2.0 * np.pi * theta[:, 1], theta[:, 2], kappa), axis=1)
        return np.ascontiguousarray(np.hstack((tank_m, oscillator, coupling.reshape(len(theta), 9), axis)))

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        out: dict[str, Any] = {
            "slosh_mass_kg": float(theta[0]),
            "slosh_frequency_hz": float(theta[1]),
            "slosh_damping_ratio": float(theta[2]),
        }
        if self.has_rod:  # numbers only (the estimate's std differentiates them); the model is in the spec
            out["slosh_axis"] = rod_axis(theta[3:4], theta[4:5])[0].tolist()
            out["slosh_rod_curvature_per_m"] = float(theta[5])
        return out

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


def rod_axis(azimuth_rad: FloatArray, elevation_rad: FloatArray) -> FloatArray:
    """Unit vectors (P, 3), base axes: ``[cos el cos az, cos el sin az, sin el]`` (the pendulum's rod)."""
    az, el = np.asarray(azimuth_rad, dtype=float), np.asarray(elevation_rad, dtype=float)
    return np.stack((np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)


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
