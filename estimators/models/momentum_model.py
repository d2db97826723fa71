"""The identification model of the free-floating robot: base rate from joint motion, batched.

With zero system momentum the base twist satisfies ``(I_base + I_arm(q)) v = -h_arm(q, dq)``, where
``I_arm`` is the arm's composite spatial inertia and ``h_arm = H_bm dq`` the momentum of the arm's
own motion, both in the base frame (they do not depend on the base's parameters and are computed
once per log with pinocchio). Summing base and arm into one spatial inertia ``(m, c, Ic)`` gives the
closed form ``omega = -Ic^{-1} (L - c x P)`` with ``[P; L] = h_arm`` (the inverse of a spatial
inertia, with ``Ic`` the composite inertia about the composite CoM), evaluated here
for P parameter vectors times T samples in one compiled (numba) loop, no per-sample Python.

An unknown **payload** held by the last link (10 parameters ``pi`` about the last joint's origin,
in its frame) adds ``A_t pi`` to the composite's parameters (``A_t`` the frame change of the
parameters, linear) and ``G_t pi`` to the momentum (``G_t`` maps ``pi`` to the payload's momentum
for the last link's velocity relative to the base), both precomputed per sample.

Effects that change the system momentum (a non-zero total angular momentum, an external torque, a
moving internal mass) enter as an **extra momentum** per parameter set and sample, ``[P; L]`` (P, T, 6)
in the base frame about the base origin: ``M v = extra - h_arm`` (:meth:`MomentumModel.predict_twist`).

This model never touches the simulator's integration path: it needs only the log's ``q`` and ``dq``.
"""

from __future__ import annotations

import copy
import weakref

import numpy as np
import pinocchio as pin
from numba import njit
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.log import MeasurementLog
from spaceid_gym.physics.fuel import base_params10_after_fuel
from spaceid_gym.physics.inertia import SPATIAL_INERTIA_BASIS, point_mass_inertia, spatial_inertia_matrix, transform_params10
from spaceid_gym.robots import Robot

Samples = slice | NDArray[np.intp]

#: the models of each log (:meth:`MomentumModel.of`), dropped with the log
_SHARED: weakref.WeakKeyDictionary[MeasurementLog, list[MomentumModel]] = weakref.WeakKeyDictionary()


