"""Rigid-body inertia: mass, centre of mass and rotational inertia, and their 10-vector form.

Conventions
-----------
* A :class:`RigidBodyInertia` is expressed in a body frame ``B``: ``com_m`` is the centre of
  mass in ``B`` (m), ``inertia_com_kgm2`` the 3x3 rotational inertia about the CoM with axes
  of ``B`` (kg m^2).
* The 10 *inertial parameters* about the frame origin follow pinocchio's order
  ``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` where ``I`` is the inertia about the
  frame **origin** (not the CoM). The spatial inertia matrix is linear in this vector.
* Spatial quantities are ordered ``[linear; angular]`` (pinocchio's motion/force order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: index pairs of the 6 independent inertia entries in the 10-vector (pinocchio's order)
_INERTIA_ENTRIES = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


#: names (with units) of a body's 10 inertial parameters about a frame origin, in pinocchio's order
PARAMS10_NAMES: tuple[str, ...] = (
    "mass_kg",
    "mcx_kgm",
    "mcy_kgm",
    "mcz_kgm",
    "ixx_kgm2",
    "ixy_kgm2",
    "iyy_kgm2",
    "ixz_kgm2",
    "iyz_kgm2",
    "izz_kgm2",
)


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix ``[v]x`` with ``[v]x w = v x w``; ``v`` has shape (..., 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def point_mass_inertia(r_m: FloatArray) -> FloatArray:
    """``S(r) = |r|^2 E - r r^T``: the inertia (per kg) of a point at ``r`` about the origin; ``r_m`` (..., 3) gives
    (..., 3, 3)."""
    r = np.asarray(r_m, dtype=float)
    return np.einsum("...i,...i->...", r, r)[..., None, None] * np.eye(3) - r[..., :, None] * r[..., None, :]


@dataclass(frozen=True)
class RigidBodyInertia:
    """Mass properties of a rigid body in its body frame.

    Attributes:
        mass_kg: mass (kg), > 0.
        com_m: centre of mass in the body frame, shape (3,), metres.
        inertia_com_kgm2: rotational inertia about the CoM, body-frame axes, shape (3, 3).
    """

    mass_kg: float
    com_m: FloatArray
    inertia_com_kgm2: FloatArray

    def validate(self, where: str) -> RigidBodyInertia:
        """Raise :class:`SpaceIdInputError` unless the body is physical; return ``self``.

        Physical: finite values, mass > 0, symmetric inertia whose principal moments are > 0
        and satisfy the triangle inequalities ``I1 + I2 >= I3`` (a real mass distribution).
        """
        inertia = np.asarray(self.inertia_com_kgm2, dtype=float)
        com = np.asarray(self.com_m, dtype=float)
        if not (np.isfinite(self.mass_kg) and np.all(np.isfinite(com)) and np.all(np.isfinite(inertia))):
            raise SpaceIdInputError(f"{where}: mass properties must be finite numbers")
        if com.shape != (3,) or inertia.shape != (3, 3):
            raise SpaceIdInputError(f"{where}: expected a 3-vector CoM and a 3x3 inertia")
        if self.mass_kg <= 0.0:
            raise SpaceIdInputError(f"{where}: mass must be > 0 kg, got {self.mass_kg:g}")
        if not np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-9 * max(1.0, np.abs(inertia).max())):
            raise SpaceIdInputError(f"{where}: inertia matrix is not symmetric")
        moments = np.linalg.eigvalsh(inertia)
        tol = 1e-9 * max(1e-12, moments.max())
        if moments[0] <= 0.0:
            raise SpaceIdInputError(
                f"{where}: inertia is not positive definite (principal moments {moments.round(6).tolist()} kg m^2)"
            )
        if moments[0] + moments[1] < moments[2] - tol:
            raise SpaceIdInputError(
                f"{where}: principal moments {moments.round(6).tolist()} kg m^2 violate the triangle "
                "inequality I1 + I2 >= I3 (no real body has them)"
            )
        return self

    def to_params10(self) -> FloatArray:
        """The 10 inertial parameters about the frame origin (pinocchio order), shape (10,)."""
        c = np.asarray(self.com_m, dtype=float)
        inertia_origin = np.asarray(self.inertia_com_kgm2, dtype=float) + self.mass_kg * point_mass_inertia(c)
        return np.concatenate(([self.mass_kg], self.mass_kg * c, [inertia_origin[i, j] for i, j in _INERTIA_ENTRIES]))

    @classmethod
    def from_params10(cls, params: FloatArray) -> RigidBodyInertia:
        """Inverse of :meth:`to_params10`. Requires ``params[0] > 0`` (no validation otherwise)."""
        p = np.asarray(params, dtype=float)
        mass = float(p[0])
        com = p[1:4] / mass
        return cls(mass, com, inertia_matrix_from_entries(p[4:10]) - mass * point_mass_inertia(com))


def inertia_matrix_from_entries(entries: FloatArray) -> FloatArray:
    """3x3 symmetric matrix from ``[Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``, shape (..., 6) -> (..., 3, 3)."""
    e = np.asarray(entries, dtype=float)
    out = np.empty((*e.shape[:-1], 3, 3))
    for k, (i, j) in enumerate(_INERTIA_ENTRIES):
        out[..., i, j] = e[..., k]
        out[..., j, i] = e[..., k]
    return out


def spatial_inertia_matrix(params10: FloatArray) -> FloatArray:
    """6x6 spatial inertia (about the frame origin) from the 10 parameters; batched over (..., 10).

    ``[[m E, -[m c]x], [[m c]x, I_origin]]`` maps a twist ``[v; w]`` at the origin to the
    momentum ``[p; L]`` about the origin. It is linear in ``params10``.
    """
    p = np.asarray(params10, dtype=float)
    out = np.zeros((*p.shape[:-1], 6, 6))
    eye = np.eye(3)
    out[..., :3, :3] = p[..., 0, None, None] * eye
    first_moment = skew(p[..., 1:4])
    out[..., :3, 3:] = -first_moment
    out[..., 3:, :3] = first_moment
    out[..., 3:, 3:] = inertia_matrix_from_entries(p[..., 4:10])
    return out


#: ``SPATIAL_INERTIA_BASIS[k]`` is d(spatial inertia)/d(params10[k]), shape (10, 6, 6)
SPATIAL_INERTIA_BASIS: FloatArray = spatial_inertia_matrix(np.eye(10))


def transform_params10(params10: FloatArray, rot: FloatArray, trans_m: FloatArray) -> FloatArray:
    """Express a body's 10 inertial parameters in a parent frame; batched over (..., 10).

    The body's parameters are given about the origin of a child frame ``C`` with axes of ``C``;
    ``C`` has orientation ``rot`` (..., 3, 3) and origin ``trans_m`` (..., 3) in the parent frame ``P``
    (one frame, or a batch that broadcasts against ``params10``'s leading axes).
    With ``h = m c`` and ``J`` the inertia about ``C``'s origin: ``h' = R h + m p`` and
    ``J' = R J R^T + m S(p) + 2 (p . R h) E - p (R h)^T - (R h) p^T``. The map is linear in the
    parameters (so it also maps differences and basis vectors).
    """
    p = np.asarray(params10, dtype=float)
    r = np.asarray(rot, dtype=float)
    t = np.asarray(trans_m, dtype=float)
    mass = p[..., 0]
    rh = np.einsum("...ij,...j->...i", r, p[..., 1:4])
    j_rot = r @ inertia_matrix_from_entries(p[..., 4:10]) @ np.swapaxes(r, -1, -2)
    p_dot_rh = np.sum(rh * t, axis=-1)
    outer = t[..., :, None] * rh[..., None, :]
    eye = np.eye(3)
    point = np.sum(t * t, axis=-1)[..., None, None] * eye - t[..., :, None] * t[..., None, :]
    inertia = j_rot + mass[..., None, None] * point + 2.0 * p_dot_rh[..., None, None] * eye - outer - np.swapaxes(outer, -1, -2)
    entries = np.stack([inertia[..., i, j] for i, j in _INERTIA_ENTRIES], axis=-1)
    masses = np.broadcast_to(mass[..., None], (*entries.shape[:-1], 1))
    return np.concatenate((masses, rh + mass[..., None] * t, entries), axis=-1)
