"""SO(3) helpers: exponential map, inverse of its differential, quaternions (scalar first).

``so3_exp`` and ``dexp_inv`` are compiled with numba: they run inside the simulator's integration
kernel, where numpy's per-call overhead would dominate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray


@njit(cache=True)
def so3_exp(theta: FloatArray) -> FloatArray:
    """Rotation matrix ``exp([theta]x)`` (Rodrigues), ``theta`` shape (3,) in rad."""
    x, y, z = theta[0], theta[1], theta[2]
    angle2 = x * x + y * y + z * z
    if angle2 < 1e-10:
        a, b = 1.0 - angle2 / 6.0, 0.5 - angle2 / 24.0
    else:
        angle = math.sqrt(angle2)
        a, b = math.sin(angle) / angle, (1.0 - math.cos(angle)) / angle2
    rot = np.empty((3, 3))
    rot[0, 0], rot[0, 1], rot[0, 2] = 1.0 - b * (y * y + z * z), -a * z + b * x * y, a * y + b * x * z
    rot[1, 0], rot[1, 1], rot[1, 2] = a * z + b * x * y, 1.0 - b * (x * x + z * z), -a * x + b * y * z
    rot[2, 0], rot[2, 1], rot[2, 2] = -a * y + b * x * z, a * x + b * y * z, 1.0 - b * (x * x + y * y)
    return rot


@njit(cache=True)
def dexp_inv(theta: FloatArray, omega: FloatArray) -> FloatArray:
    """``d theta / dt`` for ``R(t) = R0 exp([theta(t)]x)`` whose body rate is ``omega``; shapes (3,).

    The inverse of the right Jacobian of SO(3):
    ``omega + 1/2 theta x omega + c(|theta|) theta x (theta x omega)``,
    ``c = 1/|theta|^2 - (1 + cos|theta|) / (2 |theta| sin|theta|)`` (-> 1/12 as |theta| -> 0).
    """
    angle2 = theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2]
    if angle2 < 1e-8:
        c = 1.0 / 12.0 + angle2 / 720.0
    else:
        angle = math.sqrt(angle2)
        c = 1.0 / angle2 - (1.0 + math.cos(angle)) / (2.0 * angle * math.sin(angle))
    t_w = np.cross(theta, omega)
    return omega + 0.5 * t_w + c * np.cross(theta, t_w)


@njit(cache=True)
def quat_from_matrix(rot: FloatArray) -> FloatArray:
    """Unit quaternion ``[w, x, y, z]`` (scalar first, w >= 0) of a rotation matrix (3, 3)."""
    m = rot
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    q = np.empty(4)
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q[0], q[1], q[2], q[3] = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    else:
        i = 0
        if m[1, 1] > m[i, i]:
            i = 1
        if m[2, 2] > m[i, i]:
            i = 2
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q /= math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q if q[0] >= 0.0 else -q


@njit(cache=True)
def quat_from_rotation_vector(theta: FloatArray) -> FloatArray:
    """Unit quaternion ``[w, x, y, z]`` of the rotation ``exp([theta]x)``, ``theta`` shape (3,)."""
    angle = math.sqrt(theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2])
    half = 0.5 * angle
    s = 0.5 - angle * angle / 48.0 if angle < 1e-6 else math.sin(half) / angle
    return np.array([math.cos(half), s * theta[0], s * theta[1], s * theta[2]])


@njit(cache=True)
def quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a b`` of quaternions ``[w, x, y, z]`` (rotation ``a`` after ``b`` in the body)."""
    return np.array(
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    )


def matrix_from_quat(quat_wxyz: FloatArray) -> FloatArray:
    """Rotation matrix of a quaternion ``[w, x, y, z]`` (normalised first)."""
    w, x, y, z = np.asarray(quat_wxyz, dtype=float) / np.linalg.norm(quat_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
