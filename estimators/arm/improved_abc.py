"""Artificial bee colonies: Karaboga's classic ABC (``abc``) and the source's improved ABC (``improved-abc``).

Both search the **unit box** ``u = (x - lower) / width`` of their search coordinates ``x``: the
problem's ``theta`` within its search range, or, for the physically consistent variant, the
log-Cholesky coordinates of :class:`~estimators.arm.consistency.PhysicalConsistency` (every candidate is a
physically consistent set of bodies; the cost is the problem's, of ``theta = K x_full``).

Classic ABC (Karaboga 2005; Karaboga and Akay 2009)
----------------------------------------------------
``SN = colony_size / 2`` food sources ``u_i``, uniform in the box, each with its cost ``f_i`` and a trial
counter. Every cycle:

* **employed bees**: one per source; the candidate changes one random coordinate ``d``,
  ``v_id = u_id + phi (u_id - u_jd)``, ``phi ~ U(-1, 1)``, ``j != i`` a random other source, clipped to
  the box; **greedy selection**: the candidate replaces the source if its cost is lower (trial counter
  reset), else the counter grows by one;
* **onlooker bees**: ``SN`` onlookers pick sources with probability proportional to the fitness
  ``1 / (1 + f_i)`` and search around them the same way;
* **scout**: the source with the largest trial counter, if above ``limit`` (default ``SN x D``), is
  abandoned and replaced by a uniform random one.

Batched evaluation: the bees of a phase are evaluated in one ``problem.cost`` call. Several onlookers
on one source are judged together: the best of them competes with the source, and the counter grows by
the number of them that failed. A cycle costs ``2 SN`` evaluations (plus one per scout); with
``max_evaluations`` the colony runs until that budget is spent (the last phase is cut short to fit
it exactly) instead of ``max_cycles`` cycles. The estimate is the best source; ``cost_history`` its
cost after every cycle.

Improved ABC
------------
The source (a patent, digest in ``shared/design/seeds-digest.md``) keeps the colony above and moves
bees with ``v_id = s_id + phi F_ij (s_id - s_jd)``, where ``F_ij`` is an "adaptive fitness step
coefficient" built from the two sources' fitness with a constant ``a > 0``; its formula is lost from
the text. :class:`ImprovedABC` defines it and adds what measurement on the 50-parameter arm problem of
``benchmarks/abc_ablation.py`` showed the colony needs. Each change is switchable; the defaults are the
measured best:

1. ``principal_axes`` (on): with probability ``principal_probability`` (0.3) a bee moves along one of
   the colony's principal axes instead of one coordinate: ``b`` a random right singular vector of the
   centred sources (the ``SN - 1`` informative ones), ``v = u_i + phi ((u_i - u_j) . b) b``. Inertial
   parameters are strongly correlated (the condition number of the unit-box Hessian is ~2e6 on the
   benchmark problem, which prints it): a one-coordinate step must stay inside the narrow conditional width of the
   cost's valley, while the colony's spread lines up with the valley, so steps along its axes are not
   limited by the correlation (the idea of eigenvector-based crossover, Guo and Yang 2015). The
   coordinate moves stay: the colony's axes only span its own affine hull. The probability was
   chosen by measurement on the former base parameters (0.1, 0.2, 0.3, 0.5, 0.7 at 50 000 evaluations:
   0.3 lowest error; not measured again).
2. ``scaled_fitness`` (on): onlookers choose with fitness ``1 / (1 + (f_i - min f) / (median f - min f))``
   instead of ``1 / (1 + f)``, which depends on the cost's unit and flattens to uniform selection once
   all costs are small against 1 (here near the optimum every classic fitness is ``~1 / (1 + noise^2)``).
3. ``adaptive_step`` (off; the patent's ``F_ij`` as defined here). With ``e_i = f_i - min f`` the excess
   cost of source ``i`` over the colony's best and ``eps = a x median(e)`` (``a = step_constant``, 0.1)::

       F_ij = 2 sqrt(e_i + eps) / (sqrt(e_i + eps) + sqrt(e_j + eps))      (in (0, 2), 1 for equal sources)

   multiplies the coordinate moves. Reason: near a minimum the cost is quadratic, so a source's
   distance to it grows as ``sqrt(e)``, while the classic step spans the distance between the two
   sources; ``F_ij`` rescales the step to the moving source's own distance (a good source searches
   finely, a poor one takes up to twice the classic step, towards and past its better partner);
   ``eps`` keeps the best source (``e = 0``) moving (large ``a``: ``F -> 1``, the classic step).
   Measured, it does **not** help on the arm problem, so it is off by default: on top of the changes
   above it ends at the same error at 200 000 evaluations but a larger one at 100 000 (1.05 against 0.98
   Cramér-Rao std, mean of 16 seeds: ``benchmarks/abc_ablation.py --seeds 16 --evaluations 100000``) and at
   50 000 (figures below); alone on the classic colony it lowers the error somewhat (2.6 against 3.4 at
   100 000). It does help on the 4-parameter nonlinear fuel problem of the free-floating
   robot (2000 evaluations, 12 seeds: median 2.6 chi-square units above the maximum-likelihood fit,
   worst 13, against 4.6 and 54 without it), where the colony collapses early and the finer steps of
   good sources pay. Other definitions tried on the arm did not help either (a fitness-rank ratio
   ``((1 + r_i) / (1 + r_j))^a`` with a = 0.5, 1, 2; a cost ratio; a success-rule step; a step growing
   with the trial counter; each on one or both move types).
4. ``gbest_guided`` (off): Zhu and Kwong's (2010) term ``+ psi (u_best,d - u_id)``,
   ``psi ~ U(0, gbest_weight)``, pulling every move towards the best source. It was slower than the
   default after the first few thousand evaluations on the base parameters of the synthetic arm's former
   pivoted QR (4.4 against 3.2 Cramér-Rao std at 50 000); on the current ones it is slightly ahead at
   50 000 (1.6 against 1.8, mean of 10 seeds) and slightly behind at 100 000 (1.03 against 0.98, 16 seeds);
   it stays off, no clear gain either way; see the figures below.

Measured (``benchmarks/abc_ablation.py``, 10 seeds; RMS error of the 50 base parameters in Cramér-Rao
std, mean; WLS 0.95): at 50 000 evaluations classic ABC 11.2, improved ABC 1.8, without the principal
axes 12.3, without the scaled fitness 3.9, with ``F_ij`` 3.6, with gbest guidance 1.6; at 200 000 the
improved ABC reaches the WLS error (0.95, held-out torque error 1.007 x the noise like WLS) with or
without the optional changes, and the classic colony is close (1.40, held-out 1.019 x the noise). On the
synthetic arm's former base parameters (its own pivoted QR), which made one-coordinate moves much harder,
the classic colony was still at 26.7 after 200 000 evaluations (the benchmark's docstring says more).

Physically consistent variant: ``consistent=True`` (either class) searches the log-Cholesky coordinates
of the problem's :class:`~estimators.arm.consistency.PhysicalConsistency` (the box from
:meth:`~estimators.arm.consistency.PhysicalConsistency.search_box`); the estimate's ``extra`` holds the
consistent full parameters (``full_params``) and the estimate reports each link's consistency. Its ``polish``
leaves the box and the log-Cholesky coordinates for a trust-region Newton descent in factor coordinates (``J = Y Y^T``
per link; :mod:`estimators.arm.consistent_polish`, deterministic),
where every local minimum is the global consistent one: with it the colony ends at the cost of the convex ``sdp``
estimator (:mod:`estimators.arm.sdp`), which every consistent fit reports its excess over.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from estimators.arm.consistent_polish import polished_consistent
from estimators.arm.linear_problem import LinearIdentificationProblem
from estimators.arm.sdp import excess_over_optimum
from estimators.base import Estimator, SearchResult
from estimators.estimate import Estimate
from estimators.options import check_bool, check_float, check_int
from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

IntArray = NDArray[np.intp]


@dataclass
class SearchSpace:
    """Coordinates a colony searches: a box and the map from unit-box points to the problem's ``theta``.

    Attributes:
        lower, upper: (D,) the box of the search coordinates.
        to_theta: maps search coordinates (P, D) to ``theta`` (P, k).
        to_full: maps search coordinates (P, D) to full parameters (P, n_full) for the estimate (or ``None``).
    """

    lower: FloatArray
    upper: FloatArray
    to_theta: Callable[[FloatArray], FloatArray]
    to_full: Callable[[FloatArray], FloatArray] | None = None

    @property
    def dimension(self) -> int:
        """D."""
        return len(self.lower)

    def point(self, unit: FloatArray) -> FloatArray:
        """Search coordinates (..., D) of unit-box points (..., D)."""
        return self.lower + unit * (self.upper - self.lower)

    def theta(self, unit: FloatArray) -> FloatArray:
        """``theta`` (P, k) of unit-box points (P, D)."""
        return self.to_theta(self.point(np.atleast_2d(unit)))


def search_space(problem: Any, consistent: bool) -> SearchSpace:
    """The problem's own box (``theta`` itself), or its physically consistent log-Cholesky box."""
    params = problem.parameters
    if not consistent:
        return SearchSpace(params.lower, params.upper, lambda x: x)
    consistency = getattr(problem, "consistency", None)
    if consistency is None:
        raise SpaceIdInputError(
            "consistent=True: the problem has no PhysicalConsistency (pass consistency= to LinearIdentificationProblem)"
        )
    lower, upper = consistency.search_box()

    def to_theta(x: FloatArray) -> FloatArray:
        return consistency.theta_from_full(consistency.full_from_search(x))

    return SearchSpace(lower, upper, to_theta, consistency.full_from_search)


