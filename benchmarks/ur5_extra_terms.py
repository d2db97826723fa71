"""Do the real UR5 logs ask for a position-dependent friction term, a drift in time (temperature), a friction
growing with the load or one rising with the speed at low speed? Held-out error of weighted least squares with and
without each candidate term, leave one of the 7 undisturbed movements out.

The model is the identification model (``--friction``, default Coulomb + viscous, with a rotor inertia per joint);
each candidate adds per joint ``j`` columns that act on joint ``j``'s rows only, built from the prepared (filtered)
states of the log (a screening: the model's own columns are filtered in parallel with the effort instead):

* ``position_friction``: ``s(dq_j) cos q_j``, ``s(dq_j) sin q_j`` (a Coulomb level varying once per joint turn);
* ``position_friction_2``: the same and ``s(dq_j) cos 2 q_j``, ``s(dq_j) sin 2 q_j``;
* ``position_offset``: ``cos q_j``, ``sin q_j`` (a position-dependent torque, e.g. cogging or a cable);
* ``time_friction``: ``s(dq_j) t``, ``dq_j t`` (friction levels drifting linearly with the time since the movement
  started, as a warming joint's would); ``time_coulomb``: ``s(dq_j) t`` only; ``time_offset``: ``t``.

Load-dependent friction (geared joints: the Coulomb level grows with the torque the gear transmits, e.g. Hamon,
Gautier and Garrec 2010-2011; Bittencourt et al. 2010), with ``tau_load,j`` the joint's link-side rigid-body torque
(inertial + gravity: the base parameters regrouping link parameters, joint 1's rotor inertia with them):

* ``load_friction``: ``s(dq_j) |tau_load,j|`` (``tau_f,j = (Fc_j + mu_j |tau_load,j|) s(dq_j) + ...``);
* ``load_friction_direction``: ``max(s, 0) |tau_load,j|``, ``min(s, 0) |tau_load,j|`` (one ``mu`` per direction);
* ``load_friction_quadrant``: ``s |tau_load,j|`` where the load and the rate share their sign (motoring) and where
  they do not (braking), one ``mu`` each. As ``s |tau_load|`` is ``|s| tau_load`` in the first and
  ``-|s| tau_load`` in the second, the pair spans ``s |tau_load|`` and ``|s| tau_load``: a load friction and a
  per-joint gain on the rigid-body torque while the joint moves;
* ``load_gain``: ``|s(dq_j)| tau_load,j``, that gain alone: the control that tells the quadrant candidate's gain
  from its friction (an error of the torque constants' ratios would show as such a gain);
* ``load_friction_gain``: ``load_friction`` and ``load_gain`` together, the quadrant pair's span in these terms.

``tau_load`` depends on the fitted parameters (the model is bilinear), so these are fitted by a fixed-point
iteration on the training movements only: fit without the term, compute each training movement's ``tau_load`` from
the fitted rigid-body parameters, add the columns, refit, recompute, until ``tau_load`` changes by less than
``LOAD_TOLERANCE`` (relative, over the training rows); the held-out movement's columns come from the final
parameters applied to its own prepared states. The iterations and the fitted ``mu`` are printed.

Friction rising with the speed at low speed (the Stribeck screening's free excess came out negative: the joints rub
less than their Coulomb level below 0.1-0.3 rad/s), each in addition to the model's Coulomb + viscous terms:

* ``power_friction_A``: ``s(dq_j) |dq_j|^A`` with the exponent ``A`` fixed (0.25, 0.5, 0.75);
* ``power_friction_inner_cv``: the same with ``A`` chosen per outer fold among those by an **inner** leave-one-out
  on that fold's training movements only (never on the held-out movement);
* ``wide_onset_V``: ``tanh(dq_j / V)`` with ``V`` 0.1, 0.2, 0.3 or 0.5 rad/s, a wide Coulomb onset next to the narrow
  one; ``wide_onset_inner_cv``: ``V`` chosen among those by the inner leave-one-out.

Presliding (hysteretic) friction, the Dahl model, **in place of** the model's Coulomb columns: ``dahl``, each
joint's presliding length chosen per fold by the training cost; ``dahl_per_joint``, the same where the training cost
prefers it to the model's Coulomb column (``ur5_presliding.py``, whose docstring says how).

``s`` is the model's smooth sign. Weights: Gautier's two-step per-joint weights (the std of each joint's OLS
residual). Printed per candidate: the mean held-out error over the folds (``100 ||e|| / ||tau||`` over all joints, as
``arm cross-validate``), each fold's and each joint's mean.

Printed too: per candidate the change against ``none`` per fold, the folds better and better by more than
``SCATTER_POINTS`` (the folds' scatter of the position term's screening, ``docs/results.md``), and for the speed
candidates the fitted coefficients per joint (min..max over the folds). ``--ur-model`` scores the same columns
(not the load candidates) added per joint to UR's refitted model (``i_j ~ a_j m_target_j`` + the model's friction
terms + an offset, per-joint least squares, ``estimators.arm.controller_model``), on the same samples.

Run: ``.venv/bin/python benchmarks/ur5_extra_terms.py ur5-real/`` (add ``--friction coulomb_asymmetric,viscous`` for
the recommended real model); the figures in ``docs/results.md``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from ur5_colony_vs_sdp import UNDISTURBED
from ur5_presliding import DAHL_CANDIDATES, dahl_fit, presliding_columns, report_levels

from estimators.arm.controller_model import ControllerModelRows, load_controller_rows
from estimators.arm.identification import Preparation, load_movements
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm_cli import parse_friction
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

CANDIDATES = (
    "none",
    "position_friction",
    "position_friction_2",
    "position_offset",
    "time_friction",
    "time_coulomb",
    "time_offset",
)
#: low-speed friction candidates: name -> (shape, its fixed exponent or velocity in rad/s) (module docstring)
SPEED_CANDIDATES = {
    "power_friction_0.25": ("power", 0.25),
    "power_friction_0.5": ("power", 0.5),
    "power_friction_0.75": ("power", 0.75),
    "wide_onset_0.1": ("onset", 0.1),
    "wide_onset_0.2": ("onset", 0.2),
    "wide_onset_0.3": ("onset", 0.3),
    "wide_onset_0.5": ("onset", 0.5),
}
#: candidates chosen per outer fold among fixed ones by an inner leave-one-out on the training movements
INNER_CV_CANDIDATES = {
    "power_friction_inner_cv": ("power_friction_0.25", "power_friction_0.5", "power_friction_0.75"),
    "wide_onset_inner_cv": ("wide_onset_0.1", "wide_onset_0.2", "wide_onset_0.3", "wide_onset_0.5"),
}
#: the folds' scatter of the held-out error, points (docs/results.md, the position term's screening)
SCATTER_POINTS = 0.17
#: candidates whose columns depend on the fitted rigid-body torque (module docstring)
LOAD_CANDIDATES = (
    "load_friction",
    "load_friction_direction",
    "load_friction_quadrant",
    "load_gain",
    "load_friction_gain",
)
#: the fixed point's stop: largest change of the training ``tau_load`` over its largest value
LOAD_TOLERANCE = 1e-8
LOAD_MAX_ITERATIONS = 200
#: the load candidates' coefficient names, one per feature
LOAD_COLUMN_NAMES = {
    "load_friction": ("both",),
    "load_friction_direction": ("positive", "negative"),
    "load_friction_quadrant": ("motoring", "braking"),
    "load_gain": ("gain",),
    "load_friction_gain": ("both", "gain"),
}
ALL_CANDIDATES = (*CANDIDATES, *SPEED_CANDIDATES, *INNER_CV_CANDIDATES, *LOAD_CANDIDATES, *DAHL_CANDIDATES)


def features(model: ArmIdentificationModel, log: ArmLog, candidate: str, load: FloatArray | None = None) -> list[FloatArray]:
    """The candidate's per-joint features, each (T, n), of the prepared ``log`` (module docstring); ``load`` (T, n) the
    movement's rigid-body torque for the load candidates."""
    if candidate in LOAD_CANDIDATES:
        if load is None:
            raise SpaceIdInputError(f"{candidate}: needs the movement's rigid-body torque")
        return load_features(model, log, candidate, load)
    q, dq = log.q_rad, log.dq_rad_s
    s = model.regressor.friction.smooth_sign(dq)
    if candidate in SPEED_CANDIDATES:
        shape, value = SPEED_CANDIDATES[candidate]
        return [s * np.abs(dq) ** value] if shape == "power" else [np.tanh(dq / value)]
    t = (log.t_s - log.t_s[0])[:, None] * np.ones((1, q.shape[1]))
    table = {
        "none": [],
        "position_friction": [s * np.cos(q), s * np.sin(q)],
        "position_friction_2": [s * np.cos(q), s * np.sin(q), s * np.cos(2 * q), s * np.sin(2 * q)],
        "position_offset": [np.cos(q), np.sin(q)],
        "time_friction": [s * t, dq * t],
        "time_coulomb": [s * t],
        "time_offset": [t],
    }
    return table[candidate]


