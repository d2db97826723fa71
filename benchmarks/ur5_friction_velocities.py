"""Do the real UR5 logs ask for Stribeck friction, or another width of the smooth sign? Nested leave-one-out.

Two fixed velocities shape the friction columns (:class:`~spaceid_gym.arm.friction.FrictionModel`): the Stribeck
velocity ``vs`` of ``(fs - fc) exp(-(dq / vs)^2) s(dq)`` and the width ``v_eps`` of the smooth sign
``s(dq) = tanh(dq / v_eps)``. Neither is identified by the linear fit, and choosing either on the held-out
movements would make the held-out error optimistic. So each is chosen by an **inner** leave-one-out on each outer
fold's training movements only:

* outer fold: hold out movement ``k`` of the 7 undisturbed movements;
* for every value ``g`` of the grid, inner error = the mean over the 6 training movements ``i`` of the held-out
  error on ``i`` of the fit on the other 5 (``100 ||e|| / ||i||``, all joints, as ``arm cross-validate``);
* the value with the smallest inner error is fitted on the 6 and scored on ``k``.

The same is done, with its own choice, for UR's refitted model (``i_j ~ a_j m_target_j + friction_j``, the
``--compare-ur-model`` of ``arm cross-validate``) with the same friction terms and an offset. Our model is fitted by
``--estimator`` (default ``sdp``, whose friction coefficients are ``>= 0``, the Stribeck excess ``fs - fc``
included); ``wls`` (unconstrained) is nested the same way, for the sign the data give the coefficient.
``--stribeck-sign free`` lets the consistent fit take a negative excess too (a friction below the Coulomb level at
low speed: not Stribeck friction, a measurement of what the unconstrained fits point at).

Scans (``--scan``):

* ``stribeck``: the model's terms plus ``stribeck`` at each ``vs`` of ``--grid`` (``v_eps`` at its default), against
  the model without it;
* ``smoothing``: the model's terms at each ``v_eps`` of ``--grid`` (no Stribeck term), against the default width.

Printed: per outer fold the chosen value, the baseline's and the nested fit's held-out error (ours and UR's); the
means per joint; the mean held-out error of every fixed grid value (for information only: picking the best of these
would be choosing on the held-out folds); the fitted coefficients at the chosen values.

Run: ``.venv/bin/python benchmarks/ur5_friction_velocities.py ur5-real/ --friction coulomb_asymmetric,viscous --scan
stribeck`` (and ``--friction coulomb,viscous``, ``--scan smoothing``); the figures in ``docs/results.md``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from ur5_colony_vs_sdp import UNDISTURBED
from ur5_real_noise_floor import EDGE_SAMPLES

from estimators.arm.controller_model import (
    ControllerModelRows,
    fit_controller_model,
    load_controller_rows,
    predict_controller_model,
)
from estimators.arm.identification import (
    Preparation,
    error_of_prediction,
    fit,
    load_movements,
    prediction_error,
    raw_period,
)
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.friction import FrictionModel
from spaceid_gym.arm.signal import lowpass_zero_phase
from spaceid_gym.arm_cli import parse_friction
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

DEFAULTS = FrictionModel()
GRIDS = {"stribeck": "0.005,0.01,0.02,0.05,0.1,0.2,0.5,1", "smoothing": "0.002,0.005,0.01,0.02,0.05,0.1"}


@dataclass(frozen=True)
class Variant:
    """One value of the scan: our model's rows and UR's refitted model's rows for every movement."""

    value: float
    friction: FrictionModel
    model: ArmIdentificationModel
    rows: dict[str, IdentificationRows]
    ur_rows: dict[str, ControllerModelRows]


#: a fit and score: (training movements, held-out movement) -> per-joint error (n,) and overall error, %
Scorer = Callable[[tuple[str, ...], str], tuple[FloatArray, float]]


