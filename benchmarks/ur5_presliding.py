"""The ``dahl`` candidate of ``ur5_extra_terms.py``: presliding (hysteretic) friction in place of the Coulomb columns.

The columns, the grid and the choice are the package's (:mod:`estimators.arm.presliding_choice`, the model option
``--presliding``, which is ``dahl_per_joint`` with ours); this module adapts them to the screens of the benchmark
(ours and UR's refitted model).

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
from estimators.arm.presliding_choice import (
    PRESLIDING_GRID_RAD,
    PreslidingChoice,
    choose_presliding,
    presliding_design,
)
from estimators.arm.presliding_choice import (
    presliding_columns as package_columns,
)
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arrays import FloatArray

#: the presliding lengths (rad) each fold chooses from per joint (the package's grid)
DAHL_GRID_RAD = PRESLIDING_GRID_RAD
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
    """(T, n, G, c) the raw ``log``'s Dahl columns per unit of level at every length of :data:`DAHL_GRID_RAD`
    (the package's, before the effort unit: :meth:`DesignScreen.column_scale` gives it per screen)."""
    return package_columns(model, log, preparation, in_effort_unit=False)


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
    return presliding_design(design, columns, screen.coulomb_slots(), choice)


def choose_lengths(screen: DesignScreen, train: Sequence[str], candidate: str) -> FloatArray:
    """(n,) per joint the grid index of the presliding length (-1: the model's Coulomb column), by the training cost
    only (:func:`estimators.arm.presliding_choice.choose_presliding`)."""
    design, columns, effort = stacked_columns(screen, train)
    keep = DAHL_CANDIDATES[candidate]
    return choose_presliding(design, columns, effort, screen.coulomb_slots(), keep, screen.joints_apart)


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
    return PreslidingChoice(np.asarray(choice)).text()


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