def load_features(model: ArmIdentificationModel, log: ArmLog, candidate: str, load: FloatArray) -> list[FloatArray]:
    """The load candidates' per-joint features, each (T, n), of the rigid-body torque ``load`` (T, n)."""
    s = model.regressor.friction.smooth_sign(log.dq_rad_s)
    size = np.abs(load)
    if candidate == "load_friction":
        return [s * size]
    if candidate == "load_friction_direction":
        return [np.maximum(s, 0.0) * size, np.minimum(s, 0.0) * size]
    if candidate == "load_friction_quadrant":
        motoring = load * log.dq_rad_s > 0.0
        return [np.where(motoring, s * size, 0.0), np.where(motoring, 0.0, s * size)]
    gain = np.abs(s) * load
    return [gain] if candidate == "load_gain" else [s * size, gain]


def rigid_body_columns(model: ArmIdentificationModel) -> FloatArray:
    """(r,) mask of the base parameters that regroup link parameters (the rigid-body torque's)."""
    return model.base.independent < model.regressor.n_inertial


def rigid_body_torque(model: ArmIdentificationModel, item: IdentificationRows, theta: FloatArray) -> FloatArray:
    """(T, n) the rigid-body part of the prediction of ``theta`` (its first r entries the base parameters)."""
    mask = rigid_body_columns(model)
    return item.regressor[:, :, mask] @ theta[: model.n_params][mask]


