"""The free-floating momentum map: base twist from joint motion and total momentum.

With no external wrench the system's spatial momentum ``h_world`` (about the inertial origin, in
inertial axes, ``[P; L]``) is constant. In the base frame it reads ``h_base = H_bb v_base +
H_bm dq`` where ``H_bb`` (6x6) and ``H_bm`` (6xn) are the base rows of the joint-space mass matrix
(pinocchio CRBA, base velocity ``[v_lin; omega]`` in base axes). Hence

    v_base = H_bb^{-1} (h_base - H_bm dq),

which for ``h_world = 0`` is the paper's eq. 8 (generalized Jacobian) extended to the linear part.
``H_bb`` is the whole system's spatial inertia in the base frame; it depends on the base's own
10 inertial parameters linearly, which gives the analytic parameter sensitivity below.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from spaceid_gym.physics.inertia import SPATIAL_INERTIA_BASIS

FloatArray = NDArray[np.float64]


def momentum_world_to_base(h_world: FloatArray, rot_wb: FloatArray, p_wb_m: FloatArray) -> FloatArray:
    """Express momentum ``[P; L_O]`` (inertial origin, inertial axes) about the base origin in base axes."""
    lin_w, ang_w = h_world[:3], h_world[3:]
    return np.concatenate((rot_wb.T @ lin_w, rot_wb.T @ (ang_w - np.cross(p_wb_m, lin_w))))


def momentum_base_to_world(h_base: FloatArray, rot_wb: FloatArray, p_wb_m: FloatArray) -> FloatArray:
    """Inverse of :func:`momentum_world_to_base`."""
    lin_w = rot_wb @ h_base[:3]
    return np.concatenate((lin_w, rot_wb @ h_base[3:] + np.cross(p_wb_m, lin_w)))


def twist_from_momentum(composite: pin.Inertia, momentum: Sequence[float]) -> FloatArray:
    """Twist ``[v; omega]`` (frame origin, frame axes) of a body carrying ``momentum = [P; L]``.

    Closed-form inverse of the spatial inertia ``(m, c, Ic)`` (``composite``, e.g. the whole
    robot's composite inertia in the base frame, pinocchio ``data.Ycrb[1]``):
    ``P = m (v + omega x c)`` and ``L = Ic omega + c x P`` give ``omega = Ic^{-1} (L - c x P)`` and
    ``v = P / m - omega x c``. Written on floats: it sits in the simulator's inner loop.
    """
    m = composite.mass
    cx, cy, cz = (float(x) for x in composite.lever)
    (a, b, c), (_, d, e), (_, _, f) = composite.inertia.tolist()  # symmetric [[a b c] [b d e] [c e f]]
    px, py, pz, lx, ly, lz = (float(x) for x in momentum)
    # r = L - c x P
    rx, ry, rz = lx - (cy * pz - cz * py), ly - (cz * px - cx * pz), lz - (cx * py - cy * px)
    # omega = Ic^{-1} r by cofactors
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    inv_det = 1.0 / (a * c00 + b * c01 + c * c02)
    wx = (c00 * rx + c01 * ry + c02 * rz) * inv_det
    wy = (c01 * rx + c11 * ry + c12 * rz) * inv_det
    wz = (c02 * rx + c12 * ry + c22 * rz) * inv_det
    return np.array([px / m - (wy * cz - wz * cy), py / m - (wz * cx - wx * cz), pz / m - (wx * cy - wy * cx), wx, wy, wz])


def twist_parameter_jacobian(composite: pin.Inertia, twist: FloatArray, dparams10: FloatArray) -> FloatArray:
    """``d v_base / d theta`` (6, k) given ``d(base params10)/d theta`` (10, k), at fixed momentum.

    From ``H_bb v = h_base - H_bm dq`` where only the base's own spatial inertia depends on the
    parameters: ``dv/dpi_j = -H_bb^{-1} B_j v`` with ``B_j`` the spatial-inertia basis
    (:data:`SPATIAL_INERTIA_BASIS`) and ``H_bb`` the composite inertia ``composite``.
    """
    b_v = SPATIAL_INERTIA_BASIS @ twist  # (10, 6): B_j v
    rhs = -(dparams10.T @ b_v)  # (k, 6)
    return np.stack([twist_from_momentum(composite, r) for r in rhs], axis=1)
