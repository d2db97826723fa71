"""What every effect term of the identification model is: :class:`EffectTerm` (unknowns, nominal, search range,
typical size, plausibility, where it acts) and :class:`EffectContext` (the log's time and attitude), and the
search ranges they share. The catalogue: :mod:`estimators.models.effect_models`.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot
from spaceid_gym.sim.lie import matrix_from_quat, so3_exp

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
    #: a measurement term that only adds to the reading (a bias): it does not change the reading's derivatives
    #: with respect to the other unknowns (:mod:`estimators.models.effect_jacobian`)
    additive: ClassVar[bool] = False
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
        by default :meth:`starts` (a term whose cost is multimodal offers a scan). Empty where the term cannot act
        with the base parameters ``theta_base`` (a slosh where they leave no liquid): the scan is then made at other
        base parameters."""
        return self.starts(theta_base)

    def switched_off(self, theta: FloatArray) -> bool:
        """Whether at ``theta`` (k_e,) the effect is off in a way a local fit cannot leave: its prediction is the model's
        without it and its other unknowns move nothing there (a slosh without mass); false by default (an effect at
        zero, a momentum or a bias, still has the directions that switch it on)."""
        return False

    def describes(self, hidden: Mapping[str, Any]) -> bool:
        """Whether this term, as configured, is the model that made the simulated effect ``hidden`` (``truth.json``'s
        ``hidden_effects``), not only one that can stand for it (a slosh pendulum for a spring-mass); true by default."""
        return True

    def grid_from_variant(self, fitted: FloatArray) -> list[FloatArray]:
        """More candidates (k_e,) from ``fitted``, this effect's unknowns as another of its equivalent models fitted
        them (e.g. a slosh pendulum from a spring-mass fit); none by default."""
        return []

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

    def equivalent(self, theta: FloatArray, theta_base: FloatArray) -> FloatArray:
        """``theta`` (P, k_e) with the base parameters ``theta_base`` (P, k_base): the unknowns that predict the same
        within what the term can physically move; the same by default."""
        return np.array(theta, dtype=float)

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