def _polished(problem: Any, space: SearchSpace, start: FloatArray) -> FloatArray:
    """Search coordinates (D,) after a bounded local least-squares descent from ``start`` (D,) on the problem's root cost.

    The Jacobian is ``A d theta / d x`` with ``A`` of :meth:`~estimators.arm.linear_problem.LinearIdentificationProblem.root_form`
    and ``d theta / d x`` by forward differences in one batched map (D + 1 points); at most ``POLISH_ITERATIONS`` steps.
    """
    if not isinstance(problem, LinearIdentificationProblem):
        raise SpaceIdInputError(
            "polish=True: needs a linear problem (LinearIdentificationProblem); use 'hybrid' for nonlinear ones"
        )
    matrix, _ = problem.root_form()

    def jacobian(x: FloatArray) -> FloatArray:
        step = 1e-7 * np.maximum(1.0, np.abs(x))
        step = np.where(x + step > space.upper, -step, step)  # stay inside the box
        theta = space.to_theta(np.vstack((x, x + np.diag(step))))
        problem.n_model_samples += len(x) * problem.n_samples
        return matrix @ ((theta[1:] - theta[0]) / step[:, None]).T

    result = least_squares(
        lambda x: problem.root_cost(space.to_theta(x[None])[0]),
        np.clip(start, space.lower, space.upper),
        jac=jacobian,
        bounds=(space.lower, space.upper),
        x_scale="jac",
        method="trf",
        max_nfev=POLISH_ITERATIONS,
    )
    return np.asarray(result.x, dtype=float)


