"""Shared particle-swarm machinery for :mod:`estimators.pso` and :mod:`estimators.improved_pso`.

Both swarms search the **unit box** ``u = (theta - lower) / width`` in ``[0, 1]^k`` (so kg and m
are comparable and one velocity limit fits all parameters) with the update of the paper's eq. 16:

``v <- w v + c1 xi (pbest - u) + c2 eta (nbest - u)``, ``u <- u + v``,

``xi, eta ~ U(0, 1)`` drawn per particle and per coordinate. Velocities are clamped to
``+-max_velocity`` (box widths per generation); a particle leaving the box is put back on the
bound it crossed and that velocity component is zeroed (it does not keep pushing outwards).

Inertia: a constant ``w`` or a pair ``(w_start, w_end)`` decreased linearly over the generations:
large steps while the swarm explores, small ones when it refines. The paper gives no values for
``w``, ``c1``, ``c2`` or the velocity limit. The defaults, shared by both swarms, are
``DEFAULT_INERTIA = (0.7, 0.3)``, ``DEFAULT_C1 = DEFAULT_C2 = 2`` and ``DEFAULT_MAX_VELOCITY = 0.15``,
chosen for the improved PSO by measurement on settings disjoint from the README's evaluation
(``benchmarks/swarm_tuning.py``; the README's table uses settings seed 0): a grid of limits
(0.075-0.2) and schedules on the 100 settings of seed 1, then the choice among the three best
candidates on the 200 of seed 2. Classic PSO inherits them without being tuned itself. With Shi and
Eberhart's ``(0.9, 0.4)`` and a limit of 0.2 box widths the swarm explores for longer than G = 50
generations allow: on the 200 seed-2 settings the improved PSO without the quadratic step (and without
following its incumbent) then ends on average 3.5
chi-square units above the likelihood optimum (with its earlier K = 5 subsets), against 2.0 with
these defaults and K = 3.

Neighbourhood bests (``nbest``) are indices into the personal bests; three topologies are given
here: global best, a ring of ``r`` neighbours each side (by particle index) and the ``n`` nearest
particles by Euclidean distance in the unit box (the improved PSO's, eq. 17).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.options import check_float, check_int
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

IntArray = NDArray[np.intp]
Inertia = float | tuple[float, float]

#: default inertia schedule ``(w_start, w_end)`` of both swarms (see the module docstring)
DEFAULT_INERTIA: tuple[float, float] = (0.7, 0.3)
#: default velocity limit, box widths per generation (see the module docstring)
DEFAULT_MAX_VELOCITY: float = 0.15
#: default cognitive and social weights ``c1``, ``c2`` of the eq.-16 update
DEFAULT_C1: float = 2.0
DEFAULT_C2: float = 2.0


def check_inertia(value: Any) -> Inertia:
    """A constant inertia weight in [0, 1.2] or a ``(start, end)`` pair of them, else :class:`SpaceIdInputError`."""
    if isinstance(value, (tuple, list)):
        if len(value) != 2:
            raise SpaceIdInputError(f"inertia: expected a number or a (start, end) pair, got {value!r}")
        return (check_float("inertia", value[0], 0.0, 1.2), check_float("inertia", value[1], 0.0, 1.2))
    return check_float("inertia", value, 0.0, 1.2)


def inertia_at(inertia: Inertia, generation: int, n_generations: int) -> float:
    """Inertia weight at ``generation`` (1..G): constant, or linear from ``start`` (g = 1) to ``end`` (g = G)."""
    if not isinstance(inertia, tuple):
        return float(inertia)
    start, end = inertia
    return start + (end - start) * (generation - 1) / max(n_generations - 1, 1)


# ---------------------------------------------------------------------- topologies
def global_best(cost: FloatArray) -> IntArray:
    """Every particle's neighbourhood best is the swarm's best personal best: (N,) indices."""
    return np.full(len(cost), int(np.argmin(cost)), dtype=np.intp)


def ring_best(cost: FloatArray, neighbours: int) -> IntArray:
    """Best personal best among particle ``i`` and its ``neighbours`` ring neighbours each side (by index): (N,)."""
    n = len(cost)
    window = (np.arange(n)[:, None] + np.arange(-neighbours, neighbours + 1)[None, :]) % n  # (N, 2r+1)
    return window[np.arange(n), np.argmin(cost[window], axis=1)]


def nearest(unit: FloatArray, n_nearest: int) -> IntArray:
    """Indices (N, n) of each particle's ``n_nearest`` nearest particles in the unit box, itself included (unordered)."""
    n = len(unit)
    if n_nearest >= n:
        return np.broadcast_to(np.arange(n), (n, n))
    sq = np.einsum("ij,ij->i", unit, unit)
    dist2 = sq[:, None] + sq[None, :] - 2.0 * unit @ unit.T
    np.fill_diagonal(dist2, -1.0)  # itself first, even with coincident particles
    return np.argpartition(dist2, n_nearest - 1, axis=1)[:, :n_nearest]


