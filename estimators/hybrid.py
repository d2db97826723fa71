"""The toolkit's default estimator: a global search, then a least-squares polish of its result.

The global search (by default the improved PSO) finds the basin of the global minimum, which the
least-squares step alone cannot be trusted to do from a fixed start; least squares then converges
to the bottom of that basin, the maximum-likelihood estimate, in a few Jacobians. The global
search therefore needs to be only good enough to land in the right basin, and the result is as
accurate as the log allows (the Cramér-Rao bound) rather than as the search's budget allows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from estimators.base import Estimator, SearchResult
from estimators.least_squares import LeastSquaresPolish
from estimators.problem import IdentificationProblem
from estimators.registry import make_estimator
from spaceid_gym.errors import SpaceIdInputError


class HybridEstimator(LeastSquaresPolish):
    """Global search then least-squares polish (registry name ``hybrid``).

    Args:
        global_search: registry name of the global estimator (default ``"improved-pso"``) or an
            :class:`~estimators.base.Estimator`. It is run with the hybrid's generator, so the
            hybrid's ``seed`` alone fixes the result (the global estimator's own seed is not used).
        global_options: options of the global estimator when ``global_search`` is a name.
        **options: the least-squares options ``method``, ``ftol``, ``xtol``, ``gtol``, ``max_iterations``
            and ``seed`` (see :class:`~estimators.least_squares.LeastSquaresPolish`).

    ``cost_history`` is the global search's history followed by the polish's; ``extra`` holds each
    stage's ``evaluations`` (whole-log equivalents), ``wall_time_s`` and own diagnostics under
    ``global`` and ``polish``.
    """

    name: ClassVar[str] = "hybrid"

    def __init__(
        self, *, global_search: str | Estimator = "improved-pso", global_options: dict[str, Any] | None = None, **options: Any
    ) -> None:
        super().__init__(**options)
        if isinstance(global_search, Estimator) and global_options:
            raise SpaceIdInputError(
                "global_options: pass the options to the global estimator itself when global_search is an Estimator"
            )
        if global_options is not None and not isinstance(global_options, dict):
            raise SpaceIdInputError(f"global_options: expected a dict of options or None, got {global_options!r}")
        self.global_search = global_search
        self.global_options = global_options
        self.global_estimator = make_estimator(global_search, **(global_options or {}))

    def min_samples(self, problem: IdentificationProblem) -> int:
        """As many samples as both stages need."""
        return max(super().min_samples(problem), self.global_estimator.min_samples(problem))

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        found, global_stage = _stage(problem, lambda: self.global_estimator.search(problem, rng))
        polished, polish_stage = _stage(problem, lambda: self.polish(problem, found.theta))
        global_stage.update(estimator=self.global_estimator.name, theta=np.asarray(found.theta, dtype=float).tolist())
        return SearchResult(
            theta=polished.theta,
            cost_history=[*found.cost_history, *polished.cost_history],
            extra={"global": {**found.extra, **global_stage}, "polish": {**polished.extra, **polish_stage}},
        )


def _stage(problem: IdentificationProblem, run: Callable[[], SearchResult]) -> tuple[SearchResult, dict[str, Any]]:
    """Run one stage; return its result and its ``evaluations`` (whole-log equivalents) and ``wall_time_s``."""
    began, budget = time.perf_counter(), problem.n_model_samples
    result = run()
    return result, {
        "evaluations": (problem.n_model_samples - budget) / problem.n_samples,
        "wall_time_s": time.perf_counter() - began,
    }
