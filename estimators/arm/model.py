"""The fixed-base arm's identification model: the base regressor in each log's effort unit, its problem, its predictions.

:class:`ArmIdentificationModel` ties together what :mod:`spaceid_gym.arm` provides (robot, friction,
regressor, base parameters) and what the estimators fit (:class:`~estimators.arm.linear_problem.LinearIdentificationProblem`):

* **unknowns**: the ``r`` base parameters ``beta = K p`` (:class:`~spaceid_gym.arm.regressor.BaseParameterSet`)
  of the full vector ``p`` = per-link params10 (kg, kg m, kg m^2, about each joint frame's origin),
  per-joint friction (N m, N m s/rad) and optionally per-joint armature (kg m^2);
* **effort units**: a torque log predicts ``Y_b beta`` (N m); a current log predicts
  ``Y_b beta / k_t`` (A), with ``k_t`` (n,) the torque constants (gear included, N m/A) the model is
  built with: parameters stay in SI units whatever the log holds. With approximate ``k_t`` (the real
  UR5's) a wrong gain ratio between joints shows as model error, not as a unit change;
* **rows**: sample-major over the logs given (row ``t n + j`` of each log is joint ``j``), grouped by joint
  (``row_group``) so that WLS estimates one noise level per joint;
* **search box** (what the metaheuristics search; least squares ignores it), a generous prior from the
  URDF, documented in :meth:`ArmIdentificationModel.full_box`; the box of ``beta`` is its image under ``K``;
* **physical consistency**: :meth:`ArmIdentificationModel.consistency` describes ``p`` (links, non-negative
  friction and armature, a free offset) for the log-Cholesky search of the consistent estimators.

The problem is posed on :class:`IdentificationRows`: a movement's filtered, decimated effort and its base regressor
filtered with the same filter (parallel filtering, :func:`spaceid_gym.arm.signal.parallel_decimation`), made by
:meth:`estimators.arm.identification.Preparation.rows`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from estimators.arm.consistency import PhysicalConsistency
from estimators.arm.linear_problem import LinearIdentificationProblem, image_box
from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.real_logs import UR5_TORQUE_CONSTANTS_NM_A
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

IntArray = NDArray[np.intp]

#: search range of a link's mass, as factors of its URDF mass (kg); a URDF mass below MIN_NOMINAL_MASS_KG counts as that
MASS_FACTOR_RANGE = (0.2, 5.0)
MIN_NOMINAL_MASS_KG = 0.05
#: a link's size bound (m): this factor times the larger of its URDF CoM offset and the distance to the next joint
SIZE_FACTOR = 1.5
MIN_SIZE_M = 0.1
#: friction search ranges as fractions of the joint's torque limit: Coulomb, Stribeck excess and offset (N m),
#: viscous (N m per rad/s of the rate limit), armature (kg m^2 per rad/s^2 of the acceleration limit)
FRICTION_FRACTION_OF_LIMIT = 0.2


@dataclass(frozen=True, eq=False)
class IdentificationRows:
    """One movement ready for identification by one model.

    Attributes:
        log: the prepared log at the rows' samples (filtered states, ``ddq``, filtered effort), T samples.
        regressor: (T, n, r) the model's base regressor, parallel-filtered, in the log's effort unit per unit parameter.
    """

    log: ArmLog
    regressor: FloatArray

    @property
    def name(self) -> str:
        """The movement's name."""
        return self.log.name


