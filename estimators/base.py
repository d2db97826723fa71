"""The estimator protocol (scikit-learn style): options in the constructor, ``fit(model, log)`` returns an estimate.

Writing an estimator: subclass :class:`Estimator`, give it a ``name``, keyword-only constructor
options stored under the same attribute names (``get_params`` reads them back), and implement
:meth:`Estimator._search`, which works on an :class:`~estimators.problem.IdentificationProblem`
and returns a :class:`SearchResult`. The base class times the fit, checks the log is long enough
(:meth:`Estimator.min_samples`), seeds the generator and builds the :class:`~estimators.estimate.Estimate`
(Cramér-Rao bound, identifiability, physical quantities). Register it with
:func:`estimators.registry.register_estimator` to name it in the CLI and the env.
"""

from __future__ import annotations

import inspect
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from estimators.estimate import Estimate
from estimators.problem import IdentificationModel, IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog


@dataclass
class SearchResult:
    """What :meth:`Estimator._search` returns.

    Attributes:
        theta: the estimate, (k,).
        cost_history: best whole-log cost (rad/s)^2 after each iteration/generation.
        extra: estimator-specific diagnostics for the estimate file (JSON-serialisable).
    """

    theta: FloatArray
    cost_history: list[float] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)


class Estimator(ABC):
    """Base class of all estimators; see the module docstring.

    Args:
        seed: seed of the estimator's generator (``numpy.random.default_rng(seed)``); the same
            seed on the same log gives the same estimate.
    """

    name: ClassVar[str] = "estimator"

    def __init__(self, *, seed: int | None = 0) -> None:
        self.seed = seed

    def get_params(self) -> dict[str, Any]:
        """The constructor options and their current values."""
        names = [
            p.name
            for cls in type(self).__mro__
            if "__init__" in cls.__dict__
            for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
            if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        ]
        return {n: _plain(getattr(self, n)) for n in dict.fromkeys(names) if n != "seed"}

    def min_samples(self, problem: IdentificationProblem) -> int:
        """Fewest log samples this estimator needs (default: more residuals than unknowns)."""
        return problem.n_params // 3 + 2

    def fit(self, model: IdentificationModel, log: MeasurementLog) -> Estimate:
        """Identify ``model``'s parameters from ``log``; returns the :class:`Estimate`."""
        start = time.perf_counter()
        problem = model.problem(log)
        return self.fit_problem(problem, _started=start)

    def fit_problem(self, problem: IdentificationProblem, _started: float | None = None) -> Estimate:
        """As :meth:`fit`, on a problem already set up (to fit several estimators on one log)."""
        start = time.perf_counter() if _started is None else _started
        needed = self.min_samples(problem)
        if problem.n_samples < needed:
            raise SpaceIdInputError(
                f"log: {problem.n_samples} samples is shorter than the estimator {self.name!r} needs "
                f"({needed} samples with its options {self.get_params()})"
            )
        problem.n_model_samples = 0
        result = self._search(problem, np.random.default_rng(self.seed))
        wall = time.perf_counter() - start
        return problem.make_estimate(
            result.theta,
            estimator=self.name,
            options=self.get_params(),
            seed=self.seed,
            cost_history=result.cost_history,
            wall_time_s=wall,
            extra=result.extra,
        )

    def search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        """The bare search on a set-up problem (no timing, no estimate): for composing estimators (e.g. ``hybrid``)."""
        return self._search(problem, rng)

    @abstractmethod
    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        """Find the parameters minimising ``problem.cost``; all randomness from ``rng``."""

    def __repr__(self) -> str:
        options = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({options})"


def _plain(value: Any) -> Any:
    """Options as JSON-friendly values (nested estimators by their name and options)."""
    if isinstance(value, Estimator):
        return {"estimator": value.name, **value.get_params()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