class MomentumModel:
    """Predicts the base angular velocity (base body frame) over a log, for many parameter sets.

    Args:
        robot: the robot (its URDF's full-tank base is the nominal base).
        log: the measurement window; only ``q_rad`` and ``dq_rad_s`` are used.

    Attributes:
        n_samples: T.
        arm_mass_kg: total arm mass.
    """

    def __init__(self, robot: Robot, log: MeasurementLog) -> None:
        self.robot = robot
        model = pin.Model(robot.model)
        model.inertias[1] = pin.Inertia.Zero()  # composite of the arm alone
        data = model.createData()
        q_full = pin.neutral(model)
        n = log.n_samples
        mass, lever = np.empty(n), np.empty((n, 3))
        inertia_com = np.empty((n, 3, 3))
        coupling = np.empty((n, 6, model.nv - 6))
        for i, q in enumerate(log.q_rad):
            q_full[7:] = q
            coupling[i] = pin.crba(model, data, q_full)[:6, 6:]
            arm = data.Ycrb[1]
            mass[i], lever[i], inertia_com[i] = arm.mass, arm.lever, arm.inertia
        first_moment = mass[:, None] * lever
        inertia_origin = inertia_com + mass[:, None, None] * point_mass_inertia(lever)
        self.arm_mass_kg = float(sum(model.inertias[i].mass for i in range(2, model.njoints)))
        self.n_samples = n
        self._first_moment = first_moment  # (T, 3), kg m, base frame
        # (T, 6) kg m^2 about the base origin: xx, xy, yy, xz, yz, zz (pinocchio's order)
        self._inertia6 = np.ascontiguousarray(inertia_origin[:, [0, 0, 1, 0, 1, 2], [0, 1, 1, 2, 2, 2]])
        self._coupling = coupling  # (T, 6, n), the base rows of the joint-space inertia: [P; L] per unit joint rate
        self._momentum = _arm_momentum(coupling, log.dq_rad_s)  # (T, 6), [P; L] of the arm's motion, base frame
        self._model, self._data = model, data
        self._q, self._dq = log.q_rad, log.dq_rad_s  # not the log itself: the models shared per log (:meth:`of`) must not keep it
        self._payload_terms: tuple[FloatArray, FloatArray] | None = None

    @classmethod
    def of(cls, robot: Robot, log: MeasurementLog) -> MomentumModel:
        """The model of ``robot`` on ``log``, built once per robot and log and then shared: its arm terms depend on
        nothing else, so every identification model fitted to the log (each candidate of a diagnosis) uses the same
        (the log's arrays are read-only; the robot must not be changed once used)."""
        shared = _SHARED.setdefault(log, [])
        for model in shared:
            if model.robot is robot:
                return model
        same_angles = (
            m
            for other, models in list(_SHARED.items())
            if other.q_rad.shape == log.q_rad.shape and np.array_equal(other.q_rad, log.q_rad)
            for m in models
        )
        model = next((m for m in same_angles if m.robot is robot), None)
        shared.append(cls(robot, log) if model is None else model.with_joint_rates(log.dq_rad_s))
        return shared[-1]

    def with_joint_rates(self, dq_rad_s: FloatArray) -> MomentumModel:
        """This model on the same joint angles with the joint rates ``dq_rad_s`` (T, n) instead: the arm's composite
        inertia is shared, its momentum recomputed (linear in the rates), the payload's maps made again when asked.
        :meth:`of` derives a log's model so from a log with the same joint angles (a log whose joint rates alone were
        moved, as the encoders' noise propagation moves them)."""
        # the arm's arrays are shared, not copied: no model writes to them once built
        dq = np.asarray(dq_rad_s, dtype=float)
        if dq.shape != self._dq.shape:
            raise ValueError(f"dq_rad_s: expected shape {self._dq.shape}, got {dq.shape}")
        other = copy.copy(self)
        other._momentum = _arm_momentum(self._coupling, dq)
        other._dq, other._payload_terms, other._data = dq, None, self._model.createData()
        return other

    # ------------------------------------------------------------------ predictions
    def predict(self, base10: FloatArray, payload10: FloatArray | None = None, samples: Samples = slice(None)) -> FloatArray:
        """Base angular velocity (rad/s, base body frame) for P parameter sets, shape (P, T, 3).

        Args:
            base10: base inertial parameters about the base-frame origin, pinocchio order, (P, 10).
            payload10: parameters of a payload on the last link about the last joint's origin in
                its frame, (P, 10), or ``None`` for no payload.
            samples: which samples of the log (default all).
        """
        base = np.atleast_2d(np.asarray(base10, dtype=float))
        arm = (self._first_moment[samples], self._inertia6[samples], self._momentum[samples])
        if payload10 is None:
            return _base_rate(base, self.arm_mass_kg, *arm)
        return np.ascontiguousarray(self.predict_twist(base, payload10, None, samples)[..., 3:])

    def predict_twist(
        self,
        base10: FloatArray,
        payload10: FloatArray | None = None,
        extra_momentum: FloatArray | None = None,
        samples: Samples = slice(None),
        extra_params10: FloatArray | None = None,
    ) -> FloatArray:
        """Base twist ``[v; omega]`` (m/s, rad/s, base axes) for P parameter sets, shape (P, T, 6).

        Args:
            base10, payload10: as in :meth:`predict`.
            extra_momentum: the system momentum not carried by the arm's joint motion, ``[P; L]`` about the
                base origin in base axes, (P, T, 6) (N s, N m s), for the samples selected; ``None`` for zero.
            samples: which samples of the log (default all).
            extra_params10: inertial parameters added to the composite per sample (P, T, 10) (a body moving inside
                the base, e.g. a displaced slosh mass), about the base origin; ``None`` for none.
        """
        base = np.atleast_2d(np.asarray(base10, dtype=float))
        n_p = base.shape[0]
        arm = (self._first_moment[samples], self._inertia6[samples], self._momentum[samples])
        n_t = arm[0].shape[0]
        extra = np.zeros((1, 1, 6)) if extra_momentum is None else np.asarray(extra_momentum, dtype=float)
        if extra_momentum is not None and extra.shape != (n_p, n_t, 6):
            raise ValueError(f"extra_momentum: expected shape {(n_p, n_t, 6)}, got {extra.shape}")
        if payload10 is None:
            payload, to_base, momentum_map = np.zeros((1, 10)), np.zeros((1, 10, 10)), np.zeros((1, 6, 10))
        else:
            payload = np.atleast_2d(np.asarray(payload10, dtype=float))
            maps = self._payload_maps()
            to_base, momentum_map = maps[0][samples], maps[1][samples]
        moving = np.zeros((1, 1, 10)) if extra_params10 is None else np.asarray(extra_params10, dtype=float)
        if extra_params10 is not None and moving.shape != (n_p, n_t, 10):
            raise ValueError(f"extra_params10: expected shape {(n_p, n_t, 10)}, got {moving.shape}")
        return _base_twist(
            base,
            payload,
            payload10 is not None,
            extra,
            extra_momentum is not None,
            moving,
            extra_params10 is not None,
            self.arm_mass_kg,
            *arm,
            to_base,
            momentum_map,
        )

    def mean_composite10(self, base10: FloatArray, payload10: FloatArray | None = None) -> FloatArray:
        """The whole robot's 10 parameters about the base origin (P, 10), averaged over the log's configurations."""
        base = np.atleast_2d(np.asarray(base10, dtype=float))
        arm = np.concatenate(([self.arm_mass_kg], self._first_moment.mean(axis=0), self._inertia6.mean(axis=0)))
        out = base + arm
        if payload10 is not None:
            out = out + np.atleast_2d(payload10) @ self._payload_maps()[0].mean(axis=0).T
        return out

    def predict_base_params(self, params10: FloatArray, samples: Samples = slice(None)) -> FloatArray:
        """Base rate for base parameters ``params10`` (P, 10) or (10,): (P, T, 3) or (T, 3)."""
        omega = self.predict(params10, None, samples)
        return omega[0] if np.ndim(params10) == 1 else omega

    def predict_fuel(self, theta: FloatArray, samples: Samples = slice(None)) -> FloatArray:
        """Base rate for fuel parameters ``theta = [mdf kg, bf m (3)]``, (P, 4) or (4,): (P, T, 3) or (T, 3)."""
        full = self.robot.base_full
        return self.predict_base_params(base_params10_after_fuel(full.to_params10(), full.com_m, theta), samples)

    def jacobian(
        self, base10: FloatArray, payload10: FloatArray | None = None, samples: Samples = slice(None)
    ) -> tuple[FloatArray, FloatArray | None]:
        """Analytic ``d omega / d base10`` and ``d omega / d payload10`` at one parameter set.

        From ``M v = -h`` with ``M`` the composite spatial inertia: ``dv/dp_k = -M^{-1} (B_k v + dh/dp_k)``.

        Returns:
            ``(d_base, d_payload)``, each (T, 3, 10) (rad/s per parameter unit); ``d_payload``
            is ``None`` without a payload.
        """
        base = np.asarray(base10, dtype=float)
        arm10 = np.concatenate((np.full((self.n_samples, 1), self.arm_mass_kg), self._first_moment, self._inertia6), axis=1)[
            samples
        ]
        composite10 = arm10 + base
        momentum = self._momentum[samples]
        if payload10 is not None:
            to_base, momentum_map = (m[samples] for m in self._payload_maps())
            payload = np.asarray(payload10, dtype=float)
            composite10 = composite10 + to_base @ payload
            momentum = momentum + momentum_map @ payload
        inverse = np.linalg.inv(spatial_inertia_matrix(composite10))  # (T, 6, 6)
        twist = -np.einsum("tab,tb->ta", inverse, momentum)  # (T, 6)
        basis_twist = np.einsum("kab,tb->tak", SPATIAL_INERTIA_BASIS, twist)  # (T, 6, 10): B_k v
        angular = inverse[:, 3:]  # only omega is measured
        d_base = -angular @ basis_twist
        if payload10 is None:
            return d_base, None
        return d_base, -angular @ (basis_twist @ to_base + momentum_map)

    def arm_terms(self, with_payload: bool) -> tuple[FloatArray, ...]:
        """The per-sample arrays of :func:`_base_twist` after the composite's own: the arm's first moment (T, 3),
        inertia entries (T, 6) and momentum (T, 6), and the payload maps ``A_t`` (T, 10, 10) and ``G_t`` (T, 6, 10)
        (placeholders without a payload)."""
        maps = self._payload_maps() if with_payload else (np.zeros((1, 10, 10)), np.zeros((1, 6, 10)))
        return self._first_moment, self._inertia6, self._momentum, *maps

    # ------------------------------------------------------------------ internals
    def _payload_maps(self) -> tuple[FloatArray, FloatArray]:
        """Per-sample ``A_t`` (T, 10, 10) and ``G_t`` (T, 6, 10) of the module docstring (computed once)."""
        if self._payload_terms is None:
            rot, pos, twist = self._last_link_motion()
            # row k of each sample's map: the k-th basis vector's parameters in the base frame; transposed: A_t
            to_base = np.swapaxes(transform_params10(np.eye(10), rot[:, None], pos[:, None]), 1, 2)
            # payload momentum in the last link's frame is B(pi) v_link; express it at the base origin
            local = np.einsum("kab,tb->tak", SPATIAL_INERTIA_BASIS, twist)  # (T, 6, 10)
            force_to_base = np.zeros((len(rot), 6, 6))
            force_to_base[:, :3, :3] = rot
            force_to_base[:, 3:, 3:] = rot
            skew_pos = np.zeros((len(rot), 3, 3))
            skew_pos[:, 0, 1], skew_pos[:, 0, 2], skew_pos[:, 1, 2] = -pos[:, 2], pos[:, 1], -pos[:, 0]
            skew_pos -= np.swapaxes(skew_pos, 1, 2)
            force_to_base[:, 3:, :3] = skew_pos @ rot
            self._payload_terms = (np.ascontiguousarray(to_base), np.ascontiguousarray(force_to_base @ local))
        return self._payload_terms

    def _last_link_motion(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Last link's rotation (T, 3, 3), position (T, 3) in the base frame and twist relative to the base, own frame (T, 6)."""
        model, data = self._model, self._data
        last = model.njoints - 1
        q_full, v_full = pin.neutral(model), np.zeros(model.nv)
        rot, pos, twist = np.empty((self.n_samples, 3, 3)), np.empty((self.n_samples, 3)), np.empty((self.n_samples, 6))
        for i, (q, dq) in enumerate(zip(self._q, self._dq, strict=True)):
            q_full[7:], v_full[6:] = q, dq
            pin.forwardKinematics(model, data, q_full, v_full)  # base at rest at the origin: joint motion only
            rot[i], pos[i], twist[i] = data.oMi[last].rotation, data.oMi[last].translation, data.v[last].vector
        return rot, pos, twist


#: a composite's CoM (3) and its inertia about the CoM inverted: the cofactors (6) and one over the determinant
CompositeInverse = tuple[float, float, float, float, float, float, float, float, float, float]


def _arm_momentum(coupling: FloatArray, dq_rad_s: FloatArray) -> FloatArray:
    """``[P; L]`` (T, 6) of the arm's motion: each sample's coupling (6, n) times its joint rates (n,), as a stacked
    matrix product (the same bits as one product per sample)."""
    return np.matmul(coupling, np.asarray(dq_rad_s, dtype=float)[:, :, None])[:, :, 0]


@njit(cache=True, inline="always")
def composite_inverse(
    mass: float, hx: float, hy: float, hz: float, j: tuple[float, float, float, float, float, float]
) -> CompositeInverse:
    """A composite (mass, first moment h, inertia entries j about the origin) ready to solve for its rate: its CoM
    ``(cx, cy, cz)``, the cofactors ``(c00, c01, c02, c11, c12, c22)`` of its inertia about the CoM and one over its
    determinant."""
    cx, cy, cz = hx / mass, hy / mass, hz / mass  # composite CoM, base frame
    # composite inertia about its CoM, Ic = J - m S(c): [[a b e] [b d f] [e f g]]
    a = j[0] - mass * (cy * cy + cz * cz)
    b = j[1] + mass * cx * cy
    d = j[2] - mass * (cx * cx + cz * cz)
    e = j[3] + mass * cx * cz
    f = j[4] + mass * cy * cz
    g = j[5] - mass * (cx * cx + cy * cy)
    c00, c01, c02 = d * g - f * f, e * f - b * g, b * f - d * e
    c11, c12, c22 = a * g - e * e, b * e - a * f, a * d - b * b
    inv_det = 1.0 / (a * c00 + b * c01 + e * c02)
    return cx, cy, cz, c00, c01, c02, c11, c12, c22, inv_det


@njit(cache=True, inline="always")
def rate_from_inverse(
    inverse: CompositeInverse, momentum: tuple[float, float, float, float, float, float]
) -> tuple[float, float, float]:
    """``omega`` of the composite of ``inverse`` (:func:`composite_inverse`) that carries ``-momentum``."""
    cx, cy, cz, c00, c01, c02, c11, c12, c22, inv_det = inverse
    px, py, pz = momentum[0], momentum[1], momentum[2]
    # the base carries -h_arm: omega = Ic^{-1} r with r = -(L - c x P)
    rx = -(momentum[3] - (cy * pz - cz * py))
    ry = -(momentum[4] - (cz * px - cx * pz))
    rz = -(momentum[5] - (cx * py - cy * px))
    return (
        (c00 * rx + c01 * ry + c02 * rz) * inv_det,
        (c01 * rx + c11 * ry + c12 * rz) * inv_det,
        (c02 * rx + c12 * ry + c22 * rz) * inv_det,
    )


@njit(cache=True, inline="always")
def twist_from_inverse(mass: float, inverse: CompositeInverse, momentum: FloatArray, out: FloatArray, i: int, t: int) -> None:
    """``out[i, t]`` = ``[v; omega]`` (6,) of the composite of ``mass`` and ``inverse`` (:func:`composite_inverse`) that
    carries ``-momentum`` (6,).

    ``P = m (v + omega x c)`` gives ``v = P / m - omega x c`` with ``P = -momentum[:3]``.
    """
    wx, wy, wz = rate_from_inverse(inverse, (momentum[0], momentum[1], momentum[2], momentum[3], momentum[4], momentum[5]))
    cx, cy, cz = inverse[0], inverse[1], inverse[2]
    out[i, t, 0] = -momentum[0] / mass - (wy * cz - wz * cy)
    out[i, t, 1] = -momentum[1] / mass - (wz * cx - wx * cz)
    out[i, t, 2] = -momentum[2] / mass - (wx * cy - wy * cx)
    out[i, t, 3], out[i, t, 4], out[i, t, 5] = wx, wy, wz


@njit(cache=True, inline="always")
def _rate_of_composite(
    mass: float,
    hx: float,
    hy: float,
    hz: float,
    j: tuple[float, float, float, float, float, float],
    momentum: tuple[float, float, float, float, float, float],
) -> tuple[float, float, float]:
    """``omega`` of a composite (mass, first moment h, inertia entries j about the origin) with momentum ``-h_arm``."""
    return rate_from_inverse(composite_inverse(mass, hx, hy, hz, j), momentum)


@njit(cache=True, inline="always")
def _twist_of_composite(
    mass: float, hx: float, hy: float, hz: float, j: FloatArray, momentum: FloatArray, out: FloatArray, i: int, t: int
) -> None:
    """``out[i, t]`` = ``[v; omega]`` (6,) of a composite that carries ``-momentum`` (6,) (:func:`twist_from_inverse`;
    ``j`` (6,) the inertia entries)."""
    twist_from_inverse(mass, composite_inverse(mass, hx, hy, hz, (j[0], j[1], j[2], j[3], j[4], j[5])), momentum, out, i, t)


@njit(cache=True, inline="always")
def _add_product(out: FloatArray, matrix: FloatArray, vector: FloatArray) -> None:
    """``out += matrix @ vector`` for a small matrix (n, m), without allocating."""
    for r in range(matrix.shape[0]):
        total = 0.0
        for c in range(matrix.shape[1]):
            total += matrix[r, c] * vector[c]
        out[r] += total


@njit(cache=True)
def _base_twist(
    params10: FloatArray,
    payload10: FloatArray,
    with_payload: bool,
    extra: FloatArray,
    with_extra: bool,
    moving: FloatArray,
    with_moving: bool,
    arm_mass: float,
    first: FloatArray,
    inertia6: FloatArray,
    momentum: FloatArray,
    to_base: FloatArray,
    momentum_map: FloatArray,
) -> FloatArray:
    """Twist (P, T, 6) with an optional payload (P, 10), extra momentum (P, T, 6) (``M v = extra - h_arm``) and moving body (P, T, 10)."""
    n_p, n_t = params10.shape[0], first.shape[0]
    out = np.empty((n_p, n_t, 6))
    j = np.empty(6)
    h = np.empty(6)
    comp = np.empty(10)
    for i in range(n_p):
        for t in range(n_t):
            # written out: through a shared helper (used by the tangent kernel at first) numba made this loop 2.3x slower
            for k in range(10):
                comp[k] = params10[i, k]
            for k in range(6):
                h[k] = momentum[t, k]
            if with_payload:
                _add_product(comp, to_base[t], payload10[i])
                _add_product(h, momentum_map[t], payload10[i])
            if with_extra:
                for k in range(6):
                    h[k] -= extra[i, t, k]
            if with_moving:
                for k in range(10):
                    comp[k] += moving[i, t, k]
            for k in range(6):
                j[k] = comp[4 + k] + inertia6[t, k]
            _twist_of_composite(
                comp[0] + arm_mass, comp[1] + first[t, 0], comp[2] + first[t, 1], comp[3] + first[t, 2], j, h, out, i, t
            )
    return out


@njit(cache=True)
def _base_rate(
    params10: FloatArray, arm_mass: float, first: FloatArray, inertia6: FloatArray, momentum: FloatArray
) -> FloatArray:
    """``omega`` (P, T, 3) for base parameters (P, 10) and per-sample arm terms (T, ...)."""
    n_p, n_t = params10.shape[0], first.shape[0]
    out = np.empty((n_p, n_t, 3))
    for i in range(n_p):
        mass = params10[i, 0] + arm_mass
        for t in range(n_t):
            out[i, t, 0], out[i, t, 1], out[i, t, 2] = _rate_of_composite(
                mass,
                params10[i, 1] + first[t, 0],
                params10[i, 2] + first[t, 1],
                params10[i, 3] + first[t, 2],
                (
                    params10[i, 4] + inertia6[t, 0],
                    params10[i, 5] + inertia6[t, 1],
                    params10[i, 6] + inertia6[t, 2],
                    params10[i, 7] + inertia6[t, 3],
                    params10[i, 8] + inertia6[t, 4],
                    params10[i, 9] + inertia6[t, 5],
                ),
                (momentum[t, 0], momentum[t, 1], momentum[t, 2], momentum[t, 3], momentum[t, 4], momentum[t, 5]),
            )
    return out
