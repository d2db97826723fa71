"""Reference global optimisers on the same objective, to show where PSO stands at an equal budget.

* :class:`DifferentialEvolution` (``de``): :func:`scipy.optimize.differential_evolution`;
* :class:`CMAES` (``cma-es``): the ``cma`` package's CMA-ES;
* :class:`PyswarmsLocalBest` (``pyswarms-local``): pyswarms' ``LocalBestPSO`` (ring topology).

All three evaluate their whole population with one batched ``problem.cost`` call per generation
(whole log), run for ``max_evaluations // population_size`` generations, at least one (so the budget,
in whole-log evaluations, is never exceeded when it covers a generation) and return the best point evaluated. None of them polishes its result:
that is the least-squares step of the hybrid estimator. The shared pieces (budget, search box, the
batched objective that tracks the best point and the per-generation history) are :class:`PopulationSearch`
and :class:`BatchObjective`.

Determinism: DE and CMA-ES draw from the estimator's generator (``rng``) directly. pyswarms draws from
NumPy's *global* generator; it is seeded from ``rng`` for the run and its previous state restored afterwards.
"""

from __future__ import annotations

import contextlib
import logging.config
from abc import abstractmethod
from collections.abc import Iterator
from numbers import Real
from typing import Any, ClassVar
from unittest import mock

import numpy as np
from scipy.optimize import differential_evolution
from scipy.stats import qmc

from estimators.base import Estimator, SearchResult
from estimators.options import positive_option
from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: the mutation strategies of :func:`scipy.optimize.differential_evolution`
DE_STRATEGIES = (
    "best1bin",
    "best1exp",
    "best2bin",
    "best2exp",
    "rand1bin",
    "rand1exp",
    "rand2bin",
    "rand2exp",
    "randtobest1bin",
    "randtobest1exp",
    "currenttobest1bin",
    "currenttobest1exp",
)


class BatchObjective:
    """``problem.cost`` for a population, in the unit box or in the real bounds, tracking the best point.

    Each call is one generation: it evaluates the population on the whole log (counted in the
    budget), updates the best point and appends the best cost so far to ``history``.

    Args:
        problem: the identification problem.
        unit_box: ``True``: points are ``u`` in [0, 1]^k, ``theta = lower + u * width``; ``False``: ``theta`` itself.
    """

    def __init__(self, problem: IdentificationProblem, unit_box: bool) -> None:
        self.problem = problem
        self.unit_box = unit_box
        self.best_theta = problem.parameters.nominal.copy()
        self.best_cost = np.inf
        self.history: list[float] = []

    def theta(self, x: FloatArray) -> FloatArray:
        """Parameters (P, k) of the optimiser's points ``x`` (P, k)."""
        params = self.problem.parameters
        return params.from_unit(x) if self.unit_box else x

    def __call__(self, x: FloatArray) -> FloatArray:
        """Whole-log costs (P,) of the points ``x`` (P, k), (rad/s)^2."""
        theta = self.theta(np.atleast_2d(np.asarray(x, dtype=float)))
        cost = self.problem.cost(theta)
        best = int(np.argmin(cost))
        if cost[best] < self.best_cost:
            self.best_cost, self.best_theta = float(cost[best]), theta[best].copy()
        self.history.append(self.best_cost)
        return cost


