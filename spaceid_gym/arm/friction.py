"""Joint friction, linear in its coefficients.

Per joint j (rate ``dq`` in rad/s, torque in N m)::

    tau_f = fc s(dq)                                   "coulomb"   fc  [N m]
          + fv dq                                      "viscous"   fv  [N m s/rad]
          + (fs - fc) exp(-(dq / vs)^2) s(dq)          "stribeck"  fs - fc [N m]  (optional)
          + f0                                         "offset"    f0  [N m]      (optional)

or, instead of the symmetric Coulomb term, one Coulomb level per direction (the two ``>= 0``)::

          fc+ max(s(dq), 0) + fc- min(s(dq), 0)        "coulomb_asymmetric"  fc+, fc- [N m]  (optional)

Coulomb + viscous is the model of the source document (``tau_f = fc sign(dq) + fv dq``). The
Stribeck term is linear in its coefficient because the Stribeck velocity ``vs`` is fixed (not
identified): the coefficient is the excess of static over Coulomb friction, ``fs - fc``. The offset
absorbs a constant bias of the torque (or current) measurement. The asymmetric Coulomb term replaces ``coulomb``
(the two together are collinear: ``s = max(s, 0) + min(s, 0)``); its difference from a symmetric Coulomb term and an
offset, ``(fc+ - fc-) / 2 |s(dq)|`` against a constant, shows only where the joint rests or reverses
(``|s| < 1``), so the data tell the two apart only through their rests and reversals.

The sign near zero speed
------------------------
``s(dq) = tanh(dq / v_eps)`` with ``v_eps = coulomb_smoothing_rad_s`` (default 0.01 rad/s:
``s`` is within 0.5 % of ``sign(dq)`` above 0.03 rad/s and goes smoothly through 0 at rest).
At rest the true friction is anything in ``[-fs, fs]`` (stiction), which no function of ``dq``
can predict; the smooth sign avoids a 2 fc jump caused by noise on a velocity near zero. With
``coulomb_smoothing_rad_s=0`` the exact ``sign`` is used (``sign(0) = 0``); the caller should then
drop or down-weight samples whose speed is below a threshold (for example 0.02 rad/s).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: Every friction term, in the order their coefficients appear per joint.
FRICTION_TERMS: tuple[str, ...] = ("coulomb", "coulomb_asymmetric", "viscous", "stribeck", "offset")
#: The coefficients (columns per joint) of each term.
TERM_COLUMNS: dict[str, tuple[str, ...]] = {
    "coulomb": ("coulomb",),
    "viscous": ("viscous",),
    "stribeck": ("stribeck",),
    "offset": ("offset",),
    "coulomb_asymmetric": ("coulomb_positive", "coulomb_negative"),
}
#: The unit suffix of each coefficient in parameter names.
FRICTION_UNITS: dict[str, str] = {
    "coulomb": "Nm",
    "viscous": "Nms",
    "stribeck": "Nm",
    "offset": "Nm",
    "coulomb_positive": "Nm",
    "coulomb_negative": "Nm",
}
#: Terms that cannot be in one model together (their columns are collinear).
EXCLUSIVE_TERMS: tuple[tuple[str, str], ...] = (("coulomb", "coulomb_asymmetric"),)


@dataclass(frozen=True)
class FrictionModel:
    """Which friction terms each joint has, and the two fixed velocities of the model.

    Attributes:
        terms: a subset of :data:`FRICTION_TERMS`, stored in that canonical order; ``()`` = no friction.
        coulomb_smoothing_rad_s: ``v_eps`` of the smooth sign ``tanh(dq / v_eps)``, rad/s; 0 = exact sign.
        stribeck_velocity_rad_s: ``vs``, rad/s (fixed, not identified; default 0.05 rad/s, a
            typical value for harmonic-drive joints, an assumption).
    """

    terms: tuple[str, ...] = ("coulomb", "viscous")
    coulomb_smoothing_rad_s: float = 0.01
    stribeck_velocity_rad_s: float = 0.05

    def __post_init__(self) -> None:
        terms = tuple(self.terms) if not isinstance(self.terms, str) else (self.terms,)
        unknown = [t for t in terms if t not in FRICTION_TERMS]
        if unknown:
            raise SpaceIdInputError(f"friction: unknown term(s) {unknown}; expected a subset of {list(FRICTION_TERMS)}")
        if len(set(terms)) != len(terms):
            raise SpaceIdInputError(f"friction: duplicated term in {list(terms)}")
        for first, second in EXCLUSIVE_TERMS:
            if first in terms and second in terms:
                raise SpaceIdInputError(
                    f"friction: {first!r} and {second!r} cannot be in one model (collinear columns); keep one of them"
                )
        object.__setattr__(self, "terms", tuple(t for t in FRICTION_TERMS if t in terms))
        if not (np.isfinite(self.coulomb_smoothing_rad_s) and self.coulomb_smoothing_rad_s >= 0):
            raise SpaceIdInputError(f"friction: coulomb_smoothing_rad_s must be >= 0, got {self.coulomb_smoothing_rad_s!r}")
        if not (np.isfinite(self.stribeck_velocity_rad_s) and self.stribeck_velocity_rad_s > 0):
            raise SpaceIdInputError(f"friction: stribeck_velocity_rad_s must be > 0, got {self.stribeck_velocity_rad_s!r}")

    @classmethod
    def coerce(cls, friction: FrictionModel | Sequence[str] | str | None) -> FrictionModel:
        """A :class:`FrictionModel` from a model, a sequence of term names, one name, or ``None`` (no friction)."""
        if isinstance(friction, FrictionModel):
            return friction
        if friction is None:
            return cls(terms=())
        if isinstance(friction, str):
            return cls(terms=(friction,))
        return cls(terms=tuple(friction))

    @property
    def columns(self) -> tuple[str, ...]:
        """The coefficients of one joint, in order (:data:`TERM_COLUMNS` of each term)."""
        return tuple(column for term in self.terms for column in TERM_COLUMNS[term])

    @property
    def n_terms(self) -> int:
        """Number of coefficients per joint (``len(columns)``)."""
        return len(self.columns)

    def parameter_names(self, n_joints: int) -> list[str]:
        """Coefficient names, joint-major: ``joint1_coulomb_Nm, joint1_viscous_Nms, joint2_...`` (length n k)."""
        return [f"joint{j + 1}_{column}_{FRICTION_UNITS[column]}" for j in range(n_joints) for column in self.columns]

    def smooth_sign(self, dq_rad_s: FloatArray) -> FloatArray:
        """``s(dq)``: ``tanh(dq / v_eps)``, or ``sign(dq)`` if ``v_eps = 0``; same shape as ``dq``."""
        dq = np.asarray(dq_rad_s, dtype=float)
        if self.coulomb_smoothing_rad_s == 0:
            return np.sign(dq)
        return np.tanh(dq / self.coulomb_smoothing_rad_s)

    def features(self, dq_rad_s: FloatArray) -> FloatArray:
        """Per-joint friction features: ``tau_f[..., j] = features[..., j, :] @ coefficients[j]``.

        Args:
            dq_rad_s: joint rates, shape (T, n), rad/s.

        Returns:
            shape (T, n, k), k = :attr:`n_terms`, in :attr:`columns` order.
        """
        dq = np.asarray(dq_rad_s, dtype=float)
        out = np.empty((*dq.shape, self.n_terms))
        s = self.smooth_sign(dq) if {"coulomb", "stribeck", "coulomb_asymmetric"} & set(self.terms) else None
        i = 0  # the next column
        for term in self.terms:
            if term == "coulomb":
                out[..., i] = s
            elif term == "coulomb_asymmetric":
                out[..., i] = np.maximum(s, 0.0)
                out[..., i + 1] = np.minimum(s, 0.0)
            elif term == "viscous":
                out[..., i] = dq
            elif term == "stribeck":
                out[..., i] = np.exp(-((dq / self.stribeck_velocity_rad_s) ** 2)) * s
            else:  # offset
                out[..., i] = 1.0
            i += len(TERM_COLUMNS[term])
        return out

    def torque(self, dq_rad_s: FloatArray, coefficients: FloatArray) -> FloatArray:
        """Friction torque, shape (T, n), N m, for coefficients of shape (n, k) (joint j, in :attr:`columns` order)."""
        coefficients = np.asarray(coefficients, dtype=float)
        features = self.features(dq_rad_s)
        if coefficients.shape != features.shape[-2:]:
            raise SpaceIdInputError(
                f"friction: coefficients must have shape (n, k) = {features.shape[-2:]} (terms {list(self.terms)}), "
                f"got {coefficients.shape}"
            )
        return np.einsum("tjk,jk->tj", features, coefficients)