def nearest_best(cost: FloatArray, neighbourhoods: IntArray) -> IntArray:
    """Best personal best within each particle's neighbourhood (N, n) of indices: (N,)."""
    return neighbourhoods[np.arange(len(neighbourhoods)), np.argmin(cost[neighbourhoods], axis=1)]


# ---------------------------------------------------------------------- the swarm
class SwarmEstimator(Estimator):
    """Options and update rule shared by the particle swarms (see the module docstring).

    Args:
        n_particles: swarm size N.
        n_generations: generations G (each evaluates every particle once).
        inertia: ``w``: a constant or a ``(start, end)`` pair decreased linearly over the generations.
        c1, c2: cognitive (towards the particle's best) and social (towards the neighbourhood best) weights.
        max_velocity: velocity limit per coordinate, in box widths per generation, in (0, 1].
        seed: the generator's seed.
    """

    def __init__(
        self,
        *,
        n_particles: int,
        n_generations: int,
        inertia: Inertia,
        c1: float,
        c2: float,
        max_velocity: float,
        seed: int | None,
    ) -> None:
        super().__init__(seed=seed)
        self.n_particles = check_int("n_particles", n_particles, 2)
        self.n_generations = check_int("n_generations", n_generations, 1)
        self.inertia = check_inertia(inertia)
        self.c1 = check_float("c1", c1, 0.0, 4.0)
        self.c2 = check_float("c2", c2, 0.0, 4.0)
        self.max_velocity = check_float("max_velocity", max_velocity, 0.0, 1.0, low_open=True)

    def _initial_swarm(self, rng: np.random.Generator, n_particles: int, n_params: int) -> tuple[FloatArray, FloatArray]:
        """Positions uniform in the unit box and velocities uniform in ``+-max_velocity``: two (N, k) arrays."""
        unit = rng.random((n_particles, n_params))
        velocity = self.max_velocity * (2.0 * rng.random((n_particles, n_params)) - 1.0)
        return unit, velocity

    def _move(
        self,
        rng: np.random.Generator,
        unit: FloatArray,
        velocity: FloatArray,
        best_unit: FloatArray,
        attractor: FloatArray,
        weight: float,
    ) -> tuple[FloatArray, FloatArray]:
        """One eq.-16 step of all particles: new ``(unit, velocity)``, both (N, k).

        Args:
            unit, velocity: positions and velocities (N, k).
            best_unit: personal bests (N, k); attractor: neighbourhood bests (N, k).
            weight: the inertia weight of this generation.
        """
        xi = rng.random(unit.shape)
        eta = rng.random(unit.shape)
        velocity = weight * velocity + self.c1 * xi * (best_unit - unit) + self.c2 * eta * (attractor - unit)
        np.clip(velocity, -self.max_velocity, self.max_velocity, out=velocity)
        unit = unit + velocity
        outside = (unit < 0.0) | (unit > 1.0)
        np.clip(unit, 0.0, 1.0, out=unit)
        velocity[outside] = 0.0
        return unit, velocity