class PopulationSearch(Estimator):
    """Base of the reference optimisers: a population, a budget and one batched cost call per generation.

    Args:
        population_size: points per generation (each costs one whole-log evaluation).
        max_evaluations: budget in whole-log evaluations; the optimiser runs
            ``max_evaluations // population_size`` generations (at least one), or fewer if it stops itself.
        seed: seed of the estimator's generator.
    """

    #: search in the unit box (``True``) or in the real bounds
    unit_box: ClassVar[bool] = True
    #: the smallest population the optimiser accepts
    min_population: ClassVar[int] = 2

    def __init__(self, *, population_size: int, max_evaluations: float, seed: int | None = 0) -> None:
        super().__init__(seed=seed)
        self.population_size = positive_option("population_size", population_size, integer=True)
        self.max_evaluations = positive_option("max_evaluations", max_evaluations)
        if self.population_size < self.min_population:
            raise SpaceIdInputError(f"population_size: {self.name} needs at least {self.min_population}, got {population_size}")
        if self.max_evaluations < self.population_size:
            raise SpaceIdInputError(
                f"max_evaluations: {max_evaluations} is less than one generation (population_size={population_size})"
            )

    @property
    def generations(self) -> int:
        """Generations that fit in the budget, counting the initial population as the first (at least one)."""
        return max(1, int(self.max_evaluations // self.population_size))

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        objective = BatchObjective(problem, self.unit_box)
        stopped_by = self._run(objective, rng)
        extra = {"population_size": self.population_size, "generations": len(objective.history), "stopped_by": stopped_by}
        return SearchResult(theta=objective.best_theta, cost_history=objective.history, extra=extra)

    @abstractmethod
    def _run(self, objective: BatchObjective, rng: np.random.Generator) -> str:
        """Run at most :attr:`generations` generations of ``objective``; return why the run ended."""


class DifferentialEvolution(PopulationSearch):
    """scipy's differential evolution in the unit box (registry name ``de``).

    The initial population is a Latin hypercube drawn from ``rng``; scipy's ``rng`` is the estimator's
    generator; ``updating="deferred"`` with ``vectorized=True`` (one cost call per generation);
    ``tol = atol = 0`` (runs to the budget); no polish.

    Args:
        population_size: individuals (default 20 = 5 k for the fuel problem; scipy requires at least 5).
        max_evaluations: budget in whole-log evaluations (default 400).
        strategy, mutation, recombination: as in :func:`scipy.optimize.differential_evolution` (scipy's defaults).
        seed: seed of the estimator's generator.
    """

    name: ClassVar[str] = "de"
    min_population: ClassVar[int] = 5

    def __init__(
        self,
        *,
        population_size: int = 20,
        max_evaluations: float = 400,
        strategy: str = "best1bin",
        mutation: float | tuple[float, float] = (0.5, 1.0),
        recombination: float = 0.7,
        seed: int | None = 0,
    ) -> None:
        super().__init__(population_size=population_size, max_evaluations=max_evaluations, seed=seed)
        self.strategy = strategy
        self.mutation = tuple(mutation) if isinstance(mutation, (list, tuple)) else mutation
        self.recombination = recombination
        if strategy not in DE_STRATEGIES:
            raise SpaceIdInputError(f"strategy: expected one of {', '.join(DE_STRATEGIES)}, got {strategy!r}")
        bounds = np.atleast_1d(np.asarray(self.mutation, dtype=object))
        numeric = all(isinstance(b, Real) and not isinstance(b, bool) for b in bounds)
        if not numeric or bounds.size not in (1, 2) or not all(0.0 <= b < 2.0 for b in bounds) or bounds[0] > bounds[-1]:
            raise SpaceIdInputError(
                f"mutation: expected a number in [0, 2) or a pair (min, max) with 0 <= min <= max < 2, got {mutation!r}"
            )
        if isinstance(recombination, bool) or not (isinstance(recombination, Real) and 0.0 <= recombination <= 1.0):
            raise SpaceIdInputError(f"recombination: expected a number in [0, 1], got {recombination!r}")

    def _run(self, objective: BatchObjective, rng: np.random.Generator) -> str:
        k = objective.problem.n_params
        result = differential_evolution(
            lambda u: objective(u.T),  # scipy passes the population as (k, S)
            [(0.0, 1.0)] * k,
            strategy=self.strategy,
            mutation=self.mutation,
            recombination=self.recombination,
            maxiter=self.generations - 1,
            init=qmc.LatinHypercube(k, rng=rng).random(self.population_size),
            tol=0.0,
            atol=0.0,
            polish=False,
            vectorized=True,
            updating="deferred",
            rng=rng,
        )
        return "budget" if result.nit >= self.generations - 1 else str(result.message)


class CMAES(PopulationSearch):
    """CMA-ES (the ``cma`` package) in the unit box [0, 1]^k (registry name ``cma-es``).

    Starts at the centre of the box with step size ``sigma0`` (0.3: the initial sample spans most
    of the box, +-1 sigma covers 60 % of each range); bounds by cma's ``BoundTransform``. Its normal
    draws come from the estimator's generator (cma's ``randn`` option; cma's own global seeding is
    off), so the run is deterministic and leaves NumPy's global state alone. cma's function-value
    tolerances (absolute, 1e-11) are switched off: the objective is ~1e-8 (rad/s)^2 and its minimum
    is resolved only at relative differences of ~1e-4 (~2e-12 absolute), so they would stop the run
    far from the minimum; the budget ends the run (or cma's step-size tolerances).

    Args:
        population_size: candidates per generation (default 8 = cma's ``4 + 3 ln k`` for k = 4).
        max_evaluations: budget in whole-log evaluations (default 400).
        sigma0: initial step size in units of the search range, in (0, 1].
        seed: seed of the estimator's generator.
    """

    name: ClassVar[str] = "cma-es"

    def __init__(
        self, *, population_size: int = 8, max_evaluations: float = 400, sigma0: float = 0.3, seed: int | None = 0
    ) -> None:
        super().__init__(population_size=population_size, max_evaluations=max_evaluations, seed=seed)
        self.sigma0 = positive_option("sigma0", sigma0)
        if self.sigma0 > 1.0:
            raise SpaceIdInputError(f"sigma0: expected a step size in (0, 1] (fraction of the search range), got {sigma0!r}")

    def _run(self, objective: BatchObjective, rng: np.random.Generator) -> str:
        import cma  # here, not at the top: importing cma takes ~0.5 s

        k = objective.problem.n_params
        options = {
            "bounds": [0.0, 1.0],
            "popsize": self.population_size,
            "maxfevals": self.generations * self.population_size,
            "seed": np.nan,  # no global seeding: the draws below come from rng
            "randn": lambda n, dim: rng.standard_normal((n, dim)),
            "tolfun": 0.0,
            "tolfunhist": 0.0,
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
        }
        es = cma.CMAEvolutionStrategy(np.full(k, 0.5), self.sigma0, options)
        for _ in range(self.generations):
            if es.stop():
                return ", ".join(sorted(es.stop()))
            candidates = es.ask()
            es.tell(candidates, objective(np.array(candidates)).tolist())
        return "budget"


class PyswarmsLocalBest(PopulationSearch):
    """pyswarms' ``LocalBestPSO`` in the real bounds (registry name ``pyswarms-local``).

    pyswarms draws from NumPy's *global* generator: for the run it is seeded from the estimator's
    generator and its previous state is restored afterwards (so the result depends only on ``seed``
    and other users of the global generator are unaffected). pyswarms also configures the root
    logger (a stderr handler and a ``report.log`` file in the working directory) whenever it builds
    its reporter, including on import; that configuration call is suppressed during the run.
    pyswarms' defaults otherwise: dynamic ring topology, periodic boundary handling, no velocity clamp.

    Args:
        population_size: particles (default 20).
        max_evaluations: budget in whole-log evaluations (default 400).
        inertia, cognitive, social: ``w``, ``c1``, ``c2`` (default: Clerc's constriction values 0.7298, 1.49618, 1.49618).
        neighbours: ring neighbourhood size ``k`` (default 4; fewer than ``population_size``).
        seed: seed of the estimator's generator.
    """

    name: ClassVar[str] = "pyswarms-local"
    unit_box: ClassVar[bool] = False

    def __init__(
        self,
        *,
        population_size: int = 20,
        max_evaluations: float = 400,
        inertia: float = 0.7298,
        cognitive: float = 1.49618,
        social: float = 1.49618,
        neighbours: int = 4,
        seed: int | None = 0,
    ) -> None:
        super().__init__(population_size=population_size, max_evaluations=max_evaluations, seed=seed)
        self.inertia = positive_option("inertia", inertia)
        self.cognitive = positive_option("cognitive", cognitive)
        self.social = positive_option("social", social)
        self.neighbours = positive_option("neighbours", neighbours, integer=True)
        if self.neighbours >= self.population_size:
            raise SpaceIdInputError(f"neighbours: expected fewer than population_size={population_size}, got {neighbours}")

    def _run(self, objective: BatchObjective, rng: np.random.Generator) -> str:
        params = objective.problem.parameters
        options = {"w": self.inertia, "c1": self.cognitive, "c2": self.social, "k": self.neighbours, "p": 2}
        with _global_numpy_seeded_from(rng), _pyswarms_logging_untouched():
            from pyswarms.single import LocalBestPSO

            swarm = LocalBestPSO(self.population_size, params.n_params, options, bounds=(params.lower, params.upper))
            swarm.optimize(objective, iters=self.generations, verbose=False)
        return "budget"


@contextlib.contextmanager
def _global_numpy_seeded_from(rng: np.random.Generator) -> Iterator[None]:
    """Seed NumPy's global generator from ``rng`` for the block; restore its previous state afterwards."""
    state = np.random.get_state()
    np.random.seed(int(rng.integers(2**32)))
    try:
        yield
    finally:
        np.random.set_state(state)


@contextlib.contextmanager
def _pyswarms_logging_untouched() -> Iterator[None]:
    """Keep pyswarms' ``Reporter`` from reconfiguring logging (``logging.config.dictConfig``) during the block."""
    with mock.patch.object(logging.config, "dictConfig", _ignore_logging_config):
        yield


def _ignore_logging_config(config: dict[str, Any]) -> None:
    """Stands in for ``logging.config.dictConfig`` while pyswarms runs."""