class Scores:
    """Cached held-out errors (and fitted coefficients) of one variant, ours and UR's, by training set."""

    def __init__(self, variant: Variant, estimator_spec: str) -> None:
        self.variant = variant
        self.estimator = estimator_from_spec(estimator_spec, seed=0)
        self._ours: dict[tuple[str, ...], FloatArray] = {}
        self._ur: dict[tuple[str, ...], FloatArray] = {}

    def ours_theta(self, train: tuple[str, ...]) -> FloatArray:
        """Our model's base parameters fitted on ``train``."""
        if train not in self._ours:
            v = self.variant
            self._ours[train] = fit(v.model, {n: v.rows[n] for n in train}, self.estimator).theta
        return self._ours[train]

    def ur_coefficients(self, train: tuple[str, ...]) -> FloatArray:
        """UR's refitted model's coefficients (n, 1 + k) on ``train``."""
        if train not in self._ur:
            self._ur[train] = fit_controller_model([self.variant.ur_rows[n] for n in train])
        return self._ur[train]

    def ours(self, train: tuple[str, ...], held: str) -> tuple[FloatArray, float]:
        """Our model's held-out error on ``held`` fitted on ``train``."""
        v = self.variant
        error = prediction_error(v.model, self.ours_theta(train), v.rows[held])
        return error.relative_percent, error.overall_percent

    def ur(self, train: tuple[str, ...], held: str) -> tuple[FloatArray, float]:
        """UR's refitted model's held-out error on ``held`` fitted on ``train``."""
        item = self.variant.ur_rows[held]
        error = error_of_prediction(item.log, predict_controller_model(self.ur_coefficients(train), item))
        return error.relative_percent, error.overall_percent


def others(names: tuple[str, ...], *left_out: str) -> tuple[str, ...]:
    """The movements of ``names`` but ``left_out``, in order."""
    return tuple(n for n in names if n not in left_out)


def nested_choice(scorers: list[Scorer], names: tuple[str, ...], held: str) -> tuple[int, FloatArray]:
    """The index of the scorer with the smallest inner leave-one-out error on the movements but ``held``, and the
    inner errors (one per scorer)."""
    train = others(names, held)
    inner = np.array([np.mean([score(others(train, i), i)[1] for i in train]) for score in scorers])
    return int(np.argmin(inner)), inner