#: the most least-squares steps of ``polish`` in the search box (``consistent=False``)
POLISH_ITERATIONS = 100


@dataclass
class Colony:
    """The food sources of a colony and their bookkeeping.

    Attributes:
        unit: (SN, D) source positions in the unit box; cost: (SN,) their costs; trial: (SN,) failed trials since
        the last improvement; axes: (D, SN - 1) principal axes of the sources (or ``None``).
    """

    unit: FloatArray
    cost: FloatArray
    trial: IntArray
    axes: FloatArray | None = None

    @property
    def size(self) -> int:
        """SN."""
        return len(self.cost)


class ArtificialBeeColony(Estimator):
    """Karaboga's classic artificial bee colony (module docstring).

    Args:
        colony_size: bees (employed + onlookers), even, >= 4; ``SN = colony_size / 2`` food sources (default 40).
        limit: failed trials before a source is abandoned to a scout; ``None`` (default) is ``SN x D``.
        max_cycles: cycles to run (default 5000: 200 000 evaluations with the default colony, what the improved
            colony needs to reach the WLS error on the 50-parameter arm problem); replaced by ``max_evaluations``.
        max_evaluations: budget in whole-objective evaluations (>= SN, the initial colony).
        consistent: search the problem's physically consistent log-Cholesky coordinates (default False).
        polish: after the colony, a local descent from the best source (linear problems only), its evaluations counted
            in the budget's total but not limited by it (default False). Without ``consistent``: least squares in the
            search box (``scipy.optimize.least_squares``, trust region reflective, on the problem's
            :meth:`~estimators.arm.linear_problem.LinearIdentificationProblem.root_cost`). With ``consistent``: a Newton
            descent over every consistent parameter set, not only the box
            (:func:`~estimators.arm.consistent_polish.polished_consistent`), which ends at
            the global consistent optimum the ``sdp`` estimator computes.
        seed: the generator's seed.

    With ``consistent=True`` on a linear problem the estimate also reports its cost against the convex consistent
    optimum of the same cost (:func:`~estimators.arm.sdp.excess_over_optimum`, solved after the timed fit):
    ``extra["sdp_cost"]`` and ``extra["cost_excess_over_sdp"]`` (relative).
    """

    name = "abc"

    def __init__(
        self,
        *,
        colony_size: int = 40,
        limit: int | None = None,
        max_cycles: int = 5000,
        max_evaluations: float | None = None,
        consistent: bool = False,
        polish: bool = False,
        seed: int | None = 0,
    ) -> None:
        super().__init__(seed=seed)
        self.polish = check_bool("polish", polish)
        self.colony_size = check_int("colony_size", colony_size, 4)
        if self.colony_size % 2:
            raise SpaceIdInputError(f"colony_size: expected an even number (half employed, half onlookers), got {colony_size}")
        self.limit = None if limit is None else check_int("limit", limit, 1)
        self.max_cycles = check_int("max_cycles", max_cycles, 1)
        if max_evaluations is not None:
            check_float("max_evaluations", max_evaluations, self.colony_size // 2, np.inf)
        self.max_evaluations = max_evaluations
        self.consistent = check_bool("consistent", consistent)

    def min_samples(self, problem: Any) -> int:
        """More rows than unknowns."""
        return problem.n_params + 1

    def fit_problem(self, problem: Any, _started: float | None = None) -> Estimate:
        """:meth:`Estimator.fit_problem`; a consistent fit of a linear problem adds its excess over the ``sdp`` optimum."""
        estimate = super().fit_problem(problem, _started)
        if self.consistent and isinstance(problem, LinearIdentificationProblem) and problem.consistency is not None:
            estimate.extra.update(excess_over_optimum(problem, estimate.cost))
        return estimate

    # ------------------------------------------------------------------ the moves (overridden by the improved ABC)
    def _prepare_cycle(self, colony: Colony) -> None:
        """Per-cycle state the moves need (none for the classic colony)."""

    def _fitness(self, cost: FloatArray) -> FloatArray:
        """Onlookers' selection weights (SN,): the classic ``1 / (1 + f)``."""
        return 1.0 / (1.0 + cost)

    def _candidates(self, colony: Colony, sources: IntArray, rng: np.random.Generator) -> FloatArray:
        """One candidate (m, D) per bee on ``sources`` (m,): one coordinate moved, ``v_id = u_id + phi (u_id - u_jd)``."""
        m, dim = len(sources), colony.unit.shape[1]
        partner = (sources + rng.integers(1, colony.size, m)) % colony.size  # uniform over the other sources
        phi = rng.uniform(-1.0, 1.0, m)
        axis = rng.integers(0, dim, m)
        rows = np.arange(m)
        out = colony.unit[sources].copy()
        here = out[rows, axis]
        out[rows, axis] = here + phi * (here - colony.unit[partner, axis])
        return np.clip(out, 0.0, 1.0, out=out)

    # ------------------------------------------------------------------ the colony
    def _search(self, problem: LinearIdentificationProblem | IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        space = search_space(problem, self.consistent)
        n_sources = self.colony_size // 2
        limit = self.limit if self.limit is not None else n_sources * space.dimension
        budget = np.inf if self.max_evaluations is None else float(self.max_evaluations)
        max_cycles = self.max_cycles if self.max_evaluations is None else np.iinfo(np.int64).max

        def remaining() -> int:
            return int(np.floor(budget - problem.n_evaluations + 1e-9)) if np.isfinite(budget) else 2**62

        unit = rng.random((n_sources, space.dimension))
        colony = Colony(unit, problem.cost(space.theta(unit)), np.zeros(n_sources, dtype=np.intp))
        history: list[float] = []
        n_scouts = 0
        cycle = 0
        while cycle < max_cycles and remaining() > 0:
            cycle += 1
            self._prepare_cycle(colony)
            employed = np.arange(min(n_sources, remaining()))
            self._greedy(problem, space, colony, employed, self._candidates(colony, employed, rng))
            n_onlookers = min(n_sources, remaining())
            if n_onlookers > 0:
                weight = self._fitness(colony.cost)
                onlookers = rng.choice(n_sources, n_onlookers, p=weight / weight.sum())
                self._greedy(problem, space, colony, onlookers, self._candidates(colony, onlookers, rng))
            worst = int(np.argmax(colony.trial))
            if colony.trial[worst] > limit and remaining() > 0:
                colony.unit[worst] = rng.random(space.dimension)
                colony.cost[worst] = problem.cost(space.theta(colony.unit[worst]))[0]
                colony.trial[worst] = 0
                n_scouts += 1
            history.append(float(colony.cost.min()))
        best = int(np.argmin(colony.cost))
        extra: dict[str, Any] = {"n_cycles_run": cycle, "n_scouts": n_scouts, "final_cost_spread": float(np.ptp(colony.cost))}
        x_best = space.point(colony.unit[best])
        theta = space.to_theta(x_best[None])[0]
        full = None if space.to_full is None else space.to_full(x_best[None])[0]
        if self.polish:
            extra["colony_cost"] = history[-1] if history else float(colony.cost[best])
            if self.consistent:
                full, facts = polished_consistent(problem, problem.consistency, x_best)
                theta = problem.consistency.theta_from_full(full)
                extra.update(facts)
            else:
                theta = space.to_theta(_polished(problem, space, x_best)[None])[0]
            history.append(float(problem.cost(theta, count=False)[0]))
        if full is not None:
            extra["full_params"] = full.tolist()
        return SearchResult(theta=theta, cost_history=history, extra=extra)

    @staticmethod
    def _greedy(problem: Any, space: SearchSpace, colony: Colony, sources: IntArray, candidates: FloatArray) -> None:
        """Greedy selection: per source the best of its candidates replaces it if better (counter reset), else the
        counter grows by the number of its candidates. All candidates (m, D) in one ``problem.cost`` call."""
        if len(sources) == 0:
            return
        cost = problem.cost(space.theta(candidates))
        order = np.lexsort((cost, sources))  # by source, best candidate first
        first = np.ones(len(order), dtype=bool)
        first[1:] = sources[order[1:]] != sources[order[:-1]]
        best = order[first]
        source = sources[best]
        better = cost[best] < colony.cost[source]
        colony.trial += np.bincount(sources, minlength=colony.size)
        improved = source[better]
        colony.unit[improved] = candidates[best[better]]
        colony.cost[improved] = cost[best[better]]
        colony.trial[improved] = 0


class ImprovedABC(ArtificialBeeColony):
    """The improved ABC (module docstring): principal-axis moves, scaled fitness; optional ``F_ij``, gbest guidance.

    Args:
        adaptive_step: multiply coordinate moves by the patent's ``F_ij`` (default False: measured no gain);
            ``step_constant``: its ``a`` > 0 (default 0.1).
        principal_axes: move along the colony's principal axes with probability ``principal_probability``
            (default True, 0.3).
        scaled_fitness: onlookers' scale-free fitness (default True).
        gbest_guided: Zhu and Kwong's pull towards the best source (default False); ``gbest_weight``: its ``C`` (1.5).
        colony_size, limit, max_cycles, max_evaluations, consistent, polish, seed: as :class:`ArtificialBeeColony`.
    """

    name = "improved-abc"

    def __init__(
        self,
        *,
        adaptive_step: bool = False,
        step_constant: float = 0.1,
        principal_axes: bool = True,
        principal_probability: float = 0.3,
        scaled_fitness: bool = True,
        gbest_guided: bool = False,
        gbest_weight: float = 1.5,
        colony_size: int = 40,
        limit: int | None = None,
        max_cycles: int = 5000,
        max_evaluations: float | None = None,
        consistent: bool = False,
        polish: bool = False,
        seed: int | None = 0,
    ) -> None:
        super().__init__(
            colony_size=colony_size,
            limit=limit,
            max_cycles=max_cycles,
            max_evaluations=max_evaluations,
            consistent=consistent,
            polish=polish,
            seed=seed,
        )
        self.adaptive_step = check_bool("adaptive_step", adaptive_step)
        self.step_constant = check_float("step_constant", step_constant, 0.0, np.inf, low_open=True)
        self.principal_axes = check_bool("principal_axes", principal_axes)
        self.principal_probability = check_float("principal_probability", principal_probability, 0.0, 1.0)
        self.scaled_fitness = check_bool("scaled_fitness", scaled_fitness)
        self.gbest_guided = check_bool("gbest_guided", gbest_guided)
        self.gbest_weight = check_float("gbest_weight", gbest_weight, 0.0, 4.0)

    def _prepare_cycle(self, colony: Colony) -> None:
        """The colony's principal axes (D, SN - 1): right singular vectors of the centred sources."""
        if self.principal_axes and self.principal_probability > 0.0:
            centred = colony.unit - colony.unit.mean(axis=0)
            colony.axes = np.linalg.svd(centred, full_matrices=False)[2][: colony.size - 1].T

    def _fitness(self, cost: FloatArray) -> FloatArray:
        """Scale-free ``1 / (1 + (f - min f) / (median f - min f))`` when ``scaled_fitness``, else the classic."""
        if not self.scaled_fitness:
            return super()._fitness(cost)
        excess = cost - cost.min()
        scale = float(np.median(excess))
        return 1.0 / (1.0 + excess / scale) if scale > 0.0 else np.ones_like(cost)

    def step_coefficient(self, cost: FloatArray, sources: IntArray, partners: IntArray) -> FloatArray:
        """``F_ij`` (m,) for bees on ``sources`` (m,) with ``partners`` (m,), from the colony's costs (SN,) (module docstring)."""
        excess = cost - cost.min()
        floor = self.step_constant * float(np.median(excess))
        if floor <= 0.0:  # all sources equally good: the classic step
            return np.ones(len(sources))
        root_i, root_j = np.sqrt(excess[sources] + floor), np.sqrt(excess[partners] + floor)
        return 2.0 * root_i / (root_i + root_j)

    def _candidates(self, colony: Colony, sources: IntArray, rng: np.random.Generator) -> FloatArray:
        m, dim = len(sources), colony.unit.shape[1]
        partner = (sources + rng.integers(1, colony.size, m)) % colony.size
        phi = rng.uniform(-1.0, 1.0, m)
        here = colony.unit[sources]
        difference = here - colony.unit[partner]
        pull = colony.unit[np.argmin(colony.cost)] - here
        psi = rng.uniform(0.0, self.gbest_weight, m) if self.gbest_guided else np.zeros(m)
        axes = colony.axes if self.principal_axes else None
        along_axis = rng.random(m) < self.principal_probability if axes is not None else np.zeros(m, dtype=bool)
        out = here.copy()
        # coordinate moves: v_id = u_id + phi F_ij (u_id - u_jd) [+ psi (best_d - u_id)]
        coord = np.flatnonzero(~along_axis)
        axis = rng.integers(0, dim, len(coord))
        factor = self.step_coefficient(colony.cost, sources[coord], partner[coord]) if self.adaptive_step else 1.0
        out[coord, axis] += phi[coord] * factor * difference[coord, axis] + psi[coord] * pull[coord, axis]
        # principal-axis moves: v = u_i + (phi (u_i - u_j) . b + psi (best - u_i) . b) b
        moved = np.flatnonzero(along_axis)
        if axes is not None and len(moved):
            b = axes[:, rng.integers(0, axes.shape[1], len(moved))].T  # (m', D)
            step = phi[moved] * np.einsum("pd,pd->p", difference[moved], b) + psi[moved] * np.einsum("pd,pd->p", pull[moved], b)
            out[moved] += step[:, None] * b
        return np.clip(out, 0.0, 1.0, out=out)
