"""Accuracy at an equal budget of objective evaluations: improved PSO against classic PSO and reference optimisers.

Every estimator with a ``max_evaluations`` option gets, on each window, the evaluations improved-pso
used there (see :mod:`estimators.evaluation`); errors are reported as multiples of the
Cramér-Rao bound (RMS error / RMS bound) on the same windows. Usage::

    python benchmarks/equal_budget.py [--settings 40] [--seed 1] [--jobs 2]
"""

from __future__ import annotations

import argparse

from estimators.evaluation import draw_settings, markdown_table, run_evaluation, summarise
from spaceid_gym.robots import load_robot

SPECS = ("improved-pso", "pso", "pso[topology=ring]", "de", "cma-es", "pyswarms-local")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="paper6")
    parser.add_argument("--settings", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    settings = draw_settings(load_robot(args.robot), args.settings, args.seed)
    rows = run_evaluation(args.robot, SPECS, settings, budget_reference="improved-pso", jobs=args.jobs)
    print(markdown_table(summarise(rows)))


if __name__ == "__main__":
    main()