class FreeStribeckModel(ArmIdentificationModel):
    """The identification model with the Stribeck excess ``fs - fc`` free in sign in the consistent fits (``sdp``):
    a negative excess is a friction below the Coulomb level at low speed, which is not Stribeck friction. For the
    measurement ``--stribeck-sign free`` only; the package's model keeps it ``>= 0``."""

    def _joint_term_bounds(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        columns, lower, upper = super()._joint_term_bounds()
        stribeck = np.array(["_stribeck_" in self.regressor.parameter_names[c] for c in columns])
        lower = np.where(stribeck, -upper, lower)
        return columns, lower, upper


def build_variants(
    folder: str, terms: tuple[str, ...], scan: str, grid: list[float], free_sign: bool = False
) -> tuple[Variant, list[Variant]]:
    """The baseline (the terms at the default velocities, no Stribeck term) and one variant per grid value."""
    preparation = Preparation()
    logs = load_movements(folder, UNDISTURBED)
    robot = load_arm("ur5")

    def variant(value: float, friction: FrictionModel) -> Variant:
        model = (FreeStribeckModel if free_sign else ArmIdentificationModel).build(robot, friction, armature=True)
        ur_friction = FrictionModel(
            (*friction.terms, "offset"), friction.coulomb_smoothing_rad_s, friction.stribeck_velocity_rad_s
        )
        return Variant(
            value,
            friction,
            model,
            preparation.all_rows(model, logs),
            load_controller_rows(folder, logs, preparation, ur_friction),
        )

    base_terms = tuple(t for t in terms if t != "stribeck")
    baseline = variant(float("nan"), FrictionModel(base_terms))
    if scan == "stribeck":
        variants = [variant(v, FrictionModel((*base_terms, "stribeck"), stribeck_velocity_rad_s=v)) for v in grid]
    else:
        variants = [variant(v, FrictionModel(base_terms, coulomb_smoothing_rad_s=v)) for v in grid]
    return baseline, variants


def columns_of(model: ArmIdentificationModel, column: str) -> list[int]:
    """The base parameters that are joint ``j``'s friction coefficient ``column``, j = 1..n (friction is never regrouped)."""
    names = list(model.base.names)
    return [names.index(f"joint{j + 1}_{column}_Nm") for j in range(model.n_joints)]


def _row(label: str, values: FloatArray, overall: float) -> str:
    return f"| {label} | " + " | ".join(f"{v:.1f}" for v in values) + f" | {overall:.2f} |"


def print_velocity_noise(folder: str) -> None:
    """Per movement and joint the white-noise std the filtered rate keeps (rad/s), estimated as
    ``benchmarks/ur5_real_noise_floor.py`` does for the current: the raw rate's content above the cutoff, taken as
    white, times the filter's noise gain (an upper bound: that content holds motion too)."""
    preparation = Preparation()
    print("filtered joint-rate noise std, rad/s (joints 1-6)")
    for name, log in load_movements(folder, UNDISTURBED).items():
        dt_s = raw_period(log)
        gain = preparation.noise_gain(dt_s)
        t_s = np.arange(log.t_s[0], log.t_s[-1], dt_s)
        rate = np.stack([np.interp(t_s, log.t_s, log.dq_rad_s[:, j]) for j in range(log.n_joints)], axis=1)
        high = (rate - lowpass_zero_phase(rate, dt_s, preparation.cutoff_hz, preparation.order))[EDGE_SAMPLES:-EDGE_SAMPLES]
        sigma = high.std(axis=0) / np.sqrt(1.0 - gain**2)
        print(f"  {name:<38} " + " ".join(f"{v:.4f}" for v in sigma * gain))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="the folder of real UR5 movements (ur5-real/)")
    parser.add_argument("--friction", default="coulomb_asymmetric,viscous", help="the model's friction terms (no stribeck)")
    parser.add_argument("--scan", choices=sorted(GRIDS), default="stribeck")
    parser.add_argument("--velocity-noise", action="store_true", help="only print the filtered rate's noise per movement")
    parser.add_argument("--grid", default=None, help="comma-separated velocities, rad/s (default per scan)")
    parser.add_argument("--estimator", default="sdp", help="our model's estimator (default sdp)")
    parser.add_argument(
        "--stribeck-sign",
        choices=("non-negative", "free"),
        default="non-negative",
        help="the Stribeck excess's constraint in the consistent fits (default non-negative, the package's)",
    )
    args = parser.parse_args()
    if args.velocity_noise:
        print_velocity_noise(args.data)
        return
    grid = [float(v) for v in (args.grid or GRIDS[args.scan]).split(",")]
    if not grid or any(not (np.isfinite(v) and v > 0) for v in grid):
        raise SpaceIdInputError(f"--grid: expected velocities > 0 rad/s, got {args.grid!r}")
    terms = parse_friction(args.friction)
    if "stribeck" in terms:
        raise SpaceIdInputError("--friction: give the model without 'stribeck'; --scan stribeck adds it")
    start = time.perf_counter()
    baseline, variants = build_variants(args.data, terms, args.scan, grid, args.stribeck_sign == "free")
    names = tuple(UNDISTURBED)
    base, base_wls = Scores(baseline, args.estimator), Scores(baseline, "wls")
    scores = [Scores(v, args.estimator) for v in variants]
    wls = [Scores(v, "wls") for v in variants]
    label = "vs" if args.scan == "stribeck" else "v_eps"
    print(f"model: {baseline.model.describe()}; scan {args.scan} ({label}, rad/s) over {grid}; estimator {args.estimator}")
    print(
        "| held out | chosen (ours) | baseline ours % | nested ours % | chosen (UR) | baseline UR % | nested UR % "
        "| chosen (wls) | baseline wls % | nested wls % |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    keys = ("base", "nested", "base_ur", "nested_ur", "base_wls", "nested_wls")
    per_fold: dict[str, list[FloatArray]] = {key: [] for key in keys}
    overall: dict[str, list[float]] = {key: [] for key in per_fold}
    chosen: dict[str, tuple[int, int]] = {}
    for held in names:
        train = others(names, held)
        k_ours, _ = nested_choice([s.ours for s in scores], names, held)
        k_ur, _ = nested_choice([s.ur for s in scores], names, held)
        k_wls, _ = nested_choice([w.ours for w in wls], names, held)
        chosen[held] = (k_ours, k_ur)
        for key, (joints, total) in {
            "base": base.ours(train, held),
            "nested": scores[k_ours].ours(train, held),
            "base_ur": base.ur(train, held),
            "nested_ur": scores[k_ur].ur(train, held),
            "base_wls": base_wls.ours(train, held),
            "nested_wls": wls[k_wls].ours(train, held),
        }.items():
            per_fold[key].append(joints)
            overall[key].append(total)
        print(
            f"| {held} | {grid[k_ours]:g} | {overall['base'][-1]:.2f} | {overall['nested'][-1]:.2f} | "
            f"{grid[k_ur]:g} | {overall['base_ur'][-1]:.2f} | {overall['nested_ur'][-1]:.2f} | "
            f"{grid[k_wls]:g} | {overall['base_wls'][-1]:.2f} | {overall['nested_wls'][-1]:.2f} |"
        )
    print("\nmean over the folds, % (joints 1-6 | overall)")
    for key, text in {
        "base": f"ours, baseline ({args.estimator})",
        "nested": f"ours, {label} chosen by inner CV ({args.estimator})",
        "base_ur": "UR's refitted, baseline",
        "nested_ur": f"UR's refitted, {label} chosen by inner CV",
        "base_wls": "ours, baseline (wls)",
        "nested_wls": f"ours, {label} chosen by inner CV (wls)",
    }.items():
        print(_row(text, np.mean(per_fold[key], axis=0), float(np.mean(overall[key]))))
    for model, (a, b) in {
        f"ours ({args.estimator})": ("base", "nested"),
        "UR's": ("base_ur", "nested_ur"),
        "ours (wls)": ("base_wls", "nested_wls"),
    }.items():
        diff = np.array(overall[b]) - np.array(overall[a])
        print(
            f"{model}: change {diff.mean():+.3f} points (folds: {' '.join(f'{d:+.2f}' for d in diff)}), "
            f"better on {int(np.sum(diff < 0))}/7, by more than 0.17 points on {int(np.sum(diff < -0.17))}/7; "
            f"std error of the mean change {diff.std(ddof=1) / np.sqrt(len(diff)):.3f}"
        )
    print("\nfixed values, mean held-out error over the 7 folds (information only: not a choice), %")
    print(f"| {label} | ours ({args.estimator}) | ours (wls) | UR's refitted |")
    print("|---:|---:|---:|---:|")
    for value, s, w in zip(grid, scores, wls, strict=True):
        print(
            f"| {value:g} | {np.mean([s.ours(others(names, h), h)[1] for h in names]):.2f} | "
            f"{np.mean([w.ours(others(names, h), h)[1] for h in names]):.2f} | "
            f"{np.mean([s.ur(others(names, h), h)[1] for h in names]):.2f} |"
        )
    if args.scan == "stribeck":
        print_stribeck_coefficients(names, chosen, grid, scores, wls)
    print(f"\n{time.perf_counter() - start:.0f} s")


def print_stribeck_coefficients(
    names: tuple[str, ...], chosen: dict[str, tuple[int, int]], grid: list[float], scores: list[Scores], wls: list[Scores]
) -> None:
    """The fitted Stribeck excess ``fs - fc`` per joint and fold at the chosen ``vs``: ours (N m) with the estimator and
    with wls, UR's (A)."""
    print("\nStribeck excess fs - fc per joint at each fold's chosen vs (ours N m, UR's A)")
    for held in names:
        k_ours, k_ur = chosen[held]
        train = others(names, held)
        model = scores[k_ours].variant.model
        at = columns_of(model, "stribeck")
        ours = scores[k_ours].ours_theta(train)[at]
        free = wls[k_ours].ours_theta(train)[at]
        ur_terms = scores[k_ur].variant.ur_rows[held].features.shape[-1]
        ur = scores[k_ur].ur_coefficients(train)[:, 1 + list(scores[k_ur].variant.friction.columns).index("stribeck")]
        print(
            f"  {held:<38} ours: {' '.join(f'{v:+.3f}' for v in ours)} | wls: {' '.join(f'{v:+.3f}' for v in free)} | "
            f"UR's ({ur_terms} columns): {' '.join(f'{v:+.4f}' for v in ur)}"
        )
    print("\nStribeck excess per joint at every vs, min..max over the 7 folds: wls (N m) | UR's refitted (A)")
    for value, s, w in zip(grid, scores, wls, strict=True):
        at = columns_of(w.variant.model, "stribeck")
        ur_at = 1 + list(w.variant.friction.columns).index("stribeck")
        free = np.array([w.ours_theta(others(names, h))[at] for h in names])
        ur = np.array([s.ur_coefficients(others(names, h))[:, ur_at] for h in names])
        print(
            f"  vs {value:<6g} wls: "
            + " ".join(f"{a:+.2f}..{b:+.2f}" for a, b in zip(free.min(0), free.max(0), strict=True))
            + " | UR's: "
            + " ".join(f"{a:+.3f}..{b:+.3f}" for a, b in zip(ur.min(0), ur.max(0), strict=True))
        )


if __name__ == "__main__":
    main()
