"""Presliding (Dahl) friction as an option of the arm model: per joint, a presliding length or the rate's sign,
chosen on the training movements only.

The Dahl model (:mod:`spaceid_gym.arm.presliding`) drives each joint's Coulomb level by a state ``h_j`` in
``[-1, 1]`` that follows the joint's **position**: after a reversal the friction builds up over the presliding length
``delta_j`` (rad) instead of switching with the smooth sign of the rate, ``s(dq) = tanh(dq / v_eps)``. For a fixed
``delta_j`` the torque ``F_c,j h_j`` is linear in the level, so the option keeps the model and its unknowns: each
chosen joint's Coulomb column(s) (``s``; asymmetric: ``max(s, 0)``, ``min(s, 0)``) are **replaced** by the Dahl
column(s) (``h``; ``max(h, 0)``, ``min(h, 0)``). The levels keep their names, units and constraints (``>= 0`` for
``sdp`` and the consistent colonies): they are still the Coulomb levels, only the shape of their onset changes.

The columns are computed like the model's own (:func:`presliding_columns`): ``h`` on the filtered states at the full
rate (``h = 0`` at the first sample), then parallel-filtered with the effort's filter and decimated
(:func:`~spaceid_gym.arm.signal.parallel_decimation`), at every length of :data:`PRESLIDING_GRID_RAD` at once.

The choice (:func:`choose_presliding`), from the training movements only (never a held-out movement): per joint one
of the grid's lengths or, if ``keep_coulomb``, the model's own Coulomb column, by the **training cost**: weighted
least squares with the weights fixed at the Coulomb model's Gautier weights (each joint's OLS residual std on the
training rows). Coordinate descent over the joints from the Coulomb model (from the smallest length without
``keep_coulomb``): each step takes the option of one joint that minimises the cost with the others held, until a
sweep changes nothing (at most :data:`MAX_SWEEPS`). The cost of each option of a joint is one least-squares
projection (:func:`replaced_costs`), so a choice costs about ``sweeps x n x G`` small solves. The final fit at the
chosen lengths is whatever estimator the caller runs on :func:`with_presliding` rows.

Measured on the real UR5 (``docs/results.md``, "presliding"): on the 7 undisturbed movements and on the two pushed
movements no choice had seen, the option lowers the held-out error of asymmetric Coulomb + viscous + armature.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.presliding import presliding_state
from spaceid_gym.arm.signal import parallel_decimation
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

IntArray = NDArray[np.intp]

#: the presliding lengths (rad) chosen from per joint: 15 log-spaced, 1e-6 .. 5e-2 rad
PRESLIDING_GRID_RAD = np.geomspace(1e-6, 5e-2, 15)
MAX_SWEEPS = 10
#: the Coulomb terms whose columns the option replaces
COULOMB_TERMS = ("coulomb", "coulomb_asymmetric")


class SignalChain(Protocol):
    """The settings of the identification's signal chain (:class:`~estimators.arm.identification.Preparation`)."""

    cutoff_hz: float
    decimate_factor: int
    order: int


@dataclass(frozen=True)
class PreslidingChoice:
    """Per joint the grid index of the chosen presliding length, -1 where the joint keeps the rate's smooth sign."""

    grid_index: IntArray

    @property
    def lengths_rad(self) -> list[float | None]:
        """Per joint the presliding length (rad), ``None`` for the rate's smooth sign."""
        return [float(PRESLIDING_GRID_RAD[g]) if g >= 0 else None for g in self.grid_index]

    def text(self) -> str:
        """The lengths per joint as text (rad; ``coulomb`` where the joint keeps the smooth sign)."""
        return " ".join("coulomb" if length is None else f"{length:.1e}" for length in self.lengths_rad)


def check_presliding_model(model: ArmIdentificationModel) -> None:
    """Raise unless the model has a Coulomb term for the Dahl columns to replace."""
    if not set(COULOMB_TERMS) & set(model.regressor.friction.terms):
        raise SpaceIdInputError(
            f"--presliding: the model's friction {list(model.regressor.friction.terms)} has no Coulomb term to replace; "
            f"add one of {list(COULOMB_TERMS)} to --friction"
        )


