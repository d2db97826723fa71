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

import numpy as np
import pinocchio as pin
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.physics.inertia import SPATIAL_INERTIA_BASIS


@njit(cache=True)
def momentum_world_to_base(h_world: FloatArray, rot_wb: FloatArray, p_wb_m: FloatArray) -> FloatArray:
    """Express momentum ``[P; L_O]`` (inertial origin, inertial axes) about the base origin in base axes.

    Compiled with numba: it runs inside the simulator's integration kernel.
    """
    lin_w, ang_w = h_world[:3], h_world[3:]
    out = np.empty(6)
    out[:3] = rot_wb.T @ lin_w
    out[3:] = rot_wb.T @ (ang_w - np.cross(p_wb_m, lin_w))
    return out


def base_parameter_directions(dparams10: FloatArray) -> FloatArray:
    """``sum_j dparams10[j, k] B_j`` for each column k: (k, 6, 6), ``B_j`` the spatial-inertia basis."""
    return np.einsum("jk,jab->kab", dparams10, SPATIAL_INERTIA_BASIS)


@njit(cache=True)
def twist_parameter_jacobian(h_bb_inv: FloatArray, twist: FloatArray, directions: FloatArray) -> FloatArray:
    """``d v_base / d theta`` (6, k) at fixed momentum.

    From ``H_bb v = h_base - H_bm dq`` where only the base's own spatial inertia depends on the
    parameters: ``dv/dtheta_k = -H_bb^{-1} D_k v`` with ``D_k = dH_bb/dtheta_k`` (k, 6, 6) from
    :func:`base_parameter_directions` and ``h_bb_inv`` the inverse of the composite inertia ``H_bb``.
    Compiled with numba (it runs every env step, for the reward).
    """
    k = directions.shape[0]
    d_v = np.empty((6, k))
    for i in range(k):
        d_v[:, i] = directions[i] @ twist
    return -(h_bb_inv @ d_v)


def base_rate_from_joint_motion(model: pin.Model, q_rad: FloatArray, dq_rad_s: FloatArray) -> FloatArray:
    """The paper's eq. 8 over a log: base angular velocity (base body frame) from joint motion alone.

    Zero system momentum: ``A_G(q) [v_base; dq] = 0`` with pinocchio's centroidal momentum map
    ``A_G`` (a code path independent of the simulator's composite-inertia one), solved for the base
    twist at identity base attitude, so the result is in base axes.

    Args:
        model: free-flyer pinocchio model with the base mass properties to test.
        q_rad, dq_rad_s: joint angles and rates, shape (T, n).

    Returns:
        ``omega_base_body``, shape (T, 3), rad/s.
    """
    data = model.createData()
    q_full = pin.neutral(model)
    out = np.empty((len(q_rad), 3))
    for i, (q, dq) in enumerate(zip(q_rad, dq_rad_s, strict=True)):
        q_full[7:] = q
        ag = pin.computeCentroidalMap(model, data, q_full)
        out[i] = np.linalg.solve(ag[:, :6], -ag[:, 6:] @ dq)[3:]
    return out
