"""SO(3) helpers: exponential map, inverse of its differential, quaternions (scalar first).

The functions on 3-vectors work on plain Python floats (``Vec3`` tuples): they are called a few
times per integration stage, where numpy's per-call overhead would dominate.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]


def cross(a: Vec3, b: Vec3) -> Vec3:
    """``a x b``."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _exp_coefficients(angle2: float) -> tuple[float, float]:
    """``(sin t / t, (1 - cos t) / t^2)`` for ``t^2 = angle2``, series near 0."""
    if angle2 < 1e-10:
        return 1.0 - angle2 / 6.0, 0.5 - angle2 / 24.0
    angle = math.sqrt(angle2)
    return math.sin(angle) / angle, (1.0 - math.cos(angle)) / angle2


def so3_exp(theta: Vec3 | FloatArray) -> FloatArray:
    """Rotation matrix ``exp([theta]x)`` (Rodrigues), ``theta`` in rad."""
    x, y, z = float(theta[0]), float(theta[1]), float(theta[2])
    a, b = _exp_coefficients(x * x + y * y + z * z)
    return np.array(
        [
            [1.0 - b * (y * y + z * z), -a * z + b * x * y, a * y + b * x * z],
            [a * z + b * x * y, 1.0 - b * (x * x + z * z), -a * x + b * y * z],
            [-a * y + b * x * z, a * x + b * y * z, 1.0 - b * (x * x + y * y)],
        ]
    )


def dexp_inv(theta: Vec3, omega: Vec3) -> Vec3:
    """``d theta / dt`` for ``R(t) = R0 exp([theta(t)]x)`` whose body rate is ``omega``.

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
    t_w = cross(theta, omega)
    t_t_w = cross(theta, t_w)
    return (
        omega[0] + 0.5 * t_w[0] + c * t_t_w[0],
        omega[1] + 0.5 * t_w[1] + c * t_t_w[1],
        omega[2] + 0.5 * t_w[2] + c * t_t_w[2],
    )


def quat_from_matrix(rot: FloatArray) -> FloatArray:
    """Unit quaternion ``[w, x, y, z]`` (scalar first, w >= 0) of a rotation matrix."""
    m = np.asarray(rot, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        q = np.empty(4)
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0.0 else -q


def quat_from_rotation_vector(theta: FloatArray) -> FloatArray:
    """Unit quaternion ``[w, x, y, z]`` of the rotation ``exp([theta]x)``."""
    x, y, z = (float(v) for v in theta)
    angle = math.sqrt(x * x + y * y + z * z)
    half = 0.5 * angle
    s = 0.5 - angle * angle / 48.0 if angle < 1e-6 else math.sin(half) / angle
    return np.array([math.cos(half), s * x, s * y, s * z])


def quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a b`` of quaternions ``[w, x, y, z]`` (rotation ``a`` after ``b`` in the body)."""
    aw, ax, ay, az = a.tolist()
    bw, bx, by, bz = b.tolist()
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
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