def regressor(
    model: ArmIdentificationModel, item: IdentificationRows, candidate: str, load: FloatArray | None = None
) -> FloatArray:
    """(T, n, r + n m): the model's regressor and the candidate's m features as one column per joint and feature."""
    n_samples, n_joints, _ = item.regressor.shape
    blocks = [item.regressor]
    for feature in features(model, item.log, candidate, load):
        block = np.zeros((n_samples, n_joints, n_joints))
        block[:, np.arange(n_joints), np.arange(n_joints)] = feature
        blocks.append(block)
    return np.concatenate(blocks, axis=2)


def ur_design(model: ArmIdentificationModel, item: ControllerModelRows, candidate: str) -> FloatArray:
    """(T, n, 1 + k + m): UR's refitted model's per-joint columns and the candidate's m features (one each per joint)."""
    extra = features(model, item.log, candidate)
    return np.concatenate([item.features, *(feature[..., None] for feature in extra)], axis=2)


def two_step_wls(design: FloatArray, effort: FloatArray) -> FloatArray:
    """Weighted least squares of the stacked (T, n, k) ``design`` on ``effort`` (T, n), per-joint weights from OLS."""
    y, tau = design.reshape(-1, design.shape[2]), effort.reshape(-1)
    joint = np.tile(np.arange(effort.shape[1]), effort.shape[0])
    residual = y @ np.linalg.lstsq(y, tau, rcond=None)[0] - tau
    weight = 1.0 / np.sqrt(np.bincount(joint, residual**2) / np.bincount(joint))[joint]
    return np.linalg.lstsq(y * weight[:, None], tau * weight, rcond=None)[0]


@dataclass(frozen=True)
class Fold:
    """One fold's fit: the held-out error overall (%) and per joint (n,), the parameters, the fixed point's iterations
    and the candidate fitted (the inner leave-one-out's choice for those candidates)."""

    overall: float
    per_joint: FloatArray
    theta: FloatArray
    iterations: int
    chosen: str