def coulomb_slots(model: ArmIdentificationModel) -> IntArray:
    """(n, c) per joint the base-parameter indices of its Coulomb columns (friction columns are never regrouped)."""
    check_presliding_model(model)
    names = list(model.base.names)
    columns = [c for c in model.regressor.friction.columns if c.startswith("coulomb")]
    try:
        return np.array([[names.index(f"joint{j + 1}_{c}_Nm") for c in columns] for j in range(model.n_joints)])
    except ValueError as exc:
        raise SpaceIdInputError(f"--presliding: a Coulomb level is not a base parameter of the model ({exc})") from None


def presliding_columns(model: ArmIdentificationModel, log: ArmLog, chain: SignalChain, in_effort_unit: bool = True) -> FloatArray:
    """(T, n, G, c) the raw ``log``'s Dahl columns at every length of :data:`PRESLIDING_GRID_RAD`, parallel-filtered
    and decimated like the model's rows, in the log's effort unit per N m of level (``in_effort_unit=False``: per unit
    of level, dimensionless); ``c`` the Coulomb columns per joint (1: ``h``; 2, asymmetric: ``max(h, 0)``,
    ``min(h, 0)``)."""
    check_presliding_model(model)
    asymmetric = "coulomb_asymmetric" in model.regressor.friction.terms
    per_effort = model.torque_per_effort(log.effort_kind) if in_effort_unit else np.ones(model.n_joints)

    def columns(q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
        h = presliding_state(q, np.tile(PRESLIDING_GRID_RAD, (q.shape[1], 1)))
        parts = (np.maximum(h, 0.0), np.minimum(h, 0.0)) if asymmetric else (h,)
        stacked = np.stack(parts, axis=-1) / per_effort[None, :, None, None]
        return stacked.reshape(q.shape[0], q.shape[1], -1)

    _, filtered = parallel_decimation(log, columns, chain.cutoff_hz, chain.decimate_factor, chain.order)
    return filtered.reshape(filtered.shape[0], model.n_joints, len(PRESLIDING_GRID_RAD), -1)


def presliding_design(design: FloatArray, columns: FloatArray, slots: IntArray, grid_index: IntArray) -> FloatArray:
    """``design`` (T, n, k) with each joint's Coulomb columns ``slots[j]`` replaced by its Dahl ``columns``
    (T, n, G, c) at ``grid_index[j]`` (-1: kept)."""
    design = design.copy()
    for j, slot in enumerate(slots):
        if grid_index[j] >= 0:
            design[:, j, slot] = columns[:, j, grid_index[j], :]
    return design


def replaced_costs(system: FloatArray, target: FloatArray, slots: IntArray, replacements: FloatArray) -> FloatArray:
    """(G,) the least-squares cost of ``system`` (N, k) on ``target`` (N,) with its columns ``slots`` (c,) replaced by
    each of ``replacements`` (G, N, c): the other columns projected out once (a QR), then each replacement alone."""
    basis, _ = scipy.linalg.qr(np.delete(system, slots, axis=1), mode="economic")
    rest = target - basis @ (basis.T @ target)
    costs = []
    for columns in replacements:
        columns = columns - basis @ (basis.T @ columns)
        costs.append(float(np.sum((rest - columns @ np.linalg.lstsq(columns, rest, rcond=None)[0]) ** 2)))
    return np.array(costs)


def choose_presliding(
    design: FloatArray,
    columns: FloatArray,
    effort: FloatArray,
    slots: IntArray,
    keep_coulomb: bool = True,
    joints_apart: bool = False,
) -> IntArray:
    """(n,) per joint the grid index of the presliding length (-1: the Coulomb column) by the training cost (module
    docstring), from the stacked training ``design`` (T, n, k), Dahl ``columns`` (T, n, G, c) and ``effort`` (T, n).

    ``joints_apart``: each joint is its own least-squares problem on its own columns (a model fitted joint by joint,
    e.g. UR's refitted one), rather than one weighted system of every joint. Runs on one BLAS thread: its tall, thin
    QRs are several times slower threaded on a busy machine.
    """
    with threadpool_limits(limits=1):
        return _descent(design, columns, effort, slots, keep_coulomb, joints_apart)


def _descent(
    design: FloatArray, columns: FloatArray, effort: FloatArray, slots: IntArray, keep_coulomb: bool, joints_apart: bool
) -> IntArray:
    """The coordinate descent of :func:`choose_presliding`."""
    if columns.shape[0] != design.shape[0] or effort.shape != design.shape[:2]:
        raise SpaceIdInputError(
            f"presliding: {design.shape[0]} design rows, {columns.shape[0]} Dahl rows and effort {effort.shape} differ"
        )
    flat = design.reshape(-1, design.shape[2])
    residual = flat @ np.linalg.lstsq(flat, effort.reshape(-1), rcond=None)[0] - effort.reshape(-1)
    weight = 1.0 / np.sqrt(np.mean(residual.reshape(effort.shape) ** 2, axis=0))
    n_joints, n_grid = columns.shape[1], columns.shape[2]
    choice = np.full(n_joints, -1 if keep_coulomb else 0)
    options = np.arange(-1 if keep_coulomb else 0, n_grid)
    for _ in range(MAX_SWEEPS):
        before = choice.copy()
        for j, slot in enumerate(slots):
            trial = presliding_design(design, columns, slots, choice)
            own = np.concatenate([design[:, j, slot][None], np.moveaxis(columns[:, j], 1, 0)])  # (1 + G, T, c)
            if joints_apart:  # only joint j's own least squares changes
                costs = replaced_costs(trial[:, j, :], effort[:, j], slot, own[options + 1])
            else:  # the weighted system of every joint; joint j's columns act on its rows only
                placed = np.zeros((len(options), *effort.shape, len(slot)))
                placed[:, :, j, :] = own[options + 1] * weight[j]
                system = (trial * weight[:, None]).reshape(-1, design.shape[2])
                target = (effort * weight).reshape(-1)
                costs = replaced_costs(system, target, slot, placed.reshape(len(options), -1, len(slot)))
            choice[j] = options[int(np.argmin(costs))]
        if np.array_equal(choice, before):
            return choice
    raise RuntimeError(f"presliding: the lengths did not settle in {MAX_SWEEPS} sweeps")


def presliding_for_movements(
    model: ArmIdentificationModel, logs: Mapping[str, ArmLog], chain: SignalChain
) -> dict[str, FloatArray]:
    """:func:`presliding_columns` of every raw log, by name."""
    return {name: presliding_columns(model, log, chain) for name, log in logs.items()}


def choose_for_rows(
    model: ArmIdentificationModel,
    train: Mapping[str, IdentificationRows] | Sequence[IdentificationRows],
    columns: Mapping[str, FloatArray],
    keep_coulomb: bool = True,
) -> PreslidingChoice:
    """:func:`choose_presliding` on the training movements' rows and their Dahl ``columns`` (by movement name)."""
    items = list(train.values()) if isinstance(train, Mapping) else list(train)
    missing = [item.name for item in items if item.name not in columns]
    if missing:
        raise SpaceIdInputError(f"presliding: no Dahl columns for the movement(s) {missing}")
    design = np.concatenate([item.regressor for item in items])
    dahl = np.concatenate([columns[item.name] for item in items])
    effort = np.concatenate([item.log.effort for item in items])
    return PreslidingChoice(choose_presliding(design, dahl, effort, coulomb_slots(model), keep_coulomb))


def with_presliding(
    model: ArmIdentificationModel, rows: IdentificationRows, columns: FloatArray, choice: PreslidingChoice
) -> IdentificationRows:
    """The movement's ``rows`` with the chosen joints' Coulomb columns replaced by its Dahl ``columns`` (T, n, G, c)."""
    if columns.shape[0] != rows.regressor.shape[0]:
        raise SpaceIdInputError(f"{rows.name}: {columns.shape[0]} Dahl rows for {rows.regressor.shape[0]} samples")
    design = presliding_design(rows.regressor, columns, coulomb_slots(model), choice.grid_index)
    return replace(rows, regressor=design)
