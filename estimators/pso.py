"""Classic particle swarm optimisation (the paper's eq. 16), the baseline of the improved PSO.

Every particle is evaluated on the whole log each generation (``problem.cost``), so a fit costs
exactly ``n_particles x n_generations`` whole-log evaluations; ``max_evaluations`` instead fixes
that budget (``n_generations = floor(max_evaluations / n_particles)``) to compare estimators at an
equal number of objective evaluations. The update, bounds and inertia schedule are those of
:mod:`estimators.swarm`.
"""

from __future__ import annotations

import numpy as np

from estimators.base import SearchResult
from estimators.options import check_float, check_int
from estimators.problem import IdentificationProblem
from estimators.swarm import (
    DEFAULT_C1,
    DEFAULT_C2,
    DEFAULT_INERTIA,
    DEFAULT_MAX_VELOCITY,
    Inertia,
    SwarmEstimator,
    global_best,
    inertia_at,
    ring_best,
)
from spaceid_gym.errors import SpaceIdInputError


class ParticleSwarm(SwarmEstimator):
    """Classic PSO over the unit box with a global-best or ring topology.

    Args:
        n_particles: swarm size N (default 40).
        n_generations: generations G (default 50); replaced by ``max_evaluations`` when that is given.
        topology: ``"global"`` (every particle follows the swarm's best: fast, collapses early) or
            ``"ring"`` (the best of itself and ``ring_neighbours`` index neighbours each side: slower, more diverse).
        ring_neighbours: neighbours each side on the ring (default 1; ring topology only).
        inertia: ``w``, constant or ``(start, end)`` decreased linearly (default ``DEFAULT_INERTIA`` of :mod:`estimators.swarm`).
        c1, c2: cognitive and social weights (default ``DEFAULT_C1``, ``DEFAULT_C2``).
        max_velocity: velocity limit, box widths per generation (default ``DEFAULT_MAX_VELOCITY``).
        max_evaluations: budget in whole-log evaluations; sets ``n_generations = floor(max_evaluations / n_particles)``.
        seed: the generator's seed.

    The estimate is the best personal best (its whole-log cost is known exactly); ``cost_history``
    holds that cost after each generation.
    """

    name = "pso"

    def __init__(
        self,
        *,
        n_particles: int = 40,
        n_generations: int = 50,
        topology: str = "global",
        ring_neighbours: int = 1,
        inertia: Inertia = DEFAULT_INERTIA,
        c1: float = DEFAULT_C1,
        c2: float = DEFAULT_C2,
        max_velocity: float = DEFAULT_MAX_VELOCITY,
        max_evaluations: float | None = None,
        seed: int | None = 0,
    ) -> None:
        super().__init__(
            n_particles=n_particles,
            n_generations=n_generations,
            inertia=inertia,
            c1=c1,
            c2=c2,
            max_velocity=max_velocity,
            seed=seed,
        )
        if topology not in ("global", "ring"):
            raise SpaceIdInputError(f"topology: expected 'global' or 'ring', got {topology!r}")
        self.topology = topology
        self.ring_neighbours = check_int("ring_neighbours", ring_neighbours, 1)
        if max_evaluations is not None:
            check_float("max_evaluations", max_evaluations, self.n_particles, np.inf)
        self.max_evaluations = max_evaluations

    @property
    def generations(self) -> int:
        """Generations run: ``n_generations``, or ``floor(max_evaluations / n_particles)`` when a budget is given."""
        if self.max_evaluations is None:
            return self.n_generations
        return int(self.max_evaluations // self.n_particles)

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        params = problem.parameters
        n_generations = self.generations
        unit, velocity = self._initial_swarm(rng, self.n_particles, problem.n_params)
        best_unit = unit.copy()
        best_cost = np.full(self.n_particles, np.inf)
        history: list[float] = []
        for generation in range(1, n_generations + 1):
            cost = problem.cost(params.from_unit(unit))
            better = cost < best_cost
            best_unit[better], best_cost[better] = unit[better], cost[better]
            history.append(float(best_cost.min()))
            if generation == n_generations:
                break
            leader = global_best(best_cost) if self.topology == "global" else ring_best(best_cost, self.ring_neighbours)
            weight = inertia_at(self.inertia, generation, n_generations)
            unit, velocity = self._move(rng, unit, velocity, best_unit, best_unit[leader], weight)
        best = int(np.argmin(best_cost))
        spread = np.std(params.from_unit(best_unit), axis=0)
        return SearchResult(
            theta=params.from_unit(best_unit[best]),
            cost_history=history,
            extra={"n_generations_run": n_generations, "final_pbest_std": spread.tolist()},
        )
