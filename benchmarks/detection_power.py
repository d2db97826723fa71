"""How often can ``diagnose`` name a hidden effect at all? Expected power of its likelihood-ratio test.

    python benchmarks/detection_power.py [--effect gyro_scale] [--magnitude SIZE] [--seeds 20] [--first-seed 0]

For each of the diagnosis suite's logs of ``--effect`` (same simulation, seeds and magnitude as
``spaceid diagnose-suite``: the default, or ``--magnitude`` as its ``--magnitude effect=SIZE``), the Fisher information of the candidate model (the ``fuel`` unknowns plus the
effect's) at the true parameters, for the documented gyro noise and, as in ``diagnose``, the star
tracker's channel (its simulated 5 arcsec). With the fuel unknowns free, the likelihood ratio of the effect is
non-central chi-square with ``k_e`` degrees of freedom and non-centrality ``lambda = d^T S d`` (``d`` the
true effect minus the nearest model without it, ``S`` the Schur complement of the effect's block: the information
left once the fuel unknowns have absorbed what they can; :mod:`estimators.diagnostics.power`). Its power against ``diagnose``'s threshold (``alpha = 0.01``,
Bonferroni over the catalogue's candidates) is the expected fraction of such logs on which ``diagnose``'s
test calls the effect significant: an upper bound on how often it can name it (naming also needs the lowest
BIC, plausibility and the explained fraction; ``diagnose`` estimates the gyro noise from the residual, about
3 % above the gyro's own because of the joint-rate noise). Local approximation: the Fisher information at the truth.

Prints ``lambda`` and the power per log, the mean power, the median ``lambda``, and the one the test needs for 90 %.
"""

from __future__ import annotations

import argparse
import inspect

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2, ncx2

from estimators.diagnostics import power
from estimators.diagnostics.diagnose import diagnose
from estimators.diagnostics.suite import SUITE_EFFECTS, parse_magnitudes, simulate_case
from estimators.problem import IdentificationModel
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.variations import truth_of

#: ``diagnose``'s significance level
ALPHA: float = inspect.signature(diagnose).parameters["alpha"].default


def non_centrality(effect: str, seed: int, robot: str = "paper6", magnitude: float | None = None) -> float:
    """``lambda`` of the effect's likelihood ratio on the suite's log of ``effect``, ``seed`` and ``magnitude`` (None: default)
    (:func:`estimators.diagnostics.power.non_centrality` against the ``fuel`` model)."""
    env = simulate_case(robot, effect, seed, magnitude=magnitude)
    return power.non_centrality(IdentificationModel(env.robot, "fuel"), effect, env.measurement_log(), truth_of(env))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effect", default="gyro_scale", choices=[e for e in SUITE_EFFECTS if e != "none"])
    parser.add_argument("--magnitude", default=None, help="the effect's size (units: spaceid_gym.effects.MAGNITUDE_UNITS)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds: expected at least 1, got {args.seeds}")
    try:
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        text = None if args.magnitude is None else f"{args.effect}={args.magnitude}"
        magnitude = parse_magnitudes(text, (args.effect,), "paper6", seeds)
    except SpaceIdInputError as exc:
        parser.error(str(exc))
    size = magnitude.get(args.effect)
    dof = power.effect_dof(IdentificationModel("paper6", "fuel"), args.effect)
    threshold = chi2.isf(ALPHA / power.N_TESTS, dof)
    powers, lambdas = [], []
    for seed in seeds:
        lam = non_centrality(args.effect, seed, magnitude=size)
        lambdas.append(lam)
        powers.append(power.power_of(lam, dof, ALPHA, power.N_TESTS))
        print(f"seed {seed:3d}: lambda {lam:9.1f}  power {powers[-1]:.2f}", flush=True)
    needed = brentq(lambda x: ncx2.sf(threshold, dof, x) - 0.9, 1e-3, 1e4)
    print(
        f"{args.effect} (magnitude {'default' if size is None else f'{size:g}'}): mean expected power of the test {np.mean(powers):.2f} over {len(powers)} logs; median lambda "
        f"{np.median(lambdas):.1f} against the threshold {threshold:.1f} "
        f"({dof} dof, level alpha {ALPHA} / {power.N_TESTS}: half of alpha over the candidates' tests); 90 % power needs lambda {needed:.1f}"
    )


if __name__ == "__main__":
    main()
