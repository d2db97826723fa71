"""Costs of points on every subset of a split log, and the incumbent whose subset costs make them comparable.

The sequential evaluation of the improved swarm (:mod:`estimators.improved_pso`, eq. 19) evaluates
each particle on one subset of the log. The raw cost on subset ``s`` is
``c_s(x) = |f_s(x) - f_s(x*)|^2 / n_s - 2 e_s.(f_s(x) - f_s(x*)) / n_s + |e_s|^2 / n_s`` (``e`` the noise,
``n_s`` the subset's residual count). The last term, the subset's noise energy, differs between
subsets by ``~sqrt(2 / n_s)`` relative (a few %), while the differences that matter near the
optimum are ~1e-4 relative: ranking raw costs ranks particles by the subset they drew. So every
comparison uses the **excess cost** ``c_s(x) - c_s(x_ref)`` over a reference point ``x_ref``
evaluated on every subset (:class:`Incumbent`): the noise energy cancels exactly, and what remains
varies across subsets in proportion to ``|x - x_ref|``. The reference is the best point found so
far judged on the whole log; a point checked on the whole log (:meth:`Incumbent.check`) replaces it
when its whole-log cost is lower.

Costs are mean squared errors of the predicted base rate, (rad/s)^2; positions are in the unit box of the
problem's parameterisation.
"""

from __future__ import annotations

import numpy as np

from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray


class SubsetCosts:
    """The log split into subsets, and costs of points on all of them from one whole-log prediction.

    Attributes:
        subsets: K index arrays (``problem.subsets``).
        weights: (K,) fraction of the log's samples in each subset (the whole-log cost is ``weights @ costs``).
    """

    def __init__(self, problem: IdentificationProblem, n_subsets: int, kind: str) -> None:
        self.subsets = problem.subsets(n_subsets, kind)
        sizes = np.array([len(s) for s in self.subsets], dtype=float)
        self.weights = sizes / problem.n_samples
        self._mean = np.zeros((problem.n_samples, n_subsets))  # per-sample squared error -> per-subset mean
        for s, index in enumerate(self.subsets):
            self._mean[index, s] = 1.0 / (3.0 * sizes[s])

    @property
    def n_subsets(self) -> int:
        """K."""
        return len(self.subsets)

    def on_all(self, problem: IdentificationProblem, theta: FloatArray) -> FloatArray:
        """Costs (P, K) (rad/s)^2 of ``theta`` (P, k) on every subset; counted as P whole-log evaluations."""
        error = problem.predict(theta) - problem.measured
        return np.einsum("ptj,ptj->pt", error, error) @ self._mean


class Incumbent:
    """The best point so far judged on the whole log; its per-subset costs are the reference of the excess costs.

    Attributes:
        unit: its unit-box position (k,); cost: its whole-log cost (rad/s)^2;
        reference: its cost on each subset (K,); n_evaluated: whole-log evaluations spent on checks.
    """

    def __init__(self, problem: IdentificationProblem, split: SubsetCosts, theta: FloatArray) -> None:
        self.problem, self.split = problem, split
        self.unit = problem.parameters.to_unit(theta)
        self.reference = split.on_all(problem, np.asarray(theta, dtype=float)[None])[0]
        self.cost = float(split.weights @ self.reference)
        self.n_evaluated = 1

    def check(self, points: FloatArray, known: list[FloatArray | None]) -> FloatArray:
        """Whole-log costs (m,) of unit-box ``points`` (m, k); the lowest replaces the incumbent if it beats it.

        ``known[i]`` is point ``i``'s per-subset costs (K,) when already measured (not evaluated
        again), else ``None`` (evaluated on the whole log, counted).
        """
        costs = np.empty((len(points), self.split.n_subsets))
        todo = [i for i, c in enumerate(known) if c is None]
        for i, c in enumerate(known):
            if c is not None:
                costs[i] = c
        if todo:
            costs[todo] = self.split.on_all(self.problem, self.problem.parameters.from_unit(points[todo]))
            self.n_evaluated += len(todo)
        whole = costs @ self.split.weights
        if len(whole) and whole.min() < self.cost:
            j = int(np.argmin(whole))
            self.unit, self.cost, self.reference = points[j].copy(), float(whole[j]), costs[j].copy()
        return whole
