"""Held-out error of ``sdp`` with the Dahl (presliding) columns in place of the Coulomb ones, leave one of the 7
undisturbed real UR5 movements out: a measurement after the ``dahl`` screening of ``ur5_extra_terms.py``, not a model
option.

Per fold the presliding lengths are the screening's (``ur5_presliding.choose_lengths``: the WLS training cost on the
fold's 6 training movements, never the held-out one); the model's parallel-filtered regressor with each joint's
Coulomb column(s) replaced by its Dahl column(s) goes to the ``sdp`` estimator unchanged, as the columns keep their
meaning (one friction level ``>= 0`` per joint, or per joint and direction). Printed per candidate (``none`` = the
model): the mean held-out error over the folds (``100 ||e|| / ||i||``, as ``arm cross-validate``), each fold's, each
joint's mean, the change against ``none``, the folds physically consistent, the lengths chosen; and UR's refitted
model with the same friction and an offset (no Dahl term), the target.

Run: ``.venv/bin/python benchmarks/ur5_presliding_sdp.py ur5-real/ --friction coulomb_asymmetric,viscous``.
"""

from __future__ import annotations

import argparse

import numpy as np
from ur5_extra_terms import SCATTER_POINTS, OursScreen, held_out, real_setup, ur_screen
from ur5_presliding import DAHL_CANDIDATES, choose_lengths, dahl_design, lengths_text, presliding_columns, stacked_columns

from estimators.arm.identification import fit, physically_consistent, prediction_error
from estimators.arm.model import IdentificationRows
from estimators.evaluation import estimator_from_spec


def substituted(screen: OursScreen, name: str, choice: np.ndarray) -> IdentificationRows:
    """Movement ``name``'s rows with the Dahl columns of the grid indices ``choice`` (n,) (-1: kept)."""
    design, columns, _ = stacked_columns(screen, [name])
    return IdentificationRows(screen.rows[name].log, dahl_design(screen, design, columns, choice))


def main() -> None:
    """One line per candidate, then UR's refitted model."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="folder of the real UR5 movements (shared/data/ur5-real)")
    parser.add_argument("--friction", default="coulomb,viscous", help="the model's friction terms (default coulomb,viscous)")
    args = parser.parse_args()
    model, preparation, logs = real_setup(parser, args)
    screen = OursScreen(model, preparation.all_rows(model, logs))
    screen.presliding = {name: presliding_columns(model, log, preparation) for name, log in logs.items()}
    estimator = estimator_from_spec("sdp", seed=0)
    names = list(logs)
    print(f"model: {args.friction} + armature, sdp; folds (held out): {', '.join(names)}")
    baseline = None
    for candidate in ("none", *DAHL_CANDIDATES):
        overall, joints, consistent, chosen = [], [], 0, []
        for held in names:
            train = [name for name in names if name != held]
            choice = np.full(model.n_joints, -1) if candidate == "none" else choose_lengths(screen, train, candidate)
            estimate = fit(model, {name: substituted(screen, name, choice) for name in train}, estimator)
            error = prediction_error(model, estimate.theta, substituted(screen, held, choice))
            overall.append(error.overall_percent)
            joints.append(error.relative_percent)
            consistent += bool(physically_consistent(estimate))
            chosen.append(lengths_text(choice))
        mean = np.mean(joints, axis=0)
        print(
            f"{candidate:<16} mean {np.mean(overall):6.2f} %  folds {' '.join(f'{v:5.2f}' for v in overall)}  joints "
            f"{' '.join(f'{v:5.1f}' for v in mean)}  consistent {consistent}/{len(names)}",
            flush=True,
        )
        if baseline is None:
            baseline = np.array(overall)
            continue
        change = np.array(overall) - baseline
        print(
            f"    change {change.mean():+.3f} points (folds {' '.join(f'{d:+.2f}' for d in change)}), better on "
            f"{int(np.sum(change < 0))}/{len(change)}, by more than {SCATTER_POINTS} on "
            f"{int(np.sum(change < -SCATTER_POINTS))}/{len(change)}"
        )
        print("    presliding length per joint (rad), by fold:\n" + "\n".join(f"      {line}" for line in chosen))
    folds = held_out(ur_screen(model, args.data, logs, preparation), names, "none")
    values = " ".join(f"{fold.overall:5.2f}" for fold in folds)
    per_joint = " ".join(f"{v:5.1f}" for v in np.mean([fold.per_joint for fold in folds], axis=0))
    print(f"{'UR refitted':<16} mean {np.mean([f.overall for f in folds]):6.2f} %  folds {values}  joints {per_joint}")


if __name__ == "__main__":
    main()
