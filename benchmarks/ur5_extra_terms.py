"""Do the real UR5 logs ask for a position-dependent friction term, a drift in time (temperature) or a friction
growing with the load? Held-out error of weighted least squares with and without each candidate term, leave one of
the 7 undisturbed movements out.

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

``s`` is the model's smooth sign. Weights: Gautier's two-step per-joint weights (the std of each joint's OLS
residual). Printed per candidate: the mean held-out error over the folds (``100 ||e|| / ||tau||`` over all joints, as
``arm cross-validate``), each fold's and each joint's mean.

Run: ``.venv/bin/python benchmarks/ur5_extra_terms.py ur5-real/`` (add ``--friction coulomb_asymmetric,viscous`` for
the recommended real model); the figures in ``docs/results.md``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
from ur5_colony_vs_sdp import UNDISTURBED

from estimators.arm.identification import Preparation, load_movements
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from spaceid_gym.arm.arm_robot import load_arm
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


def features(
    model: ArmIdentificationModel, item: IdentificationRows, candidate: str, load: FloatArray | None = None
) -> list[FloatArray]:
    """The candidate's per-joint features, each (T, n) (module docstring); ``load`` (T, n) the movement's rigid-body
    torque for the load candidates."""
    if candidate in LOAD_CANDIDATES:
        if load is None:
            raise SpaceIdInputError(f"{candidate}: needs the movement's rigid-body torque")
        return load_features(model, item, candidate, load)
    q, dq = item.log.q_rad, item.log.dq_rad_s
    t = (item.log.t_s - item.log.t_s[0])[:, None] * np.ones((1, q.shape[1]))
    s = model.regressor.friction.smooth_sign(dq)
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


def load_features(model: ArmIdentificationModel, item: IdentificationRows, candidate: str, load: FloatArray) -> list[FloatArray]:
    """The load candidates' per-joint features, each (T, n), of the rigid-body torque ``load`` (T, n)."""
    s = model.regressor.friction.smooth_sign(item.log.dq_rad_s)
    size = np.abs(load)
    if candidate == "load_friction":
        return [s * size]
    if candidate == "load_friction_direction":
        return [np.maximum(s, 0.0) * size, np.minimum(s, 0.0) * size]
    if candidate == "load_friction_quadrant":
        motoring = load * item.log.dq_rad_s > 0.0
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
    for feature in features(model, item, candidate, load):
        block = np.zeros((n_samples, n_joints, n_joints))
        block[:, np.arange(n_joints), np.arange(n_joints)] = feature
        blocks.append(block)
    return np.concatenate(blocks, axis=2)


def two_step_wls(design: FloatArray, effort: FloatArray) -> FloatArray:
    """Weighted least squares of the stacked (T, n, k) ``design`` on ``effort`` (T, n), per-joint weights from OLS."""
    y, tau = design.reshape(-1, design.shape[2]), effort.reshape(-1)
    joint = np.tile(np.arange(effort.shape[1]), effort.shape[0])
    residual = y @ np.linalg.lstsq(y, tau, rcond=None)[0] - tau
    weight = 1.0 / np.sqrt(np.bincount(joint, residual**2) / np.bincount(joint))[joint]
    return np.linalg.lstsq(y * weight[:, None], tau * weight, rcond=None)[0]


@dataclass(frozen=True)
class Fold:
    """One fold's fit: the held-out error overall (%) and per joint (n,), the parameters, the fixed point's iterations."""

    overall: float
    per_joint: FloatArray
    theta: FloatArray
    iterations: int


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


def held_out(model: ArmIdentificationModel, rows: dict[str, IdentificationRows], candidate: str) -> list[Fold]:
    """Each fold's fit, leave one movement out."""
    folds = []
    for held in rows:
        theta, iterations = fit(model, [rows[name] for name in rows if name != held], candidate)
        item = rows[held]
        load = rigid_body_torque(model, item, theta) if candidate in LOAD_CANDIDATES else None
        measured = item.log.effort
        error = measured - regressor(model, item, candidate, load) @ theta
        folds.append(
            Fold(
                100.0 * np.linalg.norm(error) / np.linalg.norm(measured),
                100.0 * np.linalg.norm(error, axis=0) / np.linalg.norm(measured, axis=0),
                theta,
                iterations,
            )
        )
    return folds


def main() -> None:
    """One line per candidate."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="folder of the real UR5 movements (shared/data/ur5-real)")
    parser.add_argument("--friction", default="coulomb,viscous", help="the model's friction terms (default coulomb,viscous)")
    parser.add_argument("--candidates", default=",".join(CANDIDATES + LOAD_CANDIDATES), help="comma-separated (default all)")
    args = parser.parse_args()
    candidates = [name.strip() for name in args.candidates.split(",") if name.strip()]
    unknown = [name for name in candidates if name not in CANDIDATES + LOAD_CANDIDATES]
    if unknown:
        parser.error(f"--candidates: unknown {unknown}; expected some of {list(CANDIDATES + LOAD_CANDIDATES)}")
    try:
        friction = parse_friction(args.friction)
    except SpaceIdInputError as exc:
        parser.error(str(exc))
    model = ArmIdentificationModel.build(load_arm("ur5"), friction, armature=True)
    rows = Preparation().all_rows(model, load_movements(args.data, UNDISTURBED))
    print(f"model: {','.join(friction)} + armature; folds (held out): {', '.join(rows)}")
    for candidate in candidates:
        folds = held_out(model, rows, candidate)
        overall = np.array([fold.overall for fold in folds])
        joints = " ".join(f"{value:5.1f}" for value in np.mean([fold.per_joint for fold in folds], axis=0))
        line = " ".join(f"{value:5.2f}" for value in overall)
        print(f"{candidate:<24} mean {overall.mean():6.2f} %  folds {line}  joints {joints}", flush=True)
        if candidate in LOAD_CANDIDATES:
            mu = np.array([fold.theta[model.n_params :].reshape(-1, model.n_joints) for fold in folds])  # (F, m, n)
            for k, name in enumerate(LOAD_COLUMN_NAMES[candidate]):
                values = " ".join(
                    f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(mu[:, k].min(axis=0), mu[:, k].max(axis=0), strict=True)
                )
                print(f"    mu {name:<9} per joint, min..max over the folds: {values}")
            print(f"    fixed-point iterations per fold: {' '.join(str(fold.iterations) for fold in folds)}", flush=True)


if __name__ == "__main__":
    main()