def relative_error(measured: FloatArray, predicted: FloatArray) -> tuple[float, FloatArray]:
    """``100 ||e|| / ||tau||`` overall and per joint (n,), %."""
    error = measured - predicted
    return (
        float(100.0 * np.linalg.norm(error) / np.linalg.norm(measured)),
        100.0 * np.linalg.norm(error, axis=0) / np.linalg.norm(measured, axis=0),
    )


def fit(model: ArmIdentificationModel, train: list[IdentificationRows], candidate: str) -> tuple[FloatArray, int]:
    """The candidate's parameters on the ``train`` movements and the fixed point's iterations (0: a single fit)."""
    effort = np.concatenate([item.log.effort for item in train])
    if candidate not in LOAD_CANDIDATES:
        return two_step_wls(np.concatenate([regressor(model, item, candidate) for item in train]), effort), 0
    theta = two_step_wls(np.concatenate([item.regressor for item in train]), effort)
    load = [rigid_body_torque(model, item, theta) for item in train]
    for iteration in range(1, LOAD_MAX_ITERATIONS + 1):
        theta = two_step_wls(
            np.concatenate([regressor(model, item, candidate, x) for item, x in zip(train, load, strict=True)]), effort
        )
        new = [rigid_body_torque(model, item, theta) for item in train]
        change = max(np.abs(a - b).max() for a, b in zip(new, load, strict=True)) / max(np.abs(a).max() for a in new)
        load = new
        if change < LOAD_TOLERANCE:
            return theta, iteration
    raise RuntimeError(f"{candidate}: the fixed point did not converge in {LOAD_MAX_ITERATIONS} iterations")


class OursScreen:
    """The identification model with a candidate's columns, two-step WLS, on the prepared rows of every movement."""

    label = "ours (wls)"
    joints_apart = False

    def __init__(self, model: ArmIdentificationModel, rows: dict[str, IdentificationRows]) -> None:
        self.model, self.rows = model, rows
        self.presliding: dict[str, FloatArray] = {}  # the Dahl columns by movement (ur5_presliding.py)

    def effort(self, name: str) -> FloatArray:
        """(T, n) the prepared effort of movement ``name``."""
        return self.rows[name].log.effort

    def design(self, name: str) -> FloatArray:
        """(T, n, r) the model's regressor of movement ``name``."""
        return self.rows[name].regressor

    def coulomb_slots(self) -> FloatArray:
        """(n, c) per joint its Coulomb columns in :meth:`design` (one, or one per direction; never regrouped)."""
        names = list(self.model.base.names)
        columns = [c for c in self.model.regressor.friction.columns if c.startswith("coulomb")]
        return np.array([[names.index(f"joint{j + 1}_{c}_Nm") for c in columns] for j in range(self.model.n_joints)])

    def column_scale(self, name: str) -> FloatArray:
        """(n,) the model's unit of a friction column (effort per N m)."""
        return 1.0 / self.model.torque_per_effort(self.rows[name].log.effort_kind)

    def solve(self, design: FloatArray, effort: FloatArray) -> FloatArray:
        """The parameters of ``design`` (T, n, k) on ``effort`` (T, n), two-step WLS."""
        return two_step_wls(design, effort)

    def predict(self, design: FloatArray, theta: FloatArray) -> FloatArray:
        """(T, n) the prediction of ``theta`` with ``design``."""
        return design @ theta

    def levels(self, theta: FloatArray) -> FloatArray:
        """(n, c) the fitted Coulomb (or Dahl) levels, N m."""
        return theta[self.coulomb_slots()]

    def fit(self, train: Sequence[str], candidate: str) -> tuple[FloatArray, int]:
        """The parameters on the ``train`` movements and the fixed point's iterations."""
        return fit(self.model, [self.rows[name] for name in train], candidate)

    def error(self, theta: FloatArray, held: str, candidate: str) -> tuple[float, FloatArray]:
        """The held-out error of ``theta`` on ``held``."""
        item = self.rows[held]
        load = rigid_body_torque(self.model, item, theta) if candidate in LOAD_CANDIDATES else None
        return relative_error(item.log.effort, regressor(self.model, item, candidate, load) @ theta)

    def extra(self, theta: FloatArray) -> FloatArray:
        """(m, n) the candidate's fitted coefficients, one row per feature."""
        return theta[self.model.n_params :].reshape(-1, self.model.n_joints)

    def friction(self, theta: FloatArray, column: str) -> FloatArray:
        """(n,) the model's friction coefficient ``column`` (e.g. ``viscous``) per joint (friction is never regrouped)."""
        names = list(self.model.base.names)
        prefixes = [f"joint{j + 1}_{column}_" for j in range(self.model.n_joints)]
        return np.array([theta[next(i for i, n in enumerate(names) if n.startswith(prefix))] for prefix in prefixes])


