"""The improved particle swarm of the source paper: distance neighbourhoods, resets, sequential evaluation.

Three changes to the classic swarm of :mod:`estimators.pso` (update eq. 16, unit box, inertia and
bounds as in :mod:`estimators.swarm`), each switchable for an ablation:

1. ``neighbourhood`` (eq. 17): a particle follows the best personal best among its ``Nnb(g)``
   nearest particles (Euclidean distance in the unit box, itself included), with
   ``Nnb(g) = max(2, ceil((g / G) Knb N))`` growing linearly with the generation ``g = 1..G``
   (``Knb = neighbourhood_fraction``; at least itself and its nearest neighbour). Separate local
   optima develop instead of the whole swarm collapsing onto the first good point. Off: global best.
2. ``reset`` (eq. 18): after every ``Gre = reset_period`` generations (not after the last), the
   worst ``round(Kre N)`` particles by personal-best error (``Kre = reset_fraction``, at least one)
   move to ``nbest_r + xi``: ``r`` a particle drawn uniformly from the others, ``nbest_r`` its
   neighbourhood best, ``xi ~ N(0, (rho_r^2 / k) I)`` with ``rho_r`` the mean distance from ``r``
   to its ``Nnb(g) - 1`` nearest other particles, so ``E|xi|^2 = rho_r^2``: small where the swarm is
   dense, larger where it is sparse (without ``neighbourhood``, ``nbest_r`` is the global best; the
   radius still uses the ``Nnb(g)`` nearest). A reset particle restarts at rest with its new
   position as its personal best (evaluated in the next generation).
3. ``sequential`` (eq. 19): in generation ``g`` particle ``i`` is evaluated on subset
   ``(i + g) mod K`` of the log (``problem.subsets(K, subset_kind)``), so over ``K`` generations
   every particle sees the whole record, and one generation costs ``N / K`` whole-log evaluations:
   the swarm can be ``K`` times larger for the same budget. Off: every particle on the whole log.

**Comparable costs across subsets** (:mod:`estimators.subset_costs`, which says why). Every
comparison (personal bests, neighbourhood bests, resets) uses the **excess cost**
``c_s(x) - c_s(x_ref)`` of a point on its subset over the **incumbent** ``x_ref``, the best point
found so far judged on the whole log, evaluated on every subset. It starts at the
parameterisation's nominal. Each generation two candidates are evaluated on the whole log
(counted): the personal best with the lowest excess, and the *consensus*, the mean of the
``Nnb(G)`` lowest-excess personal bests (averaging positions averages out the subset noise that the
single lowest one is selected for; ``consensus=False`` drops it). The better replaces the incumbent
if its whole-log cost is lower; the checked personal best's noisy excess is replaced by its exact
whole-log one. Stored personal bests keep their raw cost and subset, so a new reference re-bases
them exactly (``excess = raw - c_s(x_ref)``); as the swarm closes in on the reference the remaining
subset noise (the ``e_s`` cross term, proportional to ``|x - x_ref|``) shrinks with it. Ranking raw subset
costs instead ends the search further above the likelihood optimum (figures on the results page).

**Not in the paper: ``quadratic`` and ``follow_fraction``** (both on by default;
``improved-pso[quadratic=false,follow_fraction=0]`` is the paper's method alone).

* ``quadratic``: each generation, a second-order model (a gradient per subset, one shared curvature:
  :mod:`estimators.quadratic_step`) is fitted to recent evaluations near the incumbent (from the last
  ``K`` generations, more when a small swarm needs them; per subset the lowest-excess ones among the
  ``NEAREST_FACTOR`` x as many nearest the incumbent) and its minimum, within the region the fitted
  points cover and within a trust radius, is checked on the whole log (one counted evaluation); it
  replaces the incumbent if better. It is the quadratic approximation of qPSO, with the subset
  structure of the sequential evaluation built into the model. Fitting the points nearest the
  incumbent rather than the swarm's lowest anywhere matters where the swarm holds several clusters
  along a curved valley: a quadratic through all of them fits none. The trust radius (unit box,
  unbounded at first) bounds the step's length; the next one is half the length of the step tried
  when it did not lower the cost, twice it when it did (a simplified trust-region rule: Conn, Gould
  and Toint, *Trust-Region Methods*, 2000, ch. 6, also weigh the decrease against the model's and
  never shrink after a good step). In a thin curved valley the fitted step points along the valley
  but overshoots its floor; without the radius the same rejected step would come back generation after
  generation.
* ``follow_fraction``: in a generation where the incumbent moved (a candidate check or the quadratic
  step), the worst ``round(follow_fraction N)`` particles (at least one) move to it: one onto it, the
  rest scattered round it as far as it moved (:meth:`ImprovedPSO._follow`). In a reset generation the
  particles just reset have no cost yet and count as the worst, so the followers are drawn from them
  (``n_resets`` still counts every reset). Without it the swarm never learns what
  the incumbent's checks found, and in a thin valley (Fisher condition numbers of 1e3 in the unit box
  when the tank is nearly empty) its isotropic moves creep along the valley for the whole run; with it
  the quadratic step gets points round the incumbent to fit, and walks the valley.

How these defaults were found, and what each addition gains, with the commands that measure it: the
documentation's results page, *How the swarm's defaults were chosen*.

The estimate is the best, on the whole log, of the incumbent and the final neighbourhood bests
(evaluated on the whole log, counted). ``cost_history`` is the incumbent's whole-log cost after each
generation (known exactly, no extra evaluation).

Swarm size: ``n_particles=None`` takes ``PARTICLES_PER_EVALUATION x n_subsets`` particles with
``sequential`` (``PARTICLES_PER_EVALUATION`` without), so a generation costs about
``PARTICLES_PER_EVALUATION`` whole-log evaluations either way and the ablations run at the same
budget (about 2170 whole-log evaluations for G = 50 with the defaults, 2114 with neither addition). 40 particles per evaluation keeps a fit on a
60 s, 50 Hz log under 0.5 s. The number of subsets is K = 3 (120 particles; chosen on settings disjoint from
the README's evaluation, see the results page): fewer subsets mean more samples per evaluation (a subset of
``3T/K`` residuals resolves only ~``sqrt(K)`` Cramér-Rao std) but a smaller swarm for the same budget.
``interleaved`` subsets are the default: each sees the whole excitation, where a ``contiguous`` one sees a part.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from estimators.base import SearchResult
from estimators.options import check_bool, check_float, check_int
from estimators.problem import IdentificationProblem
from estimators.quadratic_step import POINTS_PER_COEFFICIENT, n_coefficients, quadratic_step
from estimators.subset_costs import Incumbent, SubsetCosts
from estimators.swarm import (
    DEFAULT_C1,
    DEFAULT_C2,
    DEFAULT_INERTIA,
    DEFAULT_MAX_VELOCITY,
    FloatArray,
    Inertia,
    IntArray,
    SwarmEstimator,
    global_best,
    inertia_at,
    nearest,
    nearest_best,
)
from spaceid_gym.errors import SpaceIdInputError

#: whole-log evaluations per generation of the default swarm (particles per subset)
PARTICLES_PER_EVALUATION = 40
#: the quadratic step fits, per subset, the lowest-excess points among this many times as many nearest the incumbent
NEAREST_FACTOR = 2
#: the smallest trust radius of the quadratic step (unit box)
MIN_TRUST_RADIUS = 1e-6

#: one generation's evaluations: unit-box positions (N, k), subsets (N,), raw costs on them (N,) (rad/s)^2
Evaluations = tuple[FloatArray, IntArray, FloatArray]


def scattered(rng: np.random.Generator, centre: FloatArray, radius: FloatArray | float) -> FloatArray:
    """Points ``centre + xi`` clipped to the unit box, ``xi ~ N(0, (radius^2 / k) I)`` so ``E|xi|^2 = radius^2``.

    ``centre`` (R, k); ``radius`` (R,) per point, or one for all. Returns (R, k). Resets (eq. 18) and
    followers of the incumbent are placed with it.
    """
    xi = rng.standard_normal(centre.shape) * (np.reshape(radius, (-1, 1)) / np.sqrt(centre.shape[1]))
    return np.clip(centre + xi, 0.0, 1.0)


class ImprovedPSO(SwarmEstimator):
    """The paper's improved PSO; see the module docstring for the three strategies and the comparable costs.

    Args:
        n_particles: swarm size N; ``None`` (default): ``PARTICLES_PER_EVALUATION x n_subsets`` with
            ``sequential``, ``PARTICLES_PER_EVALUATION`` without (equal budget per generation).
        n_generations: G (default 50, the paper's).
        neighbourhood: distance-based growing neighbourhood (True) or global best (False).
        neighbourhood_fraction: Knb, the final neighbourhood as a fraction of N (default 0.10, the paper's).
        reset: reset the worst particles periodically.
        reset_period: Gre, generations between resets (default 10, the paper's).
        reset_fraction: Kre, fraction of the swarm reset (default 0.20, the paper's).
        sequential: evaluate each particle on one rotating subset of the log (True) or on the whole log.
        n_subsets: K, subsets of the log with ``sequential`` (default 3; ignored without).
        subset_kind: ``"interleaved"`` (every K-th sample, default: each subset spans the whole
            excitation) or ``"contiguous"`` (blocks).
        consensus: also check the mean of the ``Nnb(G)`` best personal bests on the whole log each generation.
        quadratic: also check the minimum of a quadratic fitted to the recent evaluations near the
            incumbent each generation (not in the paper; default on).
        follow_fraction: fraction of the swarm moved to the incumbent whenever it moves (not in the
            paper; default 0.10, 0 turns it off). Both off: the paper's method alone.
        inertia, c1, c2, max_velocity: the eq.-16 update (defaults: the ``DEFAULT_*`` of :mod:`estimators.swarm`).
        seed: the generator's seed.

    ``extra`` of the estimate: ``n_particles_used``, ``n_subsets_used``, ``n_whole_log_evaluations``
    (reference, candidate checks and finalists), ``n_finalists``, ``n_resets`` and
    ``final_pbest_std`` (spread of the personal bests, parameter units: the swarm's diversity).
    """

    name = "improved-pso"

    def __init__(
        self,
        *,
        n_particles: int | None = None,
        n_generations: int = 50,
        neighbourhood: bool = True,
        neighbourhood_fraction: float = 0.10,
        reset: bool = True,
        reset_period: int = 10,
        reset_fraction: float = 0.20,
        sequential: bool = True,
        n_subsets: int = 3,
        subset_kind: str = "interleaved",
        consensus: bool = True,
        quadratic: bool = True,
        follow_fraction: float = 0.10,
        inertia: Inertia = DEFAULT_INERTIA,
        c1: float = DEFAULT_C1,
        c2: float = DEFAULT_C2,
        max_velocity: float = DEFAULT_MAX_VELOCITY,
        seed: int | None = 0,
    ) -> None:
        self.sequential = check_bool("sequential", sequential)
        self.n_subsets = check_int("n_subsets", n_subsets, 1)
        if n_particles is None:
            n_particles = PARTICLES_PER_EVALUATION * (self.n_subsets if self.sequential else 1)
        super().__init__(
            n_particles=n_particles,
            n_generations=n_generations,
            inertia=inertia,
            c1=c1,
            c2=c2,
            max_velocity=max_velocity,
            seed=seed,
        )
        self.neighbourhood = check_bool("neighbourhood", neighbourhood)
        self.neighbourhood_fraction = check_float("neighbourhood_fraction", neighbourhood_fraction, 0.0, 1.0, low_open=True)
        self.reset = check_bool("reset", reset)
        self.reset_period = check_int("reset_period", reset_period, 1)
        self.reset_fraction = check_float("reset_fraction", reset_fraction, 0.0, 1.0, low_open=True, high_open=True)
        if subset_kind not in ("interleaved", "contiguous"):
            raise SpaceIdInputError(f"subset_kind: expected 'interleaved' or 'contiguous', got {subset_kind!r}")
        self.subset_kind = subset_kind
        self.consensus = check_bool("consensus", consensus)
        self.quadratic = check_bool("quadratic", quadratic)
        self.follow_fraction = check_float("follow_fraction", follow_fraction, 0.0, 1.0, high_open=True)
        if self.n_follow >= self.n_particles:
            raise SpaceIdInputError(
                f"follow_fraction: {self.follow_fraction:g} of {self.n_particles} particles moves the whole swarm to the incumbent"
            )
        if self.reset and self.n_particles - self.n_reset < 1:
            raise SpaceIdInputError(
                f"reset_fraction: {self.reset_fraction:g} of {self.n_particles} particles leaves no particle to reset towards"
            )

    # ------------------------------------------------------------------ schedules
    def neighbourhood_size(self, generation: int) -> int:
        """``Nnb(g) = max(2, ceil((g / G) Knb N))``, capped at N: particles in a neighbourhood, itself included."""
        size = math.ceil(generation / self.n_generations * self.neighbourhood_fraction * self.n_particles - 1e-9)
        return min(max(2, size), self.n_particles)

    @property
    def consensus_size(self) -> int:
        """Personal bests averaged into the consensus candidate: the final neighbourhood size ``Nnb(G)``."""
        return self.neighbourhood_size(self.n_generations)

    @property
    def n_follow(self) -> int:
        """Particles moved to the incumbent when it moves: ``round(follow_fraction N)``, at least one unless the fraction is 0."""
        return 0 if self.follow_fraction == 0.0 else max(1, round(self.follow_fraction * self.n_particles))

    @property
    def n_reset(self) -> int:
        """Particles reset each time: ``max(1, round(Kre N))``."""
        return max(1, round(self.reset_fraction * self.n_particles))

    def resets_after(self, generation: int) -> bool:
        """Whether the worst particles are reset after ``generation`` (every ``reset_period``, not after the last)."""
        return self.reset and generation % self.reset_period == 0 and generation < self.n_generations

    def min_samples(self, problem: IdentificationProblem) -> int:
        """Each subset must hold more residuals than unknowns."""
        subsets = self.n_subsets if self.sequential else 1
        return subsets * (problem.n_params // 3 + 2)

    def _comparable(self, raw: FloatArray, subset: IntArray, reference: FloatArray) -> FloatArray:
        """Excess costs ``raw - c_subset(x_ref)`` (the subsets' noise energy cancels): (N,)."""
        return raw - reference[subset]

    # ------------------------------------------------------------------ search
    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        params = problem.parameters
        n, n_generations = self.n_particles, self.n_generations
        split = SubsetCosts(problem, self.n_subsets if self.sequential else 1, self.subset_kind)
        ranks = np.arange(n)
        best = Incumbent(problem, split, params.nominal)  # the reference of the excess costs

        unit, velocity = self._initial_swarm(rng, n, problem.n_params)
        best_unit = unit.copy()
        best_raw = np.full(n, np.inf)  # raw cost of the personal best on the subset it was measured on
        best_subset = np.zeros(n, dtype=np.intp)
        history: list[float] = []
        n_resets = 0
        recent: deque[Evaluations] = deque(maxlen=self._quadratic_window(split.n_subsets, problem.n_params))
        radius = math.inf  # the quadratic step's trust radius in the unit box
        for generation in range(1, n_generations + 1):
            assignment = (ranks + generation) % split.n_subsets
            raw = problem.cost_on_subsets(params.from_unit(unit), assignment, split.subsets)
            if self.quadratic:
                recent.append((unit.copy(), assignment, raw))
            better = self._comparable(raw, assignment, best.reference) < self._comparable(best_raw, best_subset, best.reference)
            best_unit[better], best_raw[better], best_subset[better] = unit[better], raw[better], assignment[better]

            moved_from = best.unit.copy()
            self._check_candidates(best, best_unit, best_raw, best_subset)
            if self.quadratic:
                radius = self._check_quadratic(best, recent, radius)
            history.append(best.cost)
            if generation == n_generations:
                break

            excess = self._comparable(best_raw, best_subset, best.reference)
            reset_now = self.resets_after(generation)
            neighbours = nearest(unit, self.neighbourhood_size(generation)) if (self.neighbourhood or reset_now) else None
            leaders = nearest_best(excess, neighbours) if self.neighbourhood and neighbours is not None else global_best(excess)
            weight = inertia_at(self.inertia, generation, n_generations)
            new_unit, velocity = self._move(rng, unit, velocity, best_unit, best_unit[leaders], weight)
            if reset_now and neighbours is not None:
                worst = self._reset(rng, unit, new_unit, velocity, best_unit, excess, leaders, neighbours)
                best_raw[worst] = np.inf
                n_resets += len(worst)
            unit = new_unit
            if self.n_follow and not np.array_equal(moved_from, best.unit):
                self._follow(rng, best, moved_from, unit, velocity, best_unit, best_raw, best_subset)

        # final: the incumbent against the neighbourhood bests, on the whole log
        excess = self._comparable(best_raw, best_subset, best.reference)
        final = nearest(unit, self.neighbourhood_size(n_generations)) if self.neighbourhood else None
        leaders = np.unique(nearest_best(excess, final) if final is not None else global_best(excess))
        finalists = [i for i in leaders if np.isfinite(best_raw[i]) and not np.array_equal(best_unit[i], best.unit)]
        best.check(
            best_unit[finalists].reshape(-1, problem.n_params),
            [best_raw[i : i + 1] if split.n_subsets == 1 else None for i in finalists],
        )
        history[-1] = best.cost
        return SearchResult(
            theta=params.from_unit(best.unit),
            cost_history=history,
            extra={
                "n_subsets_used": split.n_subsets,
                "n_whole_log_evaluations": best.n_evaluated,
                "n_finalists": len(finalists),
                "n_resets": n_resets,
                "final_pbest_std": np.std(params.from_unit(best_unit), axis=0).tolist(),
            },
        )

    def _check_candidates(self, best: Incumbent, best_unit: FloatArray, best_raw: FloatArray, best_subset: IntArray) -> None:
        """Whole-log checks of the lowest-excess personal best and of the consensus; updates ``best`` and ``best_raw``.

        Args:
            best: the incumbent (changed in place when a candidate beats it).
            best_unit: personal bests (N, k); best_raw: their raw costs (N,), changed in place for the
                checked one (its exact whole-log excess); best_subset: the subsets they were measured on (N,).
        """
        excess = self._comparable(best_raw, best_subset, best.reference)
        leader = int(np.argmin(excess))
        points: list[FloatArray] = []
        known: list[FloatArray | None] = []
        leader_new = not np.array_equal(best_unit[leader], best.unit)
        if leader_new:
            points.append(best_unit[leader])
            known.append(best_raw[leader : leader + 1] if best.split.n_subsets == 1 else None)  # K = 1: already exact
        if self.consensus:
            consensus = best_unit[np.argsort(excess, kind="stable")[: self.consensus_size]].mean(axis=0)
            if not np.array_equal(consensus, best.unit):
                points.append(consensus)
                known.append(None)
        whole = best.check(np.reshape(points, (-1, best_unit.shape[1])), known)
        if leader_new and not np.array_equal(best_unit[leader], best.unit):
            best_raw[leader] = best.reference[best_subset[leader]] + (whole[0] - best.cost)  # exact, not a lucky draw

    def _per_subset_fit(self, n_subsets: int, n_params: int) -> int:
        """Evaluations per subset that the quadratic step fits (``POINTS_PER_COEFFICIENT`` x its coefficients in all)."""
        return -(-POINTS_PER_COEFFICIENT * n_coefficients(n_params, n_subsets) // n_subsets)

    def _quadratic_window(self, n_subsets: int, n_params: int) -> int:
        """Generations of evaluations kept for the quadratic step: ``K`` x enough rounds for its points.

        Over ``K`` generations every subset gets ``N`` evaluations (each particle visits each subset
        once); without ``sequential`` (``K = 1``) a small swarm needs more than one generation.
        """
        return n_subsets * max(1, -(-self._per_subset_fit(n_subsets, n_params) // self.n_particles))

    def _check_quadratic(self, best: Incumbent, recent: deque[Evaluations], radius: float) -> float:
        """Whole-log check (counted) of the minimum of a quadratic fitted to the recent evaluations; may replace ``best``.

        ``recent``: the last generations' ``(unit (N, k), subset (N,), raw cost (N,))``
        (:meth:`_quadratic_window` of them). From each subset, the lowest-excess evaluations
        (:meth:`_per_subset_fit` of them) among the ``NEAREST_FACTOR`` x as many nearest the
        incumbent are fitted (:func:`estimators.quadratic_step.quadratic_step`, around the
        incumbent); nothing is evaluated when the fit gives no step or a zero one.

        ``radius``: the trust radius (unit box), the longest step to take; returns the next one:
        twice the length of the step taken if it lowered the cost, else half of it (at least
        ``MIN_TRUST_RADIUS``; the length before the box clips the step).
        """
        unit = np.concatenate([r[0] for r in recent])
        subset = np.concatenate([r[1] for r in recent])
        excess = self._comparable(np.concatenate([r[2] for r in recent]), subset, best.reference)
        per_subset = self._per_subset_fit(best.split.n_subsets, unit.shape[1])
        chosen = []
        for s in range(best.split.n_subsets):
            on = np.flatnonzero(subset == s)
            near = on[np.argsort(np.linalg.norm(unit[on] - best.unit, axis=1), kind="stable")[: NEAREST_FACTOR * per_subset]]
            chosen.append(near[np.argsort(excess[near], kind="stable")[:per_subset]])
        fitted = np.concatenate(chosen)
        step = quadratic_step(unit[fitted] - best.unit, subset[fitted], excess[fitted], best.split.weights)
        if step is None:
            return radius
        length = float(np.linalg.norm(step))
        taken = min(length, radius)  # the step's length within the trust radius, before the box clips it
        candidate = np.clip(best.unit + step * (taken / length if length > 0.0 else 0.0), 0.0, 1.0)
        if np.array_equal(candidate, best.unit):
            return radius
        before = best.cost
        best.check(candidate[None], [None])
        return 2.0 * taken if best.cost < before else max(MIN_TRUST_RADIUS, 0.5 * taken)

    def _follow(
        self,
        rng: np.random.Generator,
        best: Incumbent,
        moved_from: FloatArray,
        unit: FloatArray,
        velocity: FloatArray,
        best_unit: FloatArray,
        best_raw: FloatArray,
        best_subset: IntArray,
    ) -> None:
        """Move the ``n_follow`` worst particles to the incumbent, which moved this generation; all arrays in place.

        The worst (highest excess; a particle just reset has no cost yet and counts as worst) lands
        on the incumbent itself and takes it as its personal best, whose costs are known (excess 0;
        the particle's position is evaluated next generation like any other); the others
        at ``incumbent + xi``, ``xi ~ N(0, (d^2 / k) I)`` with ``d`` the length of the incumbent's move
        (``E|xi|^2 = d^2``), as new personal bests evaluated in the next generation. All restart at rest.

        Args:
            best: the incumbent; moved_from: its unit-box position before this generation's checks (k,).
            unit, velocity, best_unit: positions for the next generation, velocities, personal bests (N, k).
            best_raw, best_subset: personal bests' raw costs and subsets (N,).
        """
        excess = self._comparable(best_raw, best_subset, best.reference)
        order = np.argsort(-excess, kind="stable")[: self.n_follow]
        onto, around = order[0], order[1:]
        unit[onto] = best_unit[onto] = best.unit
        best_raw[onto] = best.reference[best_subset[onto]]
        centre = np.broadcast_to(best.unit, (len(around), unit.shape[1]))
        unit[around] = best_unit[around] = scattered(rng, centre, float(np.linalg.norm(best.unit - moved_from)))
        best_raw[around] = np.inf
        velocity[order] = 0.0

    def _reset(
        self,
        rng: np.random.Generator,
        unit: FloatArray,
        new_unit: FloatArray,
        velocity: FloatArray,
        best_unit: FloatArray,
        excess: FloatArray,
        leader: IntArray,
        neighbours: IntArray,
    ) -> IntArray:
        """Reset the worst ``n_reset`` particles in place (positions, velocities, personal bests); returns their indices.

        Args:
            unit: positions before this generation's move (N, k), for the local density.
            new_unit, velocity, best_unit: the swarm after the move, changed in place (N, k).
            excess: comparable personal-best costs (N,); leader: neighbourhood bests (N,);
            neighbours: (N, Nnb) nearest particles (itself included).
        """
        order = np.argsort(excess, kind="stable")
        worst, good = order[len(order) - self.n_reset :], order[: len(order) - self.n_reset]
        drawn = rng.choice(good, size=len(worst))
        gaps = np.linalg.norm(unit[neighbours[drawn]] - unit[drawn][:, None, :], axis=2)  # (R, Nnb), 0 for itself
        radius = gaps.sum(axis=1) / max(neighbours.shape[1] - 1, 1)
        new_unit[worst] = scattered(rng, best_unit[leader[drawn]], radius)
        velocity[worst] = 0.0
        best_unit[worst] = new_unit[worst]
        return worst
