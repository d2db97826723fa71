"""The ``dahl`` candidate of ``ur5_extra_terms.py``: presliding (hysteretic) friction in place of the Coulomb columns.

The Dahl model (:mod:`spaceid_gym.arm.presliding`) replaces each joint's Coulomb column ``s(dq_j)`` (asymmetric
model: ``max(s, 0)``, ``min(s, 0)``) by the state ``h_j`` (``max(h_j, 0)``, ``min(h_j, 0)``) driven by joint
``j``'s position with a presliding length ``delta_j``. The columns are computed like the model's own: on the filtered
states at the full rate, then parallel-filtered with the effort's filter and decimated
(:func:`~spaceid_gym.arm.signal.parallel_decimation`), so ``delta -> 0`` gives the exact sign of the last motion
where the model has the smooth sign of the rate (the two differ in the sign's width and in what happens at rest:
``h`` keeps the last motion's sign, ``s`` goes to 0).

Each fold chooses ``delta_j`` per joint on :data:`DAHL_GRID_RAD` by the **training cost** only (the held-out movement
never enters): coordinate descent over the joints from the smallest length, each step taking the length of one joint
that minimises the training cost with the others held, until a sweep changes nothing. ``dahl_per_joint``: the same with one more
option per joint, the model's own Coulomb column (the descent then starts from the model): Dahl only on the joints
whose training cost asks for it. The cost: ours, weighted least
squares with the weights fixed at the baseline model's Gautier weights (each joint's OLS residual std on the training
movements); UR's refitted model, each joint's own least-squares cost (its joints are fitted apart). The final fit at
the chosen lengths is the screen's usual one (two-step WLS; per-joint least squares).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from estimators.arm.identification import Preparation
from estimators.arm.model import ArmIdentificationModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.presliding import presliding_state
from spaceid_gym.arm.signal import parallel_decimation
from spaceid_gym.arrays import FloatArray

#: the presliding lengths (rad) each fold chooses from per joint (a finer grid below 1e-4 rad, where most joints pick)
DAHL_GRID_RAD = np.geomspace(1e-6, 5e-2, 15)
DAHL_MAX_SWEEPS = 10
#: the candidates: name -> whether a joint may keep the model's Coulomb column (grid index -1)
DAHL_CANDIDATES = {"dahl": False, "dahl_per_joint": True}


class DesignScreen(Protocol):
    """What the ``dahl`` candidate needs of a screen of ``ur5_extra_terms.py`` (ours, or UR's refitted model)."""

    model: ArmIdentificationModel
    presliding: dict[str, FloatArray]
    #: whether each joint is fitted on its own (UR's refitted model) rather than all in one weighted system (ours)
    joints_apart: bool

    def effort(self, name: str) -> FloatArray:
        """(T, n) the prepared effort of movement ``name``."""
        ...

    def design(self, name: str) -> FloatArray:
        """(T, n, k) the screen's columns of movement ``name``."""
        ...

    def coulomb_slots(self) -> FloatArray:
        """(n, c) per joint the indices of its Coulomb columns in :meth:`design`."""
        ...

    def column_scale(self, name: str) -> FloatArray:
        """(n,) the unit of a friction column of movement ``name`` (effort per N m)."""
        ...

    def solve(self, design: FloatArray, effort: FloatArray) -> FloatArray:
        """The parameters of ``design`` on ``effort`` (the screen's own fit)."""
        ...

    def predict(self, design: FloatArray, theta: FloatArray) -> FloatArray:
        """(T, n) the prediction of ``theta``."""
        ...

    def levels(self, theta: FloatArray) -> FloatArray:
        """(n, c) the fitted levels of the Coulomb columns."""
        ...


def presliding_columns(model: ArmIdentificationModel, log: ArmLog, preparation: Preparation) -> FloatArray:
    """(T, n, G, c) the raw ``log``'s Dahl columns (per N m of level) at every length of :data:`DAHL_GRID_RAD`,
    parallel-filtered; ``c`` = the model's Coulomb columns per joint (2: ``max(h, 0)``, ``min(h, 0)``)."""
    asymmetric = "coulomb_asymmetric" in model.regressor.friction.terms

    def columns(q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
        h = presliding_state(q, np.tile(DAHL_GRID_RAD, (q.shape[1], 1)))
        parts = (np.maximum(h, 0.0), np.minimum(h, 0.0)) if asymmetric else (h,)
        return np.stack(parts, axis=-1).reshape(q.shape[0], q.shape[1], -1)

    _, filtered = parallel_decimation(log, columns, preparation.cutoff_hz, preparation.decimate_factor, preparation.order)
    return filtered.reshape(filtered.shape[0], model.n_joints, len(DAHL_GRID_RAD), -1)


def stacked_columns(screen: DesignScreen, names: Sequence[str]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The movements' designs (T, n, k), Dahl columns in the design's unit (T, n, G, c) and efforts (T, n), stacked."""
    design = np.concatenate([screen.design(name) for name in names])
    columns = np.concatenate([screen.presliding[name] * screen.column_scale(name)[:, None, None] for name in names])
    if columns.shape[0] != design.shape[0]:
        raise ValueError(f"{list(names)}: the Dahl columns have {columns.shape[0]} samples, the designs {design.shape[0]}")
    return design, columns, np.concatenate([screen.effort(name) for name in names])


def dahl_design(screen: DesignScreen, design: FloatArray, columns: FloatArray, choice: FloatArray) -> FloatArray:
    """``design`` (T, n, k) with each joint's Coulomb columns replaced by its Dahl ``columns`` (T, n, G, c) at the grid
    index ``choice[j]`` (-1: kept)."""
    design = design.copy()
    for j, slots in enumerate(screen.coulomb_slots()):
        if choice[j] >= 0:
            design[:, j, slots] = columns[:, j, choice[j], :]
    return design


def replaced_costs(system: FloatArray, target: FloatArray, slots: FloatArray, replacements: FloatArray) -> FloatArray:
    """(G,) the least-squares cost of ``system`` (N, k) on ``target`` (N,) with its columns ``slots`` (c,) replaced by
    each of ``replacements`` (G, N, c): the other columns projected out once (a QR), then each replacement alone."""
    basis, _ = np.linalg.qr(np.delete(system, slots, axis=1))
    rest = target - basis @ (basis.T @ target)
    costs = []
    for columns in replacements:
        columns = columns - basis @ (basis.T @ columns)
        costs.append(float(np.sum((rest - columns @ np.linalg.lstsq(columns, rest, rcond=None)[0]) ** 2)))
    return np.array(costs)


def choose_lengths(screen: DesignScreen, train: Sequence[str], candidate: str) -> FloatArray:
    """(n,) per joint the grid index of the presliding length (-1: the model's Coulomb column), by the training cost
    only (module docstring)."""
    design, columns, effort = stacked_columns(screen, train)
    flat = design.reshape(-1, design.shape[2])
    residual = flat @ np.linalg.lstsq(flat, effort.reshape(-1), rcond=None)[0] - effort.reshape(-1)
    weight = 1.0 / np.sqrt(np.mean(residual.reshape(effort.shape) ** 2, axis=0))
    keep = DAHL_CANDIDATES[candidate]
    choice = np.full(screen.model.n_joints, -1 if keep else 0)
    options = np.arange(-1 if keep else 0, len(DAHL_GRID_RAD))
    for _ in range(DAHL_MAX_SWEEPS):
        before = choice.copy()
        for j, slots in enumerate(screen.coulomb_slots()):
            trial = dahl_design(screen, design, columns, choice)
            own = np.concatenate([design[:, j, slots][None], np.moveaxis(columns[:, j], 1, 0)])  # (1 + G, T, c)
            if screen.joints_apart:  # only joint j's own least squares changes
                costs = replaced_costs(trial[:, j, :], effort[:, j], slots, own[options + 1])
            else:  # the weighted system of every joint; joint j's columns act on its rows only
                placed = np.zeros((len(options), *effort.shape, len(slots)))
                placed[:, :, j, :] = own[options + 1] * weight[j]
                system = (trial * weight[:, None]).reshape(-1, design.shape[2])
                costs = replaced_costs(system, (effort * weight).reshape(-1), slots, placed.reshape(len(options), -1, len(slots)))
            choice[j] = options[int(np.argmin(costs))]
        if np.array_equal(choice, before):
            return choice
    raise RuntimeError(f"dahl: the presliding lengths did not settle in {DAHL_MAX_SWEEPS} sweeps")


def dahl_fit(screen: DesignScreen, train: Sequence[str], held: str, candidate: str) -> tuple[FloatArray, FloatArray, str]:
    """One fold: lengths chosen on ``train`` and fitted there; the parameters, the prediction (T, n) of ``held`` and
    the lengths per joint (rad, or ``coulomb``) as text."""
    choice = choose_lengths(screen, train, candidate)
    design, columns, effort = stacked_columns(screen, train)
    theta = screen.solve(dahl_design(screen, design, columns, choice), effort)
    held_design, held_columns, _ = stacked_columns(screen, [held])
    return theta, screen.predict(dahl_design(screen, held_design, held_columns, choice), theta), lengths_text(choice)


def lengths_text(choice: FloatArray) -> str:
    """The grid indices ``choice`` (n,) as the presliding lengths per joint, rad (``coulomb`` for -1)."""
    return " ".join(f"{DAHL_GRID_RAD[g]:.1e}" if g >= 0 else "coulomb" for g in choice)


def report_levels(
    screen: DesignScreen, chosen: Sequence[str], thetas: Sequence[FloatArray], baseline: Sequence[FloatArray]
) -> None:
    """The lengths chosen per fold, and per joint the range over the folds of the fitted Dahl levels against the
    baseline's Coulomb levels (N m for ours, A for UR's refitted model; per direction for the asymmetric model)."""
    print("    presliding length per joint (rad), by fold:\n" + "\n".join(f"      {line}" for line in chosen))
    for label, runs in (("Dahl", thetas), ("baseline Coulomb", baseline)):
        levels = np.array([screen.levels(theta) for theta in runs])  # (F, n, c)
        ranges = " ".join(
            "/".join(f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(a, b, strict=True))
            for a, b in zip(levels.min(axis=0), levels.max(axis=0), strict=True)
        )
        print(f"    {label} levels per joint, min..max over the folds: {ranges}")