class UrScreen:
    """UR's refitted model (``estimators.arm.controller_model``) with a candidate's columns, per-joint least squares."""

    label = "UR's refitted"
    joints_apart = True

    def __init__(self, model: ArmIdentificationModel, rows: dict[str, ControllerModelRows]) -> None:
        self.model, self.rows = model, rows
        self.n_base = next(iter(rows.values())).features.shape[2]
        self.presliding: dict[str, FloatArray] = {}  # the Dahl columns by movement (ur5_presliding.py)

    def effort(self, name: str) -> FloatArray:
        """(T, n) the prepared current of movement ``name``."""
        return self.rows[name].log.effort

    def design(self, name: str) -> FloatArray:
        """(T, n, 1 + k) the refitted model's per-joint columns of movement ``name``."""
        return self.rows[name].features

    def coulomb_slots(self) -> FloatArray:
        """(n, c) per joint its Coulomb columns in :meth:`design`."""
        columns = self.model.regressor.friction.columns
        return np.tile([1 + i for i, c in enumerate(columns) if c.startswith("coulomb")], (self.model.n_joints, 1))

    def column_scale(self, name: str) -> FloatArray:
        """(n,) ones: the refitted model's friction is in the current's unit."""
        return np.ones(self.model.n_joints)

    def solve(self, design: FloatArray, effort: FloatArray) -> FloatArray:
        """Per joint the least-squares coefficients (n, k) of ``design`` (T, n, k) on ``effort`` (T, n)."""
        return np.stack([np.linalg.lstsq(design[:, j, :], effort[:, j], rcond=None)[0] for j in range(effort.shape[1])])

    def predict(self, design: FloatArray, theta: FloatArray) -> FloatArray:
        """(T, n) the prediction of the coefficients ``theta`` (n, k) with ``design``."""
        return np.einsum("tjk,jk->tj", design, theta)

    def levels(self, theta: FloatArray) -> FloatArray:
        """(n, c) the fitted Coulomb (or Dahl) levels, A."""
        return np.take_along_axis(theta, self.coulomb_slots(), axis=1)

    def fit(self, train: Sequence[str], candidate: str) -> tuple[FloatArray, int]:
        """Per joint the coefficients (n, 1 + k + m) on the ``train`` movements."""
        design = np.concatenate([ur_design(self.model, self.rows[name], candidate) for name in train])
        return self.solve(design, np.concatenate([self.effort(name) for name in train])), 0

    def error(self, theta: FloatArray, held: str, candidate: str) -> tuple[float, FloatArray]:
        """The held-out error of the coefficients ``theta`` on ``held``."""
        item = self.rows[held]
        return relative_error(item.log.effort, self.predict(ur_design(self.model, item, candidate), theta))

    def extra(self, theta: FloatArray) -> FloatArray:
        """(m, n) the candidate's fitted coefficients, one row per feature."""
        return theta[:, self.n_base :].T

    def friction(self, theta: FloatArray, column: str) -> FloatArray:
        """(n,) the friction coefficient ``column`` per joint (after the gain on ``m_target``)."""
        return theta[:, 1 + list(self.model.regressor.friction.columns).index(column)]


Screen = OursScreen | UrScreen


def inner_choice(screen: Screen, train: Sequence[str], options: Sequence[str]) -> str:
    """The option with the smallest mean held-out error of a leave-one-out over the ``train`` movements only."""
    inner = [
        np.mean([screen.error(screen.fit([n for n in train if n != i], option)[0], i, option)[0] for i in train])
        for option in options
    ]
    return options[int(np.argmin(inner))]


