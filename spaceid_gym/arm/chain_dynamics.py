"""Compiled rigid-body dynamics of a fixed-base serial revolute chain: the arm simulator's inner loop.

The arm simulator (:mod:`spaceid_gym.arm.torque_simulator`) evaluates, at every RK4 stage, the controller's inverse
dynamics ``RNEA_c(q, dq, v)`` and the plant's forward dynamics ``ABA(q, dq, u)``: 16 pairs per 125 Hz sample at the
env's 500 Hz. Called one by one from Python, pinocchio's functions spend most of their time crossing into C++ and
the RK4 arithmetic on 6-vectors most of the rest. This module does the same algorithms in numba on the chain's
constant data (:class:`SerialChain`, read once from the pinocchio model), a whole sample period per call:

* **RNEA** (recursive Newton-Euler, Featherstone 2008, table 5.1) and **ABA** (articulated-body algorithm, table 7.1)
  in pinocchio's conventions: spatial vectors linear part first, each body's quantities in its joint frame, the
  joint frame of body i placed in its parent's by ``jointPlacements[i]`` then rotated by ``q_i`` about the joint's
  axis, gravity entering as the base's acceleration ``-g``, rotor inertia (armature) on the joint's diagonal.
* Results equal pinocchio's to round-off (the tests hold both against each other on random states to 1e-12
  relative, and a simulated run with either); only the order of floating-point operations differs.
* Used by :class:`~spaceid_gym.arm.torque_simulator.ArmSimulator` whenever it has a controller and the arm is a
  serial revolute chain (pinocchio's functions otherwise). One period of ``ManipulatorID-v0`` (125 Hz, RK4 at
  500 Hz, and the sample at its end) took 36 us of CPU time against 119 us through pinocchio from Python on the
  loaded 2-core machine. The first compilation takes about 12 s (cached on disk).

Frames and units: each body's spatial quantities in its joint frame; rad, rad/s, rad/s^2, N m, kg, m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numba import njit

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: pinocchio's revolute joints about a frame axis, and the axis
_AXIS_OF_JOINT = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class SerialChain:
    """The constant data of a fixed-base serial revolute chain, as arrays for the compiled dynamics.

    Attributes:
        rotation: rotation of joint i's frame (at ``q_i = 0``) in its parent's frame, shape (n, 3, 3).
        translation: origin of joint i's frame in its parent's frame, shape (n, 3), m.
        axis: joint i's unit rotation axis in its own frame, shape (n, 3).
        inertia: body i's 6x6 spatial inertia in joint i's frame (linear part first), shape (n, 6, 6), kg, kg m, kg m^2.
        armature: rotor inertia on joint i, shape (n,), kg m^2.
        base_acceleration: the base's spatial acceleration ``-g`` (linear part first), shape (6,), m/s^2.
    """

    rotation: FloatArray
    translation: FloatArray
    axis: FloatArray
    inertia: FloatArray
    armature: FloatArray
    base_acceleration: FloatArray

    @classmethod
    def from_pinocchio(cls, model: pin.Model) -> SerialChain | None:
        """The chain of a fixed-base pinocchio model; ``None`` if the model is not a serial chain of revolute joints."""
        n = model.njoints - 1
        if n < 1 or model.nq != n or model.nv != n:
            return None
        axes = []
        for i in range(1, n + 1):
            joint = model.joints[i]
            if model.parents[i] != i - 1:
                return None
            name = joint.shortname()
            if name in _AXIS_OF_JOINT:
                axes.append(_AXIS_OF_JOINT[name])
            elif name == "JointModelRevoluteUnaligned":
                axes.append(tuple(np.asarray(joint.extract().axis, dtype=float)))
            else:
                return None
        placements = [model.jointPlacements[i] for i in range(1, n + 1)]
        return cls(
            rotation=np.ascontiguousarray([p.rotation for p in placements], dtype=float),
            translation=np.ascontiguousarray([p.translation for p in placements], dtype=float),
            axis=np.ascontiguousarray(axes, dtype=float),
            inertia=np.ascontiguousarray([model.inertias[i].matrix() for i in range(1, n + 1)], dtype=float),
            armature=np.ascontiguousarray(model.armature, dtype=float),
            base_acceleration=-np.asarray(model.gravity.vector, dtype=float),
        )

    def same_geometry(self, other: SerialChain) -> bool:
        """Whether ``other`` has this chain's joints, placements and gravity (its bodies may differ)."""
        return all(
            np.array_equal(a, b)
            for a, b in (
                (self.rotation, other.rotation),
                (self.translation, other.translation),
                (self.axis, other.axis),
                (self.base_acceleration, other.base_acceleration),
            )
        )

    def servo(self, controller: SerialChain, q: FloatArray, dq: FloatArray, command: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The computed-torque servo at one state: ``(tau, ddq)``, each shape (n,).

        ``tau = RNEA(q, dq, command)`` of the ``controller``'s chain (N m) and ``ddq = ABA(q, dq, tau)`` of this one
        (rad/s^2); with ``controller`` this chain, ``ddq`` is ``command`` up to round-off. The controller must have
        this chain's geometry (:meth:`same_geometry`).
        """
        if not self.same_geometry(controller):
            raise SpaceIdInputError("servo: the controller's chain has other joints or placements than the plant's")
        q, dq, command = (np.ascontiguousarray(x, dtype=float) for x in (q, dq, command))
        return servo_sample((chain_arrays(self), chain_arrays(controller)), q, dq, command, (0.0, 0.0))


# The compiled functions index whole arrays (``array, row``) rather than taking slices: a slice is a new array object
# whose reference count numba updates atomically, which costs more than the arithmetic at this size.
_jit = njit(cache=True, error_model="numpy")  # numpy's error model: no zero-division branch in every division
# the small helpers called in loops and the passes, inlined where they are called (numba's IR inlining: about 2 us a
# step faster, at the price of a longer first compilation; the larger helpers are left as calls)
_inline = njit(cache=True, error_model="numpy", inline="always")

#: a chain's arrays as the compiled functions take them (:func:`chain_arrays`)
ChainArrays = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


@_jit
def _joint_transforms(rotation: FloatArray, axis: FloatArray, q: FloatArray, rot: FloatArray) -> None:
    """``rot[i] = rotation[i] @ Rot(axis[i], q[i])`` (n, 3, 3): each joint frame's orientation in its parent's."""
    for i in range(q.shape[0]):
        c, s = math.cos(q[i]), math.sin(q[i])
        x, y, z = axis[i, 0], axis[i, 1], axis[i, 2]
        t = 1.0 - c
        r00, r01, r02 = t * x * x + c, t * x * y - s * z, t * x * z + s * y
        r10, r11, r12 = t * x * y + s * z, t * y * y + c, t * y * z - s * x
        r20, r21, r22 = t * x * z - s * y, t * y * z + s * x, t * z * z + c
        for k in range(3):
            a0, a1, a2 = rotation[i, k, 0], rotation[i, k, 1], rotation[i, k, 2]
            rot[i, k, 0] = a0 * r00 + a1 * r10 + a2 * r20
            rot[i, k, 1] = a0 * r01 + a1 * r11 + a2 * r21
            rot[i, k, 2] = a0 * r02 + a1 * r12 + a2 * r22


@_inline
def _motion_to_child(rot: FloatArray, p: FloatArray, i: int, m: FloatArray, out: FloatArray) -> None:
    """``out[i + 1] = X_i m[i]``: a motion vector at the parent's origin in its axes -> joint i's frame.

    ``(R^T (m_l - p x m_w), R^T m_w)`` with ``R = rot[i]``, ``p = p[i]``; ``m`` and ``out`` (n + 1, 6), row 0 the base.
    """
    lx = m[i, 0] - (p[i, 1] * m[i, 5] - p[i, 2] * m[i, 4])
    ly = m[i, 1] - (p[i, 2] * m[i, 3] - p[i, 0] * m[i, 5])
    lz = m[i, 2] - (p[i, 0] * m[i, 4] - p[i, 1] * m[i, 3])
    for k in range(3):
        out[i + 1, k] = rot[i, 0, k] * lx + rot[i, 1, k] * ly + rot[i, 2, k] * lz
        out[i + 1, 3 + k] = rot[i, 0, k] * m[i, 3] + rot[i, 1, k] * m[i, 4] + rot[i, 2, k] * m[i, 5]


@_jit
def _add_force_to_parent(rot: FloatArray, p: FloatArray, i: int, f: FloatArray, out: FloatArray, row: int) -> None:
    """``out[row] += X_i^T f``: a force (6,) in joint i's frame added to one in its parent's (``(R f_l, R f_n + p x R f_l)``)."""
    fx = rot[i, 0, 0] * f[0] + rot[i, 0, 1] * f[1] + rot[i, 0, 2] * f[2]
    fy = rot[i, 1, 0] * f[0] + rot[i, 1, 1] * f[1] + rot[i, 1, 2] * f[2]
    fz = rot[i, 2, 0] * f[0] + rot[i, 2, 1] * f[1] + rot[i, 2, 2] * f[2]
    out[row, 0] += fx
    out[row, 1] += fy
    out[row, 2] += fz
    for k in range(3):
        out[row, 3 + k] += rot[i, k, 0] * f[3] + rot[i, k, 1] * f[4] + rot[i, k, 2] * f[5]
    out[row, 3] += p[i, 1] * fz - p[i, 2] * fy
    out[row, 4] += p[i, 2] * fx - p[i, 0] * fz
    out[row, 5] += p[i, 0] * fy - p[i, 1] * fx


@_jit
def _add_inertia_to_parent(
    rot: FloatArray, p: FloatArray, i: int, inertia: FloatArray, work: FloatArray, out: FloatArray
) -> None:
    """``out[i - 1] += X_i^T I X_i``: a symmetric 6x6 inertia in joint i's frame added to one in its parent's.

    ``X = [[R^T, -R^T P], [0, R^T]]`` (``P = [p]x``) maps the parent's motion to the child's. With the rotated blocks
    ``A = R I_ll R^T``, ``B = R I_la R^T``, ``C = R I_aa R^T`` the result is ``[[A, B - A P], [.., C - B^T P + P (B - A P)]]``
    (``work`` a (9, 3) scratch: ``I_block R^T``, then ``A``, ``B``, ``C`` by rows of three, then ``B - A P``).
    """
    out_row = i - 1
    for block, (blk_r, blk_c) in enumerate(((0, 0), (0, 3), (3, 3))):
        for k in range(3):
            i0, i1, i2 = inertia[blk_r + k, blk_c], inertia[blk_r + k, blk_c + 1], inertia[blk_r + k, blk_c + 2]
            for s in range(3):
                work[k, s] = i0 * rot[i, s, 0] + i1 * rot[i, s, 1] + i2 * rot[i, s, 2]
        for r in range(3):
            for s in range(3):
                value = rot[i, r, 0] * work[0, s] + rot[i, r, 1] * work[1, s] + rot[i, r, 2] * work[2, s]
                out[out_row, blk_r + r, blk_c + s] += value  # A and C land in place; B is corrected below
                if block == 1:
                    work[3 + r, s] = value  # B
                elif block == 0:
                    work[6 + r, s] = value  # A
    px, py, pz = p[i, 0], p[i, 1], p[i, 2]
    # B2 = B - A P into rows 0-2 (P = [[0, -pz, py], [pz, 0, -px], [-py, px, 0]])
    for r in range(3):
        a0, a1, a2 = work[6 + r, 0], work[6 + r, 1], work[6 + r, 2]
        work[r, 0] = work[3 + r, 0] - (a1 * pz - a2 * py)
        work[r, 1] = work[3 + r, 1] - (a2 * px - a0 * pz)
        work[r, 2] = work[3 + r, 2] - (a0 * py - a1 * px)
    for r in range(3):
        for s in range(3):
            out[out_row, r, 3 + s] += work[r, s] - work[3 + r, s]  # B was added above: leave B2
            out[out_row, 3 + s, r] += work[r, s]
            b0, b1, b2 = work[3, r], work[4, r], work[5, r]  # column r of B
            if s == 0:
                btp = b1 * pz - b2 * py
            elif s == 1:
                btp = b2 * px - b0 * pz
            else:
                btp = b0 * py - b1 * px
            if r == 0:
                pb2 = py * work[2, s] - pz * work[1, s]
            elif r == 1:
                pb2 = pz * work[0, s] - px * work[2, s]
            else:
                pb2 = px * work[1, s] - py * work[0, s]
            out[out_row, 3 + r, 3 + s] += pb2 - btp


@_inline
def _kinematics(
    rotation: FloatArray,
    translation: FloatArray,
    axis: FloatArray,
    q: FloatArray,
    dq: FloatArray,
    rot: FloatArray,
    v: FloatArray,
    c: FloatArray,
) -> None:
    """Joint rotations ``rot`` (n, 3, 3), body velocities ``v`` (n + 1, 6; row 0 the base) and velocity-product
    accelerations ``c[i] = v[i + 1] x S_i dq_i`` (n, 6) of a state."""
    _joint_transforms(rotation, axis, q, rot)
    for k in range(6):
        v[0, k] = 0.0
    for i in range(q.shape[0]):
        _motion_to_child(rot, translation, i, v, v)
        wx, wy, wz = axis[i, 0] * dq[i], axis[i, 1] * dq[i], axis[i, 2] * dq[i]
        v[i + 1, 3] += wx
        v[i + 1, 4] += wy
        v[i + 1, 5] += wz
        c[i, 0] = v[i + 1, 1] * wz - v[i + 1, 2] * wy
        c[i, 1] = v[i + 1, 2] * wx - v[i + 1, 0] * wz
        c[i, 2] = v[i + 1, 0] * wy - v[i + 1, 1] * wx
        c[i, 3] = v[i + 1, 4] * wz - v[i + 1, 5] * wy
        c[i, 4] = v[i + 1, 5] * wx - v[i + 1, 3] * wz
        c[i, 5] = v[i + 1, 3] * wy - v[i + 1, 4] * wx


@_inline
def _bias_force(inertia: FloatArray, i: int, v: FloatArray, out: FloatArray) -> None:
    """``out[i] = v x* (I v)`` with ``I = inertia[i]``, ``v = v[i + 1]``: ``(w x h_l, w x h_n + v_l x h_l)``, ``h = I v``."""
    h = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    h0, h1, h2, h3, h4, h5 = h
    for s in range(6):
        vs = v[i + 1, s]
        h0 += inertia[i, 0, s] * vs
        h1 += inertia[i, 1, s] * vs
        h2 += inertia[i, 2, s] * vs
        h3 += inertia[i, 3, s] * vs
        h4 += inertia[i, 4, s] * vs
        h5 += inertia[i, 5, s] * vs
    h = (h0, h1, h2, h3, h4, h5)
    v0, v1, v2, v3, v4, v5 = v[i + 1, 0], v[i + 1, 1], v[i + 1, 2], v[i + 1, 3], v[i + 1, 4], v[i + 1, 5]
    out[i, 0] = v4 * h[2] - v5 * h[1]
    out[i, 1] = v5 * h[0] - v3 * h[2]
    out[i, 2] = v3 * h[1] - v4 * h[0]
    out[i, 3] = v4 * h[5] - v5 * h[4] + v1 * h[2] - v2 * h[1]
    out[i, 4] = v5 * h[3] - v3 * h[5] + v2 * h[0] - v0 * h[2]
    out[i, 5] = v3 * h[4] - v4 * h[3] + v0 * h[1] - v1 * h[0]


Kinematics = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
Scratch = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


@_inline
def _rnea_pass(
    chain: ChainArrays, kinematics: Kinematics, ddq: FloatArray, tau: FloatArray, a: FloatArray, f: FloatArray
) -> None:
    """Recursive Newton-Euler after :func:`_kinematics` (``kinematics``: :func:`_kinematics_scratch` filled by it):
    ``tau`` (n,) for accelerations ``ddq`` (n,); ``a`` (n + 1, 6) and ``f`` (n, 6) are scratch (accelerations, forces).
    """
    _, translation, axis, inertia, armature, base_acceleration = chain
    rot, v, c, _ = kinematics
    n = ddq.shape[0]
    for k in range(6):
        a[0, k] = base_acceleration[k]
    for i in range(n):
        _motion_to_child(rot, translation, i, a, a)
        for k in range(3):
            a[i + 1, 3 + k] += axis[i, k] * ddq[i]
        for k in range(6):
            a[i + 1, k] += c[i, k]
        _bias_force(inertia, i, v, f)
        for r in range(6):
            total = 0.0
            for s in range(6):
                total += inertia[i, r, s] * a[i + 1, s]
            f[i, r] += total
    for i in range(n - 1, -1, -1):
        tau[i] = axis[i, 0] * f[i, 3] + axis[i, 1] * f[i, 4] + axis[i, 2] * f[i, 5] + armature[i] * ddq[i]
        if i > 0:
            _add_force_to_parent(rot, translation, i, f[i], f, i - 1)


@_inline
def _aba_pass(chain: ChainArrays, kinematics: Kinematics, tau: FloatArray, ddq: FloatArray, scratch: Scratch) -> None:
    """Articulated-body algorithm after :func:`_kinematics` (see :func:`_rnea_pass`): ``ddq`` (n,) for joint torques
    ``tau`` (n,); ``scratch``: :func:`_aba_scratch`."""
    _, translation, axis, inertia, armature, base_acceleration = chain
    rot, v, c, _ = kinematics
    n = tau.shape[0]
    a, p_a, big_i, u_vec, du, ia, pa, work = scratch
    d, u = du[0], du[1]
    for i in range(n):
        for r in range(6):
            for s in range(6):
                big_i[i, r, s] = inertia[i, r, s]
    for i in range(n):
        _bias_force(inertia, i, v, p_a)
    for i in range(n - 1, -1, -1):
        for r in range(6):
            u_vec[i, r] = big_i[i, r, 3] * axis[i, 0] + big_i[i, r, 4] * axis[i, 1] + big_i[i, r, 5] * axis[i, 2]
        d[i] = axis[i, 0] * u_vec[i, 3] + axis[i, 1] * u_vec[i, 4] + axis[i, 2] * u_vec[i, 5] + armature[i]
        u[i] = tau[i] - (axis[i, 0] * p_a[i, 3] + axis[i, 1] * p_a[i, 4] + axis[i, 2] * p_a[i, 5])
        if i > 0:
            for r in range(6):
                scaled = u_vec[i, r] / d[i]
                for s in range(6):
                    ia[r, s] = big_i[i, r, s] - scaled * u_vec[i, s]
            for r in range(6):
                total = 0.0
                for s in range(6):
                    total += ia[r, s] * c[i, s]
                pa[r] = total + p_a[i, r] + u_vec[i, r] * u[i] / d[i]
            _add_inertia_to_parent(rot, translation, i, ia, work, big_i)
            _add_force_to_parent(rot, translation, i, pa, p_a, i - 1)
    for k in range(6):
        a[0, k] = base_acceleration[k]
    for i in range(n):
        _motion_to_child(rot, translation, i, a, a)
        total = 0.0
        for k in range(6):
            a[i + 1, k] += c[i, k]
            total += u_vec[i, k] * a[i + 1, k]
        ddq[i] = (u[i] - total) / d[i]
        for k in range(3):
            a[i + 1, 3 + k] += axis[i, k] * ddq[i]


@_jit
def _aba_scratch(n: int) -> Scratch:
    """Scratch of :func:`_aba_pass` (and of :func:`_rnea_pass`: the first and second arrays) for n joints."""
    return (
        np.empty((n + 1, 6)),  # accelerations, row 0 the base
        np.empty((n, 6)),  # (articulated) bias forces
        np.empty((n, 6, 6)),  # articulated inertias
        np.empty((n, 6)),  # U = I^A S
        np.empty((2, n)),  # D, u
        np.empty((6, 6)),  # Ia
        np.empty(6),  # pa
        np.empty((9, 3)),  # the inertia transform's scratch
    )


@_jit
def _closed_loop_acceleration(
    plant: ChainArrays,
    controller: ChainArrays,
    q: FloatArray,
    dq: FloatArray,
    feedforward: FloatArray,
    row: int,
    kp: float,
    kd: float,
    rigid: FloatArray,
    ddq: FloatArray,
    kinematics: Kinematics,
    scratch: Scratch,
) -> None:
    """``rigid = RNEA_c(q, dq, feedforward[row] - Kp q - Kd dq)`` and ``ddq = ABA(q, dq, rigid)`` (the servoed plant).

    The controller's chain differs from the plant's in its inertias and rotor inertias only (the same geometry), so
    the kinematics are computed once. ``kinematics``: scratch ``(rot (n, 3, 3), v (n + 1, 6), c (n, 6), command (n,))``.
    """
    rot, v, c, command = kinematics
    for k in range(q.shape[0]):
        command[k] = feedforward[row, k] - kp * q[k] - kd * dq[k]
    _kinematics(plant[0], plant[1], plant[2], q, dq, rot, v, c)
    _rnea_pass(controller, kinematics, command, rigid, scratch[0], scratch[1])
    _aba_pass(plant, kinematics, rigid, ddq, scratch)


@_jit
def _kinematics_scratch(n: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Scratch of :func:`_kinematics` and the servo's command for n joints."""
    return np.empty((n, 3, 3)), np.empty((n + 1, 6)), np.empty((n, 6)), np.empty(n)


@_jit
def rk4_period(
    plant: ChainArrays,
    controller: ChainArrays,
    q: FloatArray,
    dq: FloatArray,
    feedforward: FloatArray,
    kp: float,
    kd: float,
    h: float,
) -> tuple[FloatArray, FloatArray]:
    """``m`` classical RK4 steps of length ``h`` s of the servoed arm: the new ``(q, dq)`` (n,) each.

    Args:
        plant, controller: :func:`chain_arrays` of the true and the controller's chain (the same geometry).
        q, dq: the state at the start, rad, rad/s.
        feedforward: ``ddq_r + Kp q_r + Kd dq_r`` at the RK4 stage times ``t + i h / 2``, shape (2 m + 1, n).
        kp, kd: the controller's gains, 1/s^2, 1/s.
        h: the RK4 step, s.
    """
    n = q.shape[0]
    q, dq = q.copy(), dq.copy()
    stages = np.empty((11, n))
    rigid, a1, a2, a3, a4, q2, dq2, q3, dq3, q4, dq4 = stages
    kinematics, scratch = _kinematics_scratch(n), _aba_scratch(n)
    half, sixth = 0.5 * h, h / 6.0
    for s in range(0, feedforward.shape[0] - 1, 2):
        _closed_loop_acceleration(plant, controller, q, dq, feedforward, s, kp, kd, rigid, a1, kinematics, scratch)
        for k in range(n):
            q2[k], dq2[k] = q[k] + half * dq[k], dq[k] + half * a1[k]
        _closed_loop_acceleration(plant, controller, q2, dq2, feedforward, s + 1, kp, kd, rigid, a2, kinematics, scratch)
        for k in range(n):
            q3[k], dq3[k] = q[k] + half * dq2[k], dq[k] + half * a2[k]
        _closed_loop_acceleration(plant, controller, q3, dq3, feedforward, s + 1, kp, kd, rigid, a3, kinematics, scratch)
        for k in range(n):
            q4[k], dq4[k] = q[k] + h * dq3[k], dq[k] + h * a3[k]
        _closed_loop_acceleration(plant, controller, q4, dq4, feedforward, s + 2, kp, kd, rigid, a4, kinematics, scratch)
        for k in range(n):
            q[k] = q[k] + sixth * (dq[k] + 2.0 * (dq2[k] + dq3[k]) + dq4[k])
            dq[k] = dq[k] + sixth * (a1[k] + 2.0 * (a2[k] + a3[k]) + a4[k])
    return q, dq


@_jit
def constant_acceleration_period(
    plant: ChainArrays,
    controller: ChainArrays,
    q: FloatArray,
    dq: FloatArray,
    q_ref: FloatArray,
    dq_ref: FloatArray,
    ddq_ref: FloatArray,
    stage_offsets: FloatArray,
    kp: float,
    kd: float,
    h: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """One sample period tracking ``q_r(tau) = q_ref + dq_ref tau + ddq_ref tau^2 / 2`` (n,) each, then a sample.

    Args:
        plant, controller, q, dq, kp, kd, h: as in :func:`rk4_period`.
        stage_offsets: the RK4 stage times from the period's start, ``i h / 2``, shape (2 m + 1,), s.

    Returns:
        ``(q, dq)`` at the period's end, the rigid-body torque ``RNEA_c`` (n,) N m and the plant's ``ddq`` (n,) there,
        and the reference's angles and rates there (n,) each.
    """
    m, n = stage_offsets.shape[0], q.shape[0]
    feedforward, q_end, dq_end = np.empty((m, n)), np.empty(n), np.empty(n)
    for i in range(m):
        tau = stage_offsets[i]
        for j in range(n):
            q_r = q_ref[j] + dq_ref[j] * tau + 0.5 * ddq_ref[j] * (tau * tau)
            dq_r = dq_ref[j] + ddq_ref[j] * tau
            feedforward[i, j] = ddq_ref[j] + kp * q_r + kd * dq_r
            q_end[j], dq_end[j] = q_r, dq_r
    q, dq = rk4_period(plant, controller, q, dq, feedforward, kp, kd, h)
    rigid, ddq = np.empty(n), np.empty(n)
    _closed_loop_acceleration(
        plant, controller, q, dq, feedforward, m - 1, kp, kd, rigid, ddq, _kinematics_scratch(n), _aba_scratch(n)
    )
    return q, dq, rigid, ddq, q_end, dq_end


def servo_sample(
    chains: tuple[ChainArrays, ChainArrays], q: FloatArray, dq: FloatArray, feedforward: FloatArray, gains: tuple[float, float]
) -> tuple[FloatArray, FloatArray]:
    """At one state (n,) each: the rigid-body part of the motor torque ``RNEA_c(q, dq, v)`` (n,) N m and the plant's
    ``ddq`` (n,) rad/s^2, for the (plant, controller) ``chains``, ``feedforward`` (n,) and ``gains`` ``(Kp, Kd)`` as in
    :func:`rk4_period`."""
    n = q.shape[0]
    rigid, ddq = np.empty(n), np.empty(n)
    stage = (np.ascontiguousarray(feedforward, dtype=float).reshape(1, n), 0, *gains)
    _closed_loop_acceleration(*chains, q, dq, *stage, rigid, ddq, _kinematics_scratch(n), _aba_scratch(n))
    return rigid, ddq


def chain_arrays(chain: SerialChain) -> ChainArrays:
    """The arrays of a chain as the tuple the compiled functions take."""
    return (chain.rotation, chain.translation, chain.axis, chain.inertia, chain.armature, chain.base_acceleration)
