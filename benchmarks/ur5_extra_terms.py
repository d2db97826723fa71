"""Do the real UR5 logs ask for a position-dependent friction term or a drift in time (temperature)? Held-out error
of weighted least squares with and without each candidate term, leave one of the 7 undisturbed movements out.

The model is the identification model (``--friction``, default Coulomb + viscous, with a rotor inertia per joint);
each candidate adds per joint ``j`` columns that act on joint ``j``'s rows only, built from the prepared (filtered)
states of the log (a screening: the model's own columns are filtered in parallel with the effort instead):

* ``position_friction``: ``s(dq_j) cos q_j``, ``s(dq_j) sin q_j`` (a Coulomb level varying once per joint turn);
* ``position_friction_2``: the same and ``s(dq_j) cos 2 q_j``, ``s(dq_j) sin 2 q_j``;
* ``position_offset``: ``cos q_j``, ``sin q_j`` (a position-dependent torque, e.g. cogging or a cable);
* ``time_friction``: ``s(dq_j) t``, ``dq_j t`` (friction levels drifting linearly with the time since the movement
  started, as a warming joint's would); ``time_coulomb``: ``s(dq_j) t`` only; ``time_offset``: ``t``.

``s`` is the model's smooth sign. Weights: Gautier's two-step per-joint weights (the std of each joint's OLS
residual). Printed per candidate: the mean held-out error over the folds (``100 ||e|| / ||tau||`` over all joints, as
``arm cross-validate``), each fold's and each joint's mean.

Run: ``.venv/bin/python benchmarks/ur5_extra_terms.py ur5-real/`` (add ``--friction coulomb_asymmetric,viscous`` for
the recommended real model); the figures in ``docs/results.md``.
"""

from __future__ import annotations

import argparse

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


def features(model: ArmIdentificationModel, item: IdentificationRows, candidate: str) -> list[FloatArray]:
    """The candidate's per-joint features, each (T, n) (module docstring)."""
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


def regressor(model: ArmIdentificationModel, item: IdentificationRows, candidate: str) -> FloatArray:
    """(T, n, r + n m): the model's regressor and the candidate's m features as one column per joint and feature."""
    n_samples, n_joints, _ = item.regressor.shape
    blocks = [item.regressor]
    for feature in features(model, item, candidate):
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


def held_out(model: ArmIdentificationModel, rows: dict[str, IdentificationRows], candidate: str) -> tuple[FloatArray, FloatArray]:
    """Per fold (F,) the overall held-out error (%) and per fold and joint (F, n)."""
    overall, per_joint = [], []
    for held in rows:
        train = [name for name in rows if name != held]
        design = np.concatenate([regressor(model, rows[name], candidate) for name in train])
        effort = np.concatenate([rows[name].log.effort for name in train])
        theta = two_step_wls(design, effort)
        measured = rows[held].log.effort
        error = measured - regressor(model, rows[held], candidate) @ theta
        overall.append(100.0 * np.linalg.norm(error) / np.linalg.norm(measured))
        per_joint.append(100.0 * np.linalg.norm(error, axis=0) / np.linalg.norm(measured, axis=0))
    return np.array(overall), np.array(per_joint)


def main() -> None:
    """One line per candidate."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="folder of the real UR5 movements (shared/data/ur5-real)")
    parser.add_argument("--friction", default="coulomb,viscous", help="the model's friction terms (default coulomb,viscous)")
    args = parser.parse_args()
    try:
        friction = parse_friction(args.friction)
    except SpaceIdInputError as exc:
        parser.error(str(exc))
    model = ArmIdentificationModel.build(load_arm("ur5"), friction, armature=True)
    rows = Preparation().all_rows(model, load_movements(args.data, UNDISTURBED))
    print(f"model: {','.join(friction)} + armature; folds (held out): {', '.join(rows)}")
    for candidate in CANDIDATES:
        overall, per_joint = held_out(model, rows, candidate)
        folds = " ".join(f"{value:5.2f}" for value in overall)
        joints = " ".join(f"{value:5.1f}" for value in per_joint.mean(axis=0))
        print(f"{candidate:<20} mean {overall.mean():6.2f} %  folds {folds}  joints {joints}", flush=True)


if __name__ == "__main__":
    main()