def held_out(screen: Screen, names: Sequence[str], candidate: str) -> list[Fold]:
    """Each fold's fit, leave one movement out."""
    folds = []
    for held in names:
        train = [name for name in names if name != held]
        if candidate in DAHL_CANDIDATES:
            theta, predicted, lengths = dahl_fit(screen, train, held, candidate)
            folds.append(Fold(*relative_error(screen.effort(held), predicted), theta, 0, lengths))
            continue
        chosen = inner_choice(screen, train, INNER_CV_CANDIDATES[candidate]) if candidate in INNER_CV_CANDIDATES else candidate
        theta, iterations = screen.fit(train, chosen)
        folds.append(Fold(*screen.error(theta, held, chosen), theta, iterations, chosen))
    return folds


def friction_curves(screen: Screen, candidate: str, theta: FloatArray, top_speed: FloatArray) -> FloatArray:
    """(2, n, W) the friction's size ``F_c,d + F_v w + c g(w)`` per direction ``d`` (forward, backward) and joint on
    ``W`` speeds ``w`` from 0 to the joint's ``top_speed`` (n,) rad/s, ``g`` the candidate's shape (``w^a`` or
    ``tanh(w / V)``); the smooth sign taken as 1 (the speeds well above its width)."""
    speed = np.linspace(0.0, 1.0, 201)[None, :] * top_speed[:, None]  # (n, W)
    shape, value = SPEED_CANDIDATES[candidate]
    g = speed**value if shape == "power" else np.tanh(speed / value)
    columns = screen.model.regressor.friction.columns
    if "coulomb" in columns:
        levels = [screen.friction(theta, "coulomb")] * 2
    else:  # the backward level multiplies min(s, 0): its size is the coefficient itself
        levels = [screen.friction(theta, "coulomb_positive"), screen.friction(theta, "coulomb_negative")]
    rising = screen.friction(theta, "viscous")[:, None] * speed + screen.extra(theta)[0][:, None] * g
    return np.stack([level[:, None] + rising for level in levels])


def report_physics(screen: Screen, folds: list[Fold], top_speed: FloatArray) -> None:
    """Per joint the viscous coefficient's range and, over the folds and directions, the friction's smallest size and
    smallest slope on 0..top speed (a dissipative friction: size >= 0; one rising with speed: slope >= 0)."""
    viscous = np.array([screen.friction(fold.theta, "viscous") for fold in folds])
    curves = np.array([friction_curves(screen, fold.chosen, fold.theta, top_speed) for fold in folds])  # (F, 2, n, W)
    slope = np.diff(curves, axis=-1)
    print(
        "    viscous per joint, min..max: "
        + " ".join(f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(viscous.min(0), viscous.max(0), strict=True))
    )
    print(
        "    friction size, min over folds, directions, 0..top speed: "
        + " ".join(f"{v:+.3f}" for v in curves.min(axis=(0, 1, 3)))
    )
    print(
        "    folds x directions with a falling stretch, per joint: "
        + " ".join(str(int(np.sum((slope < 0).any(axis=-1)[..., j]))) for j in range(curves.shape[2]))
        + f" (of {2 * len(folds)}); top speeds rad/s: "
        + " ".join(f"{v:.2f}" for v in top_speed)
    )


