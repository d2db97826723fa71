"""UR's own dynamic model, refitted: the comparison baseline of the real UR5's held-out current error.

The UR controller logs ``m_target`` (N m), the joint torque its own dynamic model asked for along the movement. Its
model is not published, but its output is: a prediction of the measured current from it needs only a gain and
friction per joint. Per joint ``j`` (current ``i_j`` in A, rate ``dq_j`` in rad/s)::

    i_j  ~  a_j m_target_j  +  friction_j(dq_j)          a_j in A / (N m)

with the friction terms of :class:`~spaceid_gym.arm.friction.FrictionModel` (default Coulomb, viscous and a constant
offset, :data:`CONTROLLER_FRICTION`; ``arm cross-validate --ur-model-friction`` chooses others), every coefficient fitted by least squares on the training movements, each joint
on its own (so no weighting between joints enters). ``1 / a_j`` is the torque constant UR's model implies (N m/A).

Signals: exactly the chain of the identification (:class:`~estimators.arm.identification.Preparation`): the current
log and a log of ``m_target`` on the current log's time stamps go through
:func:`~spaceid_gym.arm.signal.parallel_decimation`, so ``m_target`` is filtered like the current and the friction
features are parallel-filtered like the rigid-body regressor, and both come out on the same samples. ``m_target`` is
read at the current log's time stamps by linear interpolation over its own (identical where both files have the row;
in the shared movements only the last sample of Movement_No4_Acc is missing from ``m_target`` and is held, and the
chain trims it with the edges anyway). The figures are :func:`~estimators.arm.identification.error_of_prediction`'s, on
the same held-out movements: :func:`controller_model_leave_one_out` gives rows of the same table as
:func:`~estimators.arm.identification.leave_one_out`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimators.arm.identification import (
    CrossValidationRow,
    PredictionError,
    Preparation,
    error_of_prediction,
    load_movements,
)
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.signal import parallel_decimation
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: the friction terms of the refitted controller model
CONTROLLER_FRICTION: tuple[str, ...] = ("coulomb", "viscous", "offset")
#: the labels of its rows in the cross-validation table
CONTROLLER_MODEL_LABEL = "UR's model refitted"


@dataclass(frozen=True, eq=False)
class ControllerModelRows:
    """One movement prepared for the refitted controller model.

    Attributes:
        log: the prepared current log (:meth:`Preparation.rows`'s samples), current in A.
        features: (T, n, 1 + k) per joint its columns: the filtered ``m_target`` (N m), then the parallel-filtered
            friction features (``FrictionModel.features``).
    """

    log: ArmLog
    features: FloatArray


def controller_rows(
    preparation: Preparation, current: ArmLog, torque: ArmLog, friction: FrictionModel | Sequence[str] = CONTROLLER_FRICTION
) -> ControllerModelRows:
    """The rows of one movement: its raw current log and raw ``m_target`` log (same movement, same joints)."""
    if current.effort_kind != "current_A" or torque.effort_kind != "torque_Nm":
        raise SpaceIdInputError(
            f"{current.name}: the refitted controller model needs a current log (A) and an m_target torque log (N m), "
            f"got {current.effort_kind} and {torque.effort_kind}"
        )
    if torque.n_joints != current.n_joints:
        raise SpaceIdInputError(f"{current.name}: m_target has {torque.n_joints} joints, the current {current.n_joints}")
    if torque.t_s[0] > current.t_s[-1] or torque.t_s[-1] < current.t_s[0]:
        raise SpaceIdInputError(f"{current.name}: the m_target log does not overlap the current log in time")
    model = FrictionModel.coerce(friction)
    m_target = np.stack([np.interp(current.t_s, torque.t_s, torque.effort[:, j]) for j in range(current.n_joints)], axis=1)
    torque_log = dataclasses.replace(current, effort=m_target, effort_kind="torque_Nm")

    def features(q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
        return model.features(dq)

    prepared, friction_columns = parallel_decimation(
        current, features, preparation.cutoff_hz, preparation.decimate_factor, preparation.order
    )
    prepared_torque, _ = parallel_decimation(
        torque_log, features, preparation.cutoff_hz, preparation.decimate_factor, preparation.order
    )
    return ControllerModelRows(prepared, np.concatenate((prepared_torque.effort[..., None], friction_columns), axis=-1))


def fit_controller_model(train: Sequence[ControllerModelRows]) -> FloatArray:
    """Per joint the least-squares coefficients (n, 1 + k) on the training movements: ``a_j`` (A/(N m)), then friction
    in A (Coulomb, offset) and A s/rad (viscous)."""
    if not train:
        raise SpaceIdInputError("refitted controller model: no training movement")
    features = np.concatenate([item.features for item in train])
    current = np.concatenate([item.log.effort for item in train])
    return np.stack([np.linalg.lstsq(features[:, j, :], current[:, j], rcond=None)[0] for j in range(current.shape[1])], axis=0)


def predict_controller_model(coefficients: FloatArray, rows: ControllerModelRows) -> FloatArray:
    """The predicted current (T, n), A."""
    return np.einsum("tjk,jk->tj", rows.features, coefficients)


def controller_estimator_label(friction: FrictionModel | Sequence[str] = CONTROLLER_FRICTION) -> str:
    """The estimator column of the refitted controller model's rows, naming its friction terms."""
    return f"per-joint least squares (gain + {', '.join(FrictionModel.coerce(friction).terms) or 'no friction'})"


def load_controller_rows(
    data: str | Path,
    current_logs: Mapping[str, ArmLog],
    preparation: Preparation,
    friction: FrictionModel | Sequence[str] = CONTROLLER_FRICTION,
) -> dict[str, ControllerModelRows]:
    """Every movement's rows from the real UR5 movement folders in ``data`` (their ``m_target.csv``) and the already
    loaded current logs, with the ``friction`` terms."""
    try:
        torques = load_movements(data, list(current_logs), effort="m_target")
    except SpaceIdInputError as exc:
        raise SpaceIdInputError(f"--compare-ur-model: needs real UR5 movements with m_target.csv ({exc})") from None
    if any(log.effort_kind != "torque_Nm" for log in torques.values()):
        raise SpaceIdInputError(
            f"--compare-ur-model: {data} holds simulated datasets; UR's model exists only in real UR5 logs (m_target.csv)"
        )
    return {name: controller_rows(preparation, current_logs[name], torques[name], friction) for name in current_logs}


def controller_model_leave_one_out(
    rows: Mapping[str, ControllerModelRows],
    noise_floors: Mapping[str, FloatArray | None] | None = None,
    label: str = controller_estimator_label(),
) -> tuple[list[CrossValidationRow], dict[str, FloatArray]]:
    """Leave one movement out with the refitted controller model: per held-out movement its
    :class:`~estimators.arm.identification.CrossValidationRow` (the table's figures) and the coefficients fitted on the
    other movements (n, 1 + k)."""
    if len(rows) < 2:
        raise SpaceIdInputError(f"leave-one-out: needs at least two movements, got {list(rows)}")
    floors = noise_floors or {}
    out, coefficients = [], {}
    for held, item in rows.items():
        start = time.perf_counter()
        fitted = fit_controller_model([r for name, r in rows.items() if name != held])
        wall = time.perf_counter() - start
        error: PredictionError = error_of_prediction(item.log, predict_controller_model(fitted, item), floors.get(held))
        out.append(CrossValidationRow(CONTROLLER_MODEL_LABEL, label, error, None, wall, 0.0))
        coefficients[held] = fitted
    return out, coefficients