@dataclass(frozen=True, eq=False)
class ArmIdentificationModel:
    """The linear identification model of a fixed-base arm (module docstring).

    Build it with :meth:`build`. Attributes:
        regressor: the full linear model ``tau = Y p`` (:class:`ArmRegressor`).
        base: its base parameters (:class:`BaseParameterSet`), ``r`` of them.
        torque_constants_Nm_A: (n,) N m/A, used for current logs.
    """

    regressor: ArmRegressor
    base: BaseParameterSet
    torque_constants_Nm_A: FloatArray

    @classmethod
    def build(
        cls,
        robot: ArmRobot,
        friction: FrictionModel | Sequence[str] | None = ("coulomb", "viscous"),
        armature: bool = False,
        torque_constants_Nm_A: Sequence[float] | FloatArray | None = None,
        seed: int = 0,
    ) -> ArmIdentificationModel:
        """The model of ``robot`` with the ``friction`` terms (and rotor ``armature``) per joint.

        Args:
            robot: the arm.
            friction: friction terms (:class:`FrictionModel` or names; ``None``/``()`` = none).
            armature: add a rotor inertia per joint.
            torque_constants_Nm_A: (n,) for current logs; default the UR5's approximate values for a 6-joint arm.
            seed: seed of the random states the base parameters are found from (structure only).
        """
        regressor = ArmRegressor(robot, friction, armature)
        if torque_constants_Nm_A is None:
            if robot.n_joints != len(UR5_TORQUE_CONSTANTS_NM_A):
                raise SpaceIdInputError(
                    f"torque_constants_Nm_A: the robot has {robot.n_joints} joints; give one torque constant per joint"
                )
            torque_constants_Nm_A = UR5_TORQUE_CONSTANTS_NM_A
        k_t = np.asarray(torque_constants_Nm_A, dtype=float)
        if k_t.shape != (robot.n_joints,) or not np.all(np.isfinite(k_t)) or np.any(k_t <= 0):
            raise SpaceIdInputError(f"torque_constants_Nm_A: expected {robot.n_joints} positive values (N m/A), got {k_t!r}")
        with threadpool_limits(limits=1):  # a small QR: BLAS threads only slow it down on a busy machine
            base = BaseParameterSet.from_regressor(regressor, np.random.default_rng(seed))
        return cls(regressor, base, k_t)

    # ------------------------------------------------------------------ structure
    @property
    def robot(self) -> ArmRobot:
        """The arm."""
        return self.regressor.robot

    @property
    def n_joints(self) -> int:
        """n."""
        return self.regressor.n_joints

    @property
    def n_params(self) -> int:
        """r, the number of base parameters."""
        return self.base.rank

    def describe(self) -> str:
        """One line: friction terms, armature, parameter counts."""
        terms = ", ".join(self.regressor.friction.terms) or "no friction"
        return (
            f"{self.robot.name}: rigid bodies + {terms}{' + armature' if self.regressor.armature else ''}; "
            f"{self.regressor.n_parameters} parameters, {self.base.rank} base parameters"
        )

    def torque_per_effort(self, effort_kind: str) -> FloatArray:
        """(n,) N m per unit of effort: ones for torque (``"torque_Nm"``), ``k_t`` for current (``"current_A"``)."""
        if effort_kind == "torque_Nm":
            return np.ones(self.n_joints)
        if effort_kind == "current_A":
            return self.torque_constants_Nm_A
        raise SpaceIdInputError(f"effort kind: expected 'torque_Nm' or 'current_A', got {effort_kind!r}")

    # ------------------------------------------------------------------ regressor and predictions
    def base_regressor(self, q_rad: FloatArray, dq_rad_s: FloatArray, ddq_rad_s2: FloatArray, effort_kind: str) -> FloatArray:
        """``Y_b`` (T, n, r) of states (T, n) each, in the unit of ``effort_kind`` per unit base parameter."""
        full = self.regressor.regressor(q_rad, dq_rad_s, ddq_rad_s2)
        return self.base.base_regressor(full) / self.torque_per_effort(effort_kind)[None, :, None]

    def log_regressor(self, log: ArmLog) -> FloatArray:
        """:meth:`base_regressor` along a log that has accelerations (e.g. a simulator's true states)."""
        if log.n_joints != self.n_joints:
            raise SpaceIdInputError(f"{log.name or 'log'}: has {log.n_joints} joints, the robot {self.n_joints}")
        if log.ddq_rad_s2 is None:
            raise SpaceIdInputError(f"{log.name or 'log'}: has no joint accelerations; prepare it first (Preparation.rows)")
        return self.base_regressor(log.q_rad, log.dq_rad_s, log.ddq_rad_s2, log.effort_kind)

    def predict(self, beta: FloatArray, rows: IdentificationRows) -> FloatArray:
        """Predicted effort (T, n) of base parameters ``beta`` (r,) on a movement's rows (its unit)."""
        beta = np.asarray(beta, dtype=float)
        if beta.shape != (self.n_params,):
            raise SpaceIdInputError(f"beta: expected {self.n_params} base parameters, got shape {beta.shape}")
        if rows.regressor.shape[2] != self.n_params:
            raise SpaceIdInputError(
                f"{rows.name}: rows of another model ({rows.regressor.shape[2]} parameters, this one {self.n_params})"
            )
        return rows.regressor @ beta

    # ------------------------------------------------------------------ the problem
    def problem(
        self, rows: Sequence[IdentificationRows] | Mapping[str, IdentificationRows], row_std: FloatArray | None = None
    ) -> LinearIdentificationProblem:
        """The base-parameter problem on the movements' ``rows`` stacked (module docstring), with :meth:`consistency`.

        Args:
            rows: the movements (a sequence, or a mapping name -> rows) made for this model.
            row_std: (n,) known noise std per joint in the logs' effort unit (all logs the same kind), or ``None``
                (estimated per joint from residuals).
        """
        items = list(rows.values()) if isinstance(rows, Mapping) else list(rows)
        if not items:
            raise SpaceIdInputError("problem: expected at least one movement")
        kinds = {item.log.effort_kind for item in items}
        if len(kinds) > 1 and row_std is not None:
            raise SpaceIdInputError(f"row_std: the logs mix effort kinds {sorted(kinds)}; give no row_std")
        for item in items:
            if item.regressor.shape[1:] != (self.n_joints, self.n_params):
                raise SpaceIdInputError(
                    f"{item.name}: rows of shape {item.regressor.shape[1:]}, this model needs ({self.n_joints}, {self.n_params})"
                )
        Y = np.concatenate([item.regressor.reshape(-1, self.n_params) for item in items])
        tau = np.concatenate([item.log.effort.reshape(-1) for item in items])
        groups = np.tile(np.arange(self.n_joints), len(tau) // self.n_joints)
        std = None
        if row_std is not None:
            std_joint = np.asarray(row_std, dtype=float)
            if std_joint.shape != (self.n_joints,):
                raise SpaceIdInputError(
                    f"row_std: expected one noise std per joint ({self.n_joints}), got shape {std_joint.shape}"
                )
            std = std_joint[groups]
        full_lower, full_upper = self.full_box()
        lower, upper = image_box(self.base.K, full_lower, full_upper)
        return LinearIdentificationProblem(
            Y,
            tau,
            self.base.names,
            lower,
            upper,
            nominal=self.base.to_base(np.clip(self.regressor.nominal_parameters(), full_lower, full_upper)),
            row_std=std,
            row_group=groups,
            consistency=self.consistency(),
            name="base",
        )

    # ------------------------------------------------------------------ prior box and consistency
    def _link_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Per link the mass range (n, 2) kg and size (n,) m of the search (module constants)."""
        model = self.robot.model
        n = self.n_joints
        mass = np.array([max(model.inertias[k + 1].mass, MIN_NOMINAL_MASS_KG) for k in range(n)])
        reach = np.array(
            [
                max(
                    np.linalg.norm(model.inertias[k + 1].lever),
                    np.linalg.norm(model.jointPlacements[k + 2].translation) if k + 2 < model.njoints else 0.0,
                )
                for k in range(n)
            ]
        )
        return np.outer(mass, MASS_FACTOR_RANGE), np.maximum(SIZE_FACTOR * reach, MIN_SIZE_M)

    def _joint_term_bounds(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per-joint coefficient columns after the links: indices (m,), lower (m,), upper (m,) bounds."""
        robot, friction = self.robot, self.regressor.friction
        fraction = FRICTION_FRACTION_OF_LIMIT * robot.torque_limit_Nm
        zero = np.zeros_like(fraction)
        per_term = {
            "coulomb": (zero, fraction),
            "viscous": (zero, fraction / robot.dq_limit_rad_s),
            "stribeck": (zero, fraction),
            "offset": (-fraction, fraction),
            "coulomb_positive": (zero, fraction),
            "coulomb_negative": (zero, fraction),
        }
        lower = [per_term[c][0][j] for j in range(self.n_joints) for c in friction.columns]
        upper = [per_term[c][1][j] for j in range(self.n_joints) for c in friction.columns]
        if self.regressor.armature:
            lower += [0.0] * self.n_joints
            upper += list(fraction / robot.ddq_limit_rad_s2)
        columns = self.regressor.n_inertial + np.arange(len(lower))
        return columns, np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)

    def full_box(self) -> tuple[FloatArray, FloatArray]:
        """The search box (p,) x 2 of the full parameters, a generous prior from the URDF.

        Per link with mass range ``[m_lo, m_hi]`` (``MASS_FACTOR_RANGE`` x the URDF mass) and size ``s``
        (``SIZE_FACTOR`` x the larger of the URDF CoM offset and the distance to the next joint, at least
        ``MIN_SIZE_M``): mass ``[0, m_hi]``, first moments ``+-m_hi s``, diagonal inertia ``[0, 2 m_hi s^2]``,
        products ``+-m_hi s^2``. Per joint, with ``f = FRICTION_FRACTION_OF_LIMIT x`` its torque limit: Coulomb and
        Stribeck excess ``[0, f]``, viscous ``[0, f / rate limit]``, offset ``+-f``, armature ``[0, f / acceleration
        limit]``; each direction's Coulomb level like Coulomb.
        """
        masses, size = self._link_bounds()
        m_hi = masses[:, 1]
        first, second = m_hi * size, m_hi * size**2
        zero = np.zeros_like(m_hi)
        # params10 order: m, mcx, mcy, mcz, ixx, ixy, iyy, ixz, iyz, izz
        link_lower = np.stack([zero, -first, -first, -first, zero, -second, zero, -second, -second, zero], axis=1)
        link_upper = np.stack([m_hi, first, first, first, 2 * second, second, 2 * second, second, second, 2 * second], axis=1)
        columns, lower_j, upper_j = self._joint_term_bounds()
        lower = np.empty(self.regressor.n_parameters)
        upper = np.empty(self.regressor.n_parameters)
        lower[: self.regressor.n_inertial], upper[: self.regressor.n_inertial] = link_lower.ravel(), link_upper.ravel()
        lower[columns], upper[columns] = lower_j, upper_j
        return lower, upper

    def consistency(self) -> PhysicalConsistency:
        """The full parameters' layout for the physically consistent search: links (mass range and size as in
        :meth:`full_box`), non-negative friction and armature, a free offset; ``base_map`` = ``K``; the URDF's values
        (zero friction) as ``nominal_full``."""
        masses, size = self._link_bounds()
        columns, lower, upper = self._joint_term_bounds()
        free = lower < 0.0
        return PhysicalConsistency(
            link_columns=10 * np.arange(self.n_joints)[:, None] + np.arange(10),
            friction_columns=columns[~free],
            mass_range_kg=masses,
            size_m=size,
            friction_upper=upper[~free],
            base_map=self.base.K,
            free_columns=columns[free],
            free_bound=upper[free],
            nominal_full=self.regressor.nominal_parameters(),
        )