def report(screen: Screen, candidate: str, folds: list[Fold], baseline: list[Fold], top_speed: FloatArray) -> None:
    """One line for the candidate, its change against the baseline per fold and its fitted coefficients (for the speed
    candidates with the friction curve's checks on 0..``top_speed`` (n,), rad/s)."""
    overall = np.array([fold.overall for fold in folds])
    joints = " ".join(f"{value:5.1f}" for value in np.mean([fold.per_joint for fold in folds], axis=0))
    line = " ".join(f"{value:5.2f}" for value in overall)
    print(f"{candidate:<24} mean {overall.mean():6.2f} %  folds {line}  joints {joints}", flush=True)
    if candidate == "none":
        return
    change = overall - np.array([fold.overall for fold in baseline])
    print(
        f"    change {change.mean():+.3f} points (folds {' '.join(f'{d:+.2f}' for d in change)}), better on "
        f"{int(np.sum(change < 0))}/{len(change)}, by more than {SCATTER_POINTS} on "
        f"{int(np.sum(change < -SCATTER_POINTS))}/{len(change)}"
    )
    if candidate in INNER_CV_CANDIDATES:
        print(f"    inner leave-one-out's choice per fold: {' '.join(fold.chosen for fold in folds)}")
    if candidate in DAHL_CANDIDATES:
        report_levels(screen, [f.chosen for f in folds], [f.theta for f in folds], [f.theta for f in baseline])
    if candidate in SPEED_CANDIDATES or candidate in INNER_CV_CANDIDATES:
        extra = np.array([screen.extra(fold.theta) for fold in folds])  # (F, m, n)
        for k in range(extra.shape[1]):
            values = " ".join(
                f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(extra[:, k].min(axis=0), extra[:, k].max(axis=0), strict=True)
            )
            print(f"    coefficient per joint, min..max over the folds: {values}")
        report_physics(screen, folds, top_speed)
    if candidate in LOAD_CANDIDATES:
        mu = np.array([screen.extra(fold.theta) for fold in folds])  # (F, m, n)
        for k, name in enumerate(LOAD_COLUMN_NAMES[candidate]):
            values = " ".join(f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(mu[:, k].min(axis=0), mu[:, k].max(axis=0), strict=True))
            print(f"    mu {name:<9} per joint, min..max over the folds: {values}")
        print(f"    fixed-point iterations per fold: {' '.join(str(fold.iterations) for fold in folds)}", flush=True)


def real_setup(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> tuple[ArmIdentificationModel, Preparation, dict[str, ArmLog]]:
    """The model of ``args.friction`` with armature, the signal chain and the 7 undisturbed movements of ``args.data``."""
    try:
        friction = parse_friction(args.friction)
    except SpaceIdInputError as exc:
        parser.error(str(exc))
    model = ArmIdentificationModel.build(load_arm("ur5"), friction, armature=True)
    return model, Preparation(), load_movements(args.data, UNDISTURBED)


def ur_screen(model: ArmIdentificationModel, data: str, logs: dict[str, ArmLog], preparation: Preparation) -> UrScreen:
    """UR's refitted model with the model's friction terms and an offset, on the movements ``logs`` of ``data``."""
    friction = FrictionModel((*model.regressor.friction.terms, "offset"), model.regressor.friction.coulomb_smoothing_rad_s)
    return UrScreen(model, load_controller_rows(data, logs, preparation, friction))


def main() -> None:
    """One line per candidate."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="folder of the real UR5 movements (shared/data/ur5-real)")
    parser.add_argument("--friction", default="coulomb,viscous", help="the model's friction terms (default coulomb,viscous)")
    parser.add_argument("--candidates", default=",".join(ALL_CANDIDATES), help="comma-separated (default all)")
    parser.add_argument(
        "--ur-model", action="store_true", help="also UR's refitted model with the same columns (not the load candidates)"
    )
    args = parser.parse_args()
    candidates = [name.strip() for name in args.candidates.split(",") if name.strip()]
    unknown = [name for name in candidates if name not in ALL_CANDIDATES]
    if unknown:
        parser.error(f"--candidates: unknown {unknown}; expected some of {list(ALL_CANDIDATES)}")
    model, preparation, logs = real_setup(parser, args)
    screens: list[Screen] = [OursScreen(model, preparation.all_rows(model, logs))]
    if args.ur_model:
        screens.append(ur_screen(model, args.data, logs, preparation))
    if set(DAHL_CANDIDATES) & set(candidates):
        columns = {name: presliding_columns(model, log, preparation) for name, log in logs.items()}
        for screen in screens:
            screen.presliding = columns
    names = list(logs)
    top_speed = np.max([np.abs(item.log.dq_rad_s).max(axis=0) for item in screens[0].rows.values()], axis=0)
    print(f"model: {','.join(model.regressor.friction.terms)} + armature; folds (held out): {', '.join(names)}")
    for screen in screens:
        print(f"\n{screen.label}")
        baseline = held_out(screen, names, "none")
        for candidate in candidates:
            if isinstance(screen, UrScreen) and candidate in LOAD_CANDIDATES:
                continue
            folds = baseline if candidate == "none" else held_out(screen, names, candidate)
            report(screen, candidate, folds, baseline, top_speed)


if __name__ == "__main__":
    main()
