"""The arm's dynamics as a linear model ``tau = Y(q, dq, ddq) p``, and its base (identifiable) parameters.

Parameters ``p`` (length ``10 n + k n``), in this order:

* per moving body k = 1..n (body k is the link moved by joint k, frame = pinocchio's joint frame
  k, see :mod:`spaceid_gym.arm.arm_robot`), pinocchio's dynamic parameters of that body, about the
  frame's **origin** and in the frame's axes (not about the CoM)::

      linkk_mass_kg, linkk_mcx_kgm, linkk_mcy_kgm, linkk_mcz_kgm,
      linkk_ixx_kgm2, linkk_ixy_kgm2, linkk_iyy_kgm2, linkk_ixz_kgm2, linkk_iyz_kgm2, linkk_izz_kgm2

  (``mc = m c`` the first moment; ``I = I_C + m S(c)^T S(c)`` the inertia at the origin); this is
  the source document's ``[Ixx, Ixy, Ixz, Iyy, Iyz, Izz, m rx, m ry, m rz, m]`` reordered;
* then the friction coefficients, joint-major (``joint1_coulomb_Nm, joint1_viscous_Nms,
  joint2_coulomb_Nm, ...``), see :mod:`spaceid_gym.arm.friction`;
* then, with ``armature=True``, one rotor inertia per joint reflected through its gear,
  ``jointj_armature_kgm2`` (``tau_j += I_a,j ddq_j``; pinocchio's ``model.armature``), which the
  link parameters cannot express for the UR5's first joints.

``Y`` has shape (T, n, p): ``tau[t, j] = Y[t, j, :] @ p`` (N m). Stacking samples for least
squares (:func:`stack`) is **sample-major**: row ``t n + j`` is joint j of sample t.

Base parameters
---------------
Some parameters never change the torques (link 1's mass on a vertical joint 1) and others act only
in fixed combinations (link 3's mass adds to link 2's first moment through the 0.425 m upper arm).
:class:`BaseParameterSet` finds, from the regressor at many random states, a set of ``r``
independent columns ``Y_b = Y[..., independent]`` and the matrix ``K`` (r, p) with
``Y p = Y_b (K p)`` for every ``p``: the base parameters are ``beta = K p``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg
from numpy.typing import NDArray

from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.physics.inertia import PARAMS10_NAMES

IntArray = NDArray[np.int64]

#: Name suffixes of a body's 10 inertial parameters, in pinocchio's order.
INERTIAL_FIELDS: tuple[str, ...] = PARAMS10_NAMES


#: A stacked-regressor column whose norm is below this fraction of the largest column's is treated as zero.
_ZERO_COLUMN_RTOL = 1e-10


class ArmRegressor:
    """``Y(q, dq, ddq)`` of a fixed-base arm: rigid-body columns from pinocchio plus friction columns.

    Not thread safe (it caches one ``pinocchio.Data``): use one instance per thread.

    Args:
        robot: the arm.
        friction: a :class:`FrictionModel`, or the names of its terms (``("coulomb", "viscous")``,
            default), or ``None`` / ``()`` for rigid-body parameters only.
        armature: add one rotor-inertia column per joint (kg m^2), after the friction (default False).

    Attributes:
        robot, friction: as given (``friction`` as a :class:`FrictionModel`).
        parameter_names: names of the p parameters (see the module docstring).
        n_inertial: 10 n, the number of rigid-body parameters (they come first).
        armature: whether the last n parameters are rotor inertias.
    """

    def __init__(
        self,
        robot: ArmRobot,
        friction: FrictionModel | Sequence[str] | None = ("coulomb", "viscous"),
        armature: bool = False,
    ) -> None:
        self.robot = robot
        self.friction = FrictionModel.coerce(friction)
        self.armature = bool(armature)
        self._data = robot.create_data()
        n = robot.n_joints
        self.n_inertial = 10 * n
        inertial_names = [f"link{k + 1}_{field}" for k in range(n) for field in INERTIAL_FIELDS]
        armature_names = [f"joint{j + 1}_armature_kgm2" for j in range(n)] if self.armature else []
        self.parameter_names: tuple[str, ...] = (*inertial_names, *self.friction.parameter_names(n), *armature_names)
        k = self.friction.n_terms  # joint j's friction coefficients are columns n_inertial + j k .. + k - 1
        self._friction_rows, self._friction_columns = np.repeat(np.arange(n), k), self.n_inertial + np.arange(n * k)
        self._joints, self._armature_columns = np.arange(n), self.n_inertial + n * k + np.arange(n)

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return self.robot.n_joints

    @property
    def n_parameters(self) -> int:
        """Number of parameters p = 10 n + k n."""
        return len(self.parameter_names)

    def regressor(self, q_rad: FloatArray, dq_rad_s: FloatArray, ddq_rad_s2: FloatArray) -> FloatArray:
        """``Y``, shape (T, n, p), N m per unit parameter, for states of shape (T, n) each (or (n,) for T = 1).

        The rigid-body part is ``pinocchio.computeJointTorqueRegressor`` per sample (gravity of the
        robot included); the friction part is block diagonal (joint j's coefficients act on joint j).
        """
        q, dq, ddq = self._states(q_rad, dq_rad_s, ddq_rad_s2)
        out = np.zeros((q.shape[0], q.shape[1], self.n_parameters))
        model, data = self.robot.model, self._data
        for t in range(q.shape[0]):
            out[t, :, : self.n_inertial] = pin.computeJointTorqueRegressor(model, data, q[t], dq[t], ddq[t])
        n_samples = q.shape[0]
        out[:, self._friction_rows, self._friction_columns] = self.friction.features(dq).reshape(n_samples, -1)
        if self.armature:
            out[:, self._joints, self._armature_columns] = ddq
        return out

    def state_regressor(self, q_rad: FloatArray, dq_rad_s: FloatArray, ddq_rad_s2: FloatArray) -> FloatArray:
        """``Y`` at one state, shape (n, p): :meth:`regressor` without its input checks, for states a simulator made.

        Args:
            q_rad, dq_rad_s, ddq_rad_s2: finite float arrays of shape (n,) each (not checked).
        """
        out = np.zeros((self.n_joints, self.n_parameters))
        out[:, : self.n_inertial] = pin.computeJointTorqueRegressor(self.robot.model, self._data, q_rad, dq_rad_s, ddq_rad_s2)
        out[self._friction_rows, self._friction_columns] = self.friction.features(dq_rad_s).ravel()
        if self.armature:
            out[self._joints, self._armature_columns] = ddq_rad_s2
        return out

    def torque(self, q_rad: FloatArray, dq_rad_s: FloatArray, ddq_rad_s2: FloatArray, parameters: FloatArray) -> FloatArray:
        """Predicted joint torques ``Y p``, shape (T, n), N m, for parameters of shape (p,)."""
        p = self._parameters(parameters)
        return self.regressor(q_rad, dq_rad_s, ddq_rad_s2) @ p

    def nominal_parameters(self) -> FloatArray:
        """The URDF's inertial parameters and zero friction, shape (p,)."""
        return self.parameters_of_model(self.robot.model)

    def parameters_of_model(self, model: pin.Model) -> FloatArray:
        """Inertial parameters of a pinocchio model with the robot's structure, friction zero, its armature, shape (p,)."""
        if model.njoints != self.n_joints + 1:
            raise SpaceIdInputError(f"parameters_of_model: model has {model.njoints - 1} joints, the robot {self.n_joints}")
        out = np.zeros(self.n_parameters)
        out[: self.n_inertial] = np.concatenate([model.inertias[k].toDynamicParameters() for k in range(1, model.njoints)])
        if self.armature:
            out[-self.n_joints :] = model.armature
        return out

    def model_with_parameters(self, parameters: FloatArray) -> pin.Model:
        """A copy of the robot's pinocchio model whose bodies have the given inertial parameters.

        Friction coefficients in ``parameters`` are ignored (pinocchio models no friction); armature goes
        to ``model.armature``. The parameters need not be physically consistent (pinocchio stores them as given).
        """
        p = self._parameters(parameters)
        model = pin.Model(self.robot.model)
        for k in range(1, model.njoints):
            model.inertias[k] = pin.Inertia.FromDynamicParameters(p[10 * (k - 1) : 10 * k].copy())
        if self.armature:
            model.armature = p[-self.n_joints :].copy()
        return model

    def _parameters(self, parameters: FloatArray) -> FloatArray:
        p = np.asarray(parameters, dtype=float)
        if p.shape != (self.n_parameters,):
            raise SpaceIdInputError(f"parameters must have shape ({self.n_parameters},) (see parameter_names), got {p.shape}")
        return p

    def _states(self, q: FloatArray, dq: FloatArray, ddq: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        n = self.n_joints
        arrays = []
        for name, value in (("q_rad", q), ("dq_rad_s", dq), ("ddq_rad_s2", ddq)):
            array = np.asarray(value, dtype=float)
            if array.ndim == 1:
                array = array[None, :]
            if array.ndim != 2 or array.shape[1] != n:
                raise SpaceIdInputError(f"regressor: {name} must have shape (T, {n}), got {np.shape(value)}")
            if not np.isfinite(array).all():
                row = int(np.argmax(~np.isfinite(array).all(axis=1)))
                raise SpaceIdInputError(f"regressor: {name} has a non-finite value at sample {row}")
            arrays.append(np.ascontiguousarray(array))
        if not arrays[0].shape == arrays[1].shape == arrays[2].shape:
            raise SpaceIdInputError(
                f"regressor: q, dq, ddq must have the same shape, got {arrays[0].shape}, {arrays[1].shape}, {arrays[2].shape}"
            )
        return arrays[0], arrays[1], arrays[2]


def stack(regressor: FloatArray, tau: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The stacked linear problem ``W p = y`` from ``Y`` (T, n, p) and torques (T, n).

    Row order is **sample-major**: row ``t n + j`` is joint j of sample t (``W = Y.reshape(T n, p)``).

    Returns:
        ``W`` shape (T n, p) and ``y`` shape (T n,).
    """
    Y = np.asarray(regressor, dtype=float)
    y = np.asarray(tau, dtype=float)
    if Y.ndim != 3 or y.shape != Y.shape[:2]:
        raise SpaceIdInputError(f"stack: expected Y of shape (T, n, p) and tau of shape (T, n), got {Y.shape} and {y.shape}")
    return Y.reshape(-1, Y.shape[2]), y.reshape(-1)


@dataclass(frozen=True, eq=False)
class BaseParameterSet:
    """The base (identifiable) parameters of a linear model and the map from the full parameters.

    ``beta = K p`` with ``K[:, independent] = I`` and ``K[:, dependent] = R_b^{-1} R_d``: each base
    parameter is one independent parameter plus the dependent ones regrouped into it, and
    ``Y p = Y[..., independent] @ beta`` for every full ``p``.

    Which columns are independent: the numerical rank ``r`` comes from a QR decomposition with
    column pivoting (``scipy.linalg.qr(pivoting=True)``) of the stacked regressor with unit-norm
    columns; the independent set is then chosen in the **natural parameter order** (a column is
    independent if it is not a combination of the columns before it: QR without pivoting, the
    classical numerical method of Gautier), so dependent parameters are regrouped into the earlier
    ones, as in the symbolic rules (a link's mass into the previous link's first moments), and the
    choice does not depend on how the random states happened to scale the columns. Entries of ``K``
    below 1e-10 in magnitude are set to zero (round-off of structural zeros).

    Back from base to full parameters: a base vector ``beta`` stands for the affine family
    ``{p : K p = beta} = p0 + span(null_space())``; every member predicts the same torques. The
    data cannot pick one; :meth:`full_parameters` returns the member closest to a reference (e.g.
    the URDF's values). A physically consistent estimator works in the full space (positive masses,
    positive-definite inertias, which ``beta`` cannot express) and uses ``K`` to compare or project.

    Attributes:
        parameter_names: names of the p full parameters.
        independent: indices of the r independent parameters (ascending), shape (r,).
        dependent: indices of the p - r regrouped parameters (ascending), shape (p - r,).
        K: the map ``beta = K p``, shape (r, p).
        names: each base parameter as the combination it stands for, e.g.
            ``"link2_mcx_kgm - 0.425 link3_mass_kg"`` (coefficients to 4 significant digits), shape (r,).
        r_diag: ``|R_ii| / |R_00|`` of the pivoted QR, shape (p,) (the rank gap, for diagnostics).
        tolerance: the rank threshold on ``r_diag``.
    """

    parameter_names: tuple[str, ...]
    independent: IntArray
    dependent: IntArray
    K: FloatArray
    names: tuple[str, ...]
    r_diag: FloatArray
    tolerance: float

    @property
    def rank(self) -> int:
        """Number of base parameters r."""
        return int(self.independent.size)

    @classmethod
    def from_regressor(
        cls,
        regressor: ArmRegressor,
        rng: np.random.Generator,
        n_samples: int = 300,
        tolerance: float = 1e-8,
    ) -> BaseParameterSet:
        """Base parameters of ``regressor`` from ``n_samples`` random states within the robot's limits.

        Args:
            regressor: the linear model.
            rng: seeded generator for the states (:meth:`ArmRobot.sample_states`).
            n_samples: number of random states (each gives n rows); 300 is ample for 6 joints.
            tolerance: rank threshold on ``|R_ii| / |R_00|`` with unit-norm columns.
        """
        q, dq, ddq = regressor.robot.sample_states(rng, n_samples)
        W, _ = stack(regressor.regressor(q, dq, ddq), np.zeros((n_samples, regressor.n_joints)))
        return cls.from_matrix(W, regressor.parameter_names, tolerance)

    @classmethod
    def from_matrix(cls, W: FloatArray, parameter_names: Sequence[str], tolerance: float = 1e-8) -> BaseParameterSet:
        """Base parameters of a stacked regressor ``W`` (m, p) whose columns are ``parameter_names``."""
        W = np.asarray(W, dtype=float)
        names = tuple(parameter_names)
        if W.ndim != 2 or W.shape[1] != len(names) or W.shape[0] < W.shape[1]:
            raise SpaceIdInputError(
                f"BaseParameterSet: W must have shape (m, p) with p = {len(names)} names and m >= p, got {W.shape}"
            )
        if not np.isfinite(W).all():
            raise SpaceIdInputError("BaseParameterSet: W has non-finite entries")
        norms = np.linalg.norm(W, axis=0)
        # A column of round-off (e.g. a first moment along an axis through a fixed point) is zero:
        # scaled to unit norm it would look like an independent random column.
        zero = norms <= _ZERO_COLUMN_RTOL * norms.max(initial=0.0)
        Wn = W / np.where(zero, 1.0, norms)
        Wn[:, zero] = 0.0

        _, R, _ = scipy.linalg.qr(Wn, mode="economic", pivoting=True)
        r_diag = np.abs(np.diag(R)) / max(abs(R[0, 0]), np.finfo(float).tiny)
        rank = int(np.count_nonzero(r_diag > tolerance))

        R_natural = scipy.linalg.qr(Wn, mode="r")[0]
        natural_diag = np.abs(np.diag(R_natural)) / max(abs(R[0, 0]), np.finfo(float).tiny)
        independent = np.flatnonzero(natural_diag > tolerance)
        if independent.size != rank:
            raise SpaceIdInputError(
                f"BaseParameterSet: the rank is ambiguous (pivoted QR: {rank}, natural order: {independent.size}); "
                "use more or better spread samples, or another tolerance"
            )
        dependent = np.setdiff1d(np.arange(len(names)), independent)

        # R_b^{-1} R_d of the QR of [W_b W_d], computed as the least-squares solution of W_b X = W_d
        # on the unit-norm columns (exact: W_d lies in the span of W_b), then unscaled
        Kd_scaled = scipy.linalg.lstsq(Wn[:, independent], Wn[:, dependent])[0]
        Kd = Kd_scaled / np.where(zero[independent], 1.0, norms[independent])[:, None] * norms[dependent][None, :]
        Kd[np.abs(Kd) < 1e-10] = 0.0
        K = np.zeros((rank, len(names)))
        K[np.arange(rank), independent] = 1.0
        K[:, dependent] = Kd
        for array in (independent, dependent, K, r_diag):
            array.flags.writeable = False
        return cls(
            parameter_names=names,
            independent=independent,
            dependent=dependent,
            K=K,
            names=tuple(_combination_name(names, row, i) for row, i in zip(K, independent, strict=True)),
            r_diag=r_diag,
            tolerance=float(tolerance),
        )

    def to_base(self, parameters: FloatArray) -> FloatArray:
        """``beta = K p`` for full parameters of shape (..., p); returns shape (..., r)."""
        return np.asarray(parameters, dtype=float) @ self.K.T

    def base_regressor(self, regressor: FloatArray) -> FloatArray:
        """``Y_b``: the independent columns of a regressor of shape (..., p); returns shape (..., r)."""
        return np.asarray(regressor, dtype=float)[..., self.independent]

    def null_space(self) -> FloatArray:
        """A basis ``N`` (p, p - r) of the parameter changes that leave every torque unchanged (``K N = 0``).

        Column i moves dependent parameter ``dependent[i]`` by 1 and compensates with the
        independent ones (not orthonormal; ``scipy.linalg.orth`` makes it so).
        """
        N = np.zeros((len(self.parameter_names), self.dependent.size))
        N[self.dependent, np.arange(self.dependent.size)] = 1.0
        N[self.independent, :] = -self.K[:, self.dependent]
        return N

    def full_parameters(self, beta: FloatArray, reference: FloatArray | None = None) -> FloatArray:
        """The full parameter vector with ``K p = beta`` closest (Euclidean) to ``reference`` (default 0), shape (p,)."""
        beta = np.asarray(beta, dtype=float)
        if beta.shape != (self.rank,):
            raise SpaceIdInputError(f"full_parameters: beta must have shape ({self.rank},), got {beta.shape}")
        p0 = np.zeros(len(self.parameter_names)) if reference is None else np.asarray(reference, dtype=float)
        if p0.shape != (len(self.parameter_names),):
            raise SpaceIdInputError(f"full_parameters: reference must have shape ({len(self.parameter_names)},), got {p0.shape}")
        correction = scipy.linalg.lstsq(self.K, beta - self.K @ p0)[0]  # minimum-norm solution
        return p0 + correction


def _combination_name(names: Sequence[str], row: FloatArray, own: int) -> str:
    """``"a + 0.425 b - 2 c"`` for ``beta = row @ p`` whose own (independent) parameter is ``names[own]``."""
    parts = [names[own]]
    for j in np.flatnonzero(row):
        if j == own:
            continue
        c = float(f"{float(row[j]):.10g}")  # the same structural value formats the same despite round-off
        magnitude = f"{abs(c):.4g}"
        parts.append(f"{'-' if c < 0 else '+'} {'' if magnitude == '1' else magnitude + ' '}{names[j]}")
    return " ".join(parts)
