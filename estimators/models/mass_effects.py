"""The effect terms of extra masses: a payload held by the last link (its 10 inertial parameters) and fuel that
sloshes in the tank (a point mass on a spring-damper). The catalogue: :mod:`estimators.models.effect_models`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numba import njit

from estimators.models.effect_base import EffectContext, EffectTerm
from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.draws import remaining_liquid_kg
from spaceid_gym.effects.settings import SLOSH_MODELS
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import PARAMS10_NAMES, RigidBodyInertia, skew, spatial_inertia_matrix
from spaceid_gym.robots import Robot

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
    ``x'' = -A (k x + c x') - a_tank(t) - g`` with ``k = m_s w^2``, ``c = 2 zeta m_s w``, ``w = 2 pi f``, driven by the
    tank's inertial acceleration ``a_tank = dv/dt + omega x v + domega/dt x r + omega x (omega x r)`` (base axes)
    of the prediction without the slosh mass (the rest of the robot), with ``g = 2 omega x x' + domega/dt x x + omega x
    (omega x x)`` the rotating base frame's Coriolis, Euler and centripetal terms on the displacement
    (:func:`frame_terms`; without them a 40 s slosh left 5 % of its effect unexplained on a noise-free log); ``A = E / m_s + Lambda^-1`` because the spring force also pushes the rest of the
    robot (``Lambda^-1``: its inverse operational mass at the tank, from the log's mean composite), which raises
    the relative frequency above ``f`` (the mass's frequency against a fixed wall).
    Its momentum relative to the base, ``[m_s x'; m_s (r + x) x x']``, is then carried by the rest, the
    displaced mass changes the composite's first moment and inertia (a point mass at ``r + x`` instead of
    ``r``), and the prediction is made again with both. Neglected: the coupling's change with the arm's
    configuration, and the slosh's feedback on its own forcing beyond ``Lambda^-1``.
    Integrated with RK4 at the log's sample period, starting at rest.

    Two equivalent mechanical models (Abramson, NASA SP-106, ch. 6), ``model=``: ``"spring"`` (the default; the mass
    moves in every direction) and ``"pendulum"`` (``slosh[model=pendulum]``: a mass on a rod whose direction, two more
    unknowns ``slosh_axis_azimuth_rad`` and ``slosh_axis_elevation_rad`` (base frame), is fitted; in the small-angle
    limit the rod carries the mass with the base along it and the mass moves only normal to it, so the oscillator and
    its forcing are projected on that plane, :meth:`projector`). Their lateral dynamics are the same; they differ in
    what the motion along the rod does. :func:`~estimators.diagnostics.diagnose.diagnose` fits both and names
    ``slosh`` with the better.

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
            self.names = (*Slosh.names, "slosh_axis_azimuth_rad", "slosh_axis_elevation_rad")
            self.truth_fields = (*Slosh.truth_fields, ("slosh_axis", 3))
            nominal, lower = [*nominal, 0.0, 0.5 * math.pi], [*lower, -2.0 * math.pi, -math.pi]
            upper, scale = [*upper, 2.0 * math.pi, math.pi], [*scale, 0.5, 0.5]
        super().__init__(np.array(nominal), np.array(lower), np.array(upper), np.array(scale))
        full_com = np.asarray(robot.base_full.com_m, dtype=float)
        self.tank_of = tank_of if tank_of is not None else (lambda theta_base: np.broadcast_to(full_com, (len(theta_base), 3)))
        self.liquid_of = liquid_of if liquid_of is not None else (lambda theta_base: np.full(len(theta_base), liquid_max_kg))

    @property
    def spec(self) -> str:
        return self.name if self.model == "spring" else f"{self.name}[model={self.model}]"

    def from_truth(self, hidden: Mapping[str, Any]) -> FloatArray:
        """As :meth:`EffectTerm.from_truth`; the pendulum's axis (a unit vector in the truth) as its two angles, and a
        spring truth read by the pendulum term with the rod along the nominal axis (and vice versa, the axis dropped)."""
        theta = self.nominal.copy()
        for i, field in enumerate(Slosh.names):
            if field in hidden:
                theta[i] = float(hidden[field])
        if self.model == "pendulum" and hidden.get("slosh_axis") is not None:
            axis = np.ravel(np.asarray(hidden["slosh_axis"], dtype=float))
            if axis.size != 3 or not np.linalg.norm(axis) > 0.0:
                raise SpaceIdInputError(f"hidden_effects: slosh_axis expected a non-zero 3-vector, got {hidden['slosh_axis']!r}")
            axis = axis / np.linalg.norm(axis)
            theta[3:5] = math.atan2(axis[1], axis[0]), math.asin(float(np.clip(axis[2], -1.0, 1.0)))
        return theta

    def projector(self, theta: FloatArray) -> FloatArray:
        """(P, 3, 3): where the slosh mass can move, base axes: everywhere for the spring, the plane normal to the
        rod ``a = [cos el cos az, cos el sin az, sin el]`` for the pendulum (``E - a a^T``: the small-angle limit, in which
        the rod moves the mass with the base along ``a``)."""
        if self.model == "spring":
            return np.broadcast_to(np.eye(3), (len(theta), 3, 3)).copy()
        axis = rod_axis(theta[:, 3], theta[:, 4])
        return np.eye(3) - axis[:, :, None] * axis[:, None, :]

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
        return [np.array([mass, f, 0.05, *self.GRID_AXES[0]][: self.n_params]) for f in self.START_FREQUENCIES_HZ]

    def grid(self, theta_base: FloatArray | None = None) -> list[FloatArray]:
        """:data:`GRID_FREQUENCIES_HZ` x :data:`GRID_MASS_FRACTIONS` of the liquid left for ``theta_base`` (or of the
        usable fuel), damping 0.05: candidates to score in one batched evaluation before the local fits."""
        liquid = self.upper[0] if theta_base is None else float(self.liquid_of(np.atleast_2d(theta_base))[0])
        axes = self.GRID_AXES if self.model == "pendulum" else ((),)
        return [
            np.array([fraction * liquid, f, 0.05, *axis])
            for f in self.GRID_FREQUENCIES_HZ
            for fraction in self.GRID_MASS_FRACTIONS
            for axis in axes
        ]

    def grid_from_variant(self, fitted: FloatArray) -> list[FloatArray]:
        """The pendulum's candidates (5,) with the mass, frequency and damping of ``fitted`` (the first three values: a
        fit of the other slosh model, whose lateral dynamics are the same) and the rod along each of
        :data:`FINE_AXES`; none for the spring."""
        if self.model != "pendulum":
            return []
        return [np.array([*np.asarray(fitted, dtype=float)[:3], *axis]) for axis in self.FINE_AXES]

    def momentum(
        self, twist: FloatArray, theta: FloatArray, tank_m: FloatArray, composite10: FloatArray, context: EffectContext
    ) -> tuple[FloatArray, FloatArray]:
        """For rigid twists (P, T, 6): the slosh mass's momentum relative to the base, ``[P; L]`` about the base
        origin (P, T, 6), and the change of the composite's 10 parameters (P, T, 10) from its displacement.

        ``composite10`` (P, 10) is the robot's mean composite (base and arm, slosh mass included) over the log,
        whose inverse inertia at the tank couples the slosh back to the base.
        """
        omega_n, coupling, projector = self.oscillator(theta, tank_m, composite10)
        return _slosh_momentum(
            np.ascontiguousarray(twist),
            context.t_s,
            np.ascontiguousarray(tank_m),
            theta[:, 0],
            omega_n,
            theta[:, 2],
            coupling,
            projector,
        )

    def oscillator(self, theta: FloatArray, tank_m: FloatArray, composite10: FloatArray) -> tuple[FloatArray, ...]:
        """The oscillator of :meth:`momentum` for ``theta`` (P, k_e): natural frequency (P,) rad/s, the projected
        coupling ``Pi (E + m_s Lambda^-1)`` (P, 3, 3) and the projector ``Pi`` (P, 3, 3)."""
        rest = composite10 - _point_mass10(theta[:, 0], tank_m)
        coupling = np.eye(3) + theta[:, 0, None, None] * _inverse_mass_at(rest, tank_m)  # m_s A, finite at m_s = 0
        projector = self.projector(theta)
        return 2.0 * np.pi * theta[:, 1], np.ascontiguousarray(projector @ coupling), np.ascontiguousarray(projector)

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        out: dict[str, Any] = {
            "slosh_mass_kg": float(theta[0]),
            "slosh_frequency_hz": float(theta[1]),
            "slosh_damping_ratio": float(theta[2]),
        }
        if self.model == "pendulum":  # numbers only (the estimate's std differentiates them); the model is in the spec
            out["slosh_axis"] = rod_axis(theta[3:4], theta[4:5])[0].tolist()
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


@njit(cache=True, inline="always")
def _cross(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> tuple[float, float, float]:
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def frame_terms(spin: FloatArray, row: int, point: FloatArray) -> tuple[float, float, float]:
    """The acceleration terms of a displacement ``x`` moving at ``x'`` (``point`` = ``[x; x']``, base axes) in the
    rotating base frame, ``2 omega x x' + domega/dt x x + omega x (omega x x)``, for ``spin[row]`` = ``[omega;
    domega/dt]`` (base axes): Coriolis, Euler and centripetal."""
    wx, wy, wz = spin[row, 0], spin[row, 1], spin[row, 2]
    c1 = _cross(wx, wy, wz, point[3], point[4], point[5])
    c2 = _cross(spin[row, 3], spin[row, 4], spin[row, 5], point[0], point[1], point[2])
    wx_ = _cross(wx, wy, wz, point[0], point[1], point[2])
    c3 = _cross(wx, wy, wz, wx_[0], wx_[1], wx_[2])
    return 2.0 * c1[0] + c2[0] + c3[0], 2.0 * c1[1] + c2[1] + c3[1], 2.0 * c1[2] + c2[2] + c3[2]


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
    spin: FloatArray,
    projector: FloatArray,
) -> None:
    """``slopes[s]`` = the derivative ``[x'; -A (stiff x + damp x') - f - Pi g]`` of the slosh oscillator at ``point`` =
    ``[x; x']`` (6,), with ``A = coupling[p]``, the forcing ``f = force[row]``, the base frame's terms ``g`` of
    :func:`frame_terms` for ``spin[row]`` and ``Pi = projector[p]`` (see :func:`_slosh_momentum`)."""
    s0 = stiff * point[0] + damp * point[3]
    s1 = stiff * point[1] + damp * point[4]
    s2 = stiff * point[2] + damp * point[5]
    g = frame_terms(spin, row, point)
    for c in range(3):
        slopes[s, c] = point[3 + c]
        slopes[s, 3 + c] = (
            -(coupling[p, c, 0] * s0 + coupling[p, c, 1] * s1 + coupling[p, c, 2] * s2)
            - force[row, c]
            - (projector[p, c, 0] * g[0] + projector[p, c, 1] * g[1] + projector[p, c, 2] * g[2])
        )


@njit(cache=True)
def _slosh_momentum(
    twist: FloatArray,
    t_s: FloatArray,
    tank: FloatArray,
    mass: FloatArray,
    omega_n: FloatArray,
    zeta: FloatArray,
    coupling: FloatArray,
    projector: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """See :meth:`Slosh.momentum`; RK4 with the forcing linear between samples (each axis is the same scalar
    oscillator). ``coupling`` (P, 3, 3) is ``Pi (E + m_s Lambda^-1)`` and the forcing is ``Pi a_tank``, with ``Pi =
    projector`` (P, 3, 3) the directions the mass can move in (:meth:`Slosh.projector`): starting at rest, the
    displacement stays in them."""
    n_p, n_t = twist.shape[0], twist.shape[1]
    out = np.zeros((n_p, n_t, 6))
    moved = np.zeros((n_p, n_t, 10))
    accel = np.empty((n_t, 3))
    rates = np.empty((n_t, 6))  # [omega; domega/dt] of the base per sample, base axes
    spin = np.empty((3, 6))  # the same at a step's start, middle and end
    # RK4 scratch: the state [x; x'], the point of a stage, the four slopes, the forcing at a step's start/middle/end
    state, stage, slopes, force = np.empty(6), np.empty(6), np.empty((4, 6)), np.empty((3, 3))
    free = np.empty(3)  # the tank's acceleration before the projection
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
                free[c] = (twist[p, hi, c] - twist[p, lo, c]) * inv + a1[c] + a2[c] + a3[c]
            for c in range(3):
                accel[k, c] = projector[p, c, 0] * free[0] + projector[p, c, 1] * free[1] + projector[p, c, 2] * free[2]
            rates[k, 0], rates[k, 1], rates[k, 2], rates[k, 3], rates[k, 4], rates[k, 5] = wx, wy, wz, dwx, dwy, dwz
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
            for c in range(6):
                spin[0, c], spin[2, c] = rates[k - 1, c], rates[k, c]
                spin[1, c] = 0.5 * (spin[0, c] + spin[2, c])
            _oscillator_slope(coupling, p, stiff, damp, state, force, 0, slopes, 0, spin, projector)
            for s in range(1, 4):
                fraction = 1.0 if s == 3 else 0.5
                for i in range(6):
                    stage[i] = state[i] + fraction * h * slopes[s - 1, i]
                _oscillator_slope(coupling, p, stiff, damp, stage, force, 1 if s < 3 else 2, slopes, s, spin, projector)
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
