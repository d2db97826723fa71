"""Gauss-Newton / Levenberg-Marquardt on the residuals: the maximum-likelihood estimate from a good start.

:class:`LevenbergMarquardt` (registry name ``lm``) minimises ``sum(residuals^2)``, the same objective as
``problem.cost`` up to the factor ``3T``, with :func:`scipy.optimize.least_squares`, the analytic Jacobian
(:meth:`~estimators.problem.IdentificationProblem.jacobian`) and ``x_scale`` = the parameters' typical sizes
(``Parameterisation.scale``: the search widths, and an effect's size expected in flight where its search range is far
wider), so a trust region of 1 spans the box, or an effect's expected size, in every direction. For white Gaussian gyro noise its minimum is
the maximum-likelihood estimate, whose covariance reaches the Cramér-Rao bound. It converges in ~10
Jacobians from anywhere in the basin of the global minimum, but it is a local method: the hybrid estimator
(:mod:`estimators.hybrid`) gives it a start from a global search, through :meth:`LeastSquaresPolish.polish`.

Cost: a residual evaluation is one whole-log evaluation (T model samples) and a Jacobian k of them; both are
counted in the problem's budget counter by the problem itself.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from estimators.base import Estimator, SearchResult
from estimators.options import finite_vector, positive_option
from estimators.parameters import Parameterisation
from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: scipy's methods: ``trf`` (bounded trust-region reflective), ``dogbox`` (bounded), ``lm`` (MINPACK, unbounded)
METHODS = ("trf", "dogbox", "lm")

#: the default start: the nominal, with every coordinate closer than this fraction of the width to a bound
#: moved to that distance (the fuel nominal mdf = 0 sits on its bound, where the tank position has no effect)
INTERIOR_FRACTION = 0.1


def interior_start(params: Parameterisation) -> FloatArray:
    """The nominal (k,) with every coordinate moved at least :data:`INTERIOR_FRACTION` of its width inside the box."""
    margin = INTERIOR_FRACTION * params.width
    return np.clip(params.nominal, params.lower + margin, params.upper - margin)


class _IterationLimit(Exception):
    """Raised from the Jacobian callback to stop scipy after ``max_iterations`` accepted steps."""


class _Trace:
    """Residual and Jacobian callbacks for :func:`least_squares` that record the cost after every accepted step.

    scipy evaluates the Jacobian once at the start and then once after every accepted step, at the
    new iterate (all three methods), so each Jacobian call after the first marks one iteration. The
    whole-log cost there is ``mean(r^2)`` of the residual just computed at that point (no extra
    evaluation). Reaching ``max_iterations`` raises :class:`_IterationLimit` before the Jacobian is
    computed; the last iterate is kept in ``x``.

    scipy sees the residuals divided by the norm of the measured rates, ``r / ||measured||``: its
    cost is then half the fraction of the gyro signal's energy left unexplained, independent of the
    log's length and of the units of the rates, and so is ``gtol``, an absolute test on its gradient.
    """

    def __init__(self, problem: IdentificationProblem, max_iterations: int) -> None:
        self.problem = problem
        self.max_iterations = max_iterations
        self.nfev = 0
        self.njev = 0
        self.history: list[float] = []
        self.x: FloatArray | None = None  # the last iterate recorded
        self._last: tuple[FloatArray, FloatArray] | None = None  # (x, residuals) of the last residual call
        signal = float(np.linalg.norm(problem.measured))
        self.scale = 1.0 / signal if signal > 0.0 else 1.0

    def residuals(self, x: FloatArray) -> FloatArray:
        """``(predicted - measured) / ||measured||`` (3T,) at ``x`` (k,), counted."""
        self.nfev += 1
        r = self.problem.residuals(x)
        self._last = (x.copy(), r)
        return r * self.scale

    def jacobian(self, x: FloatArray) -> FloatArray:
        """``d residuals / d x`` (3T, k) at ``x`` (k,), scaled as the residuals, counted; records the iterate first."""
        if self.njev > 0:  # every Jacobian after the first follows an accepted step
            self.record(x)
            if len(self.history) >= self.max_iterations:
                raise _IterationLimit
        self.x = np.array(x, dtype=float)
        self.njev += 1
        return self.problem.jacobian(x) * self.scale

    def record(self, x: FloatArray) -> None:
        """Make ``x`` (k,) the current iterate and append its whole-log cost (rad/s)^2."""
        if self._last is not None and np.array_equal(self._last[0], x):
            r = self._last[1]
        else:
            r = self.problem.residuals(x, count=False)
        self.history.append(float(r @ r) / r.size)
        self.x = np.array(x, dtype=float)

    def finish(self, x: FloatArray) -> None:
        """Record the returned point unless it is the last recorded iterate (MINPACK stops without a last Jacobian).

        A run without an accepted step still gets one entry, the cost at the start.
        """
        if not self.history or self.x is None or not np.array_equal(self.x, x):
            self.record(x)


class LeastSquaresPolish(Estimator):
    """Options and the :meth:`polish` routine shared by ``lm`` and ``hybrid`` (not registered itself).

    Args:
        method: ``"trf"`` (default; trust-region reflective, honours the bounds), ``"dogbox"`` (bounded)
            or ``"lm"`` (MINPACK Levenberg-Marquardt, unbounded: the result may leave the search box).
        ftol: stop when a step reduces the cost by less than ``ftol`` times the cost (relative).
        xtol: stop when the step is shorter than ``xtol * (xtol + |x|)`` (scipy's test, parameter units).
        gtol: scipy's first-order optimality test, on the gradient of the residuals relative to the
            measured signal (``r / ||measured||``), so that it does not depend on the log's length.
            With the defaults the three methods agree to 1e-4 Cramér-Rao std on a 60 s log.
        max_iterations: at most this many accepted steps (each costs one Jacobian, k whole-log evaluations,
            plus at least one residual evaluation).
        seed: unused (the method is deterministic); kept for the estimator protocol.
    """

    name: ClassVar[str] = "least-squares"

    def __init__(
        self,
        *,
        method: str = "trf",
        ftol: float = 1e-10,
        xtol: float = 1e-10,
        gtol: float = 1e-10,
        max_iterations: int = 100,
        seed: int | None = 0,
    ) -> None:
        super().__init__(seed=seed)
        if method not in METHODS:
            raise SpaceIdInputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
        self.method = method
        self.ftol = positive_option("ftol", ftol)
        self.xtol = positive_option("xtol", xtol)
        self.gtol = positive_option("gtol", gtol)
        self.max_iterations = positive_option("max_iterations", max_iterations, integer=True)

    def polish(self, problem: IdentificationProblem, start: ArrayLike) -> SearchResult:
        """Run the least-squares solver from ``start`` (k,) to the nearest minimum.

        For the bounded methods ``start`` is clipped into the search box. Returns the minimum, the
        whole-log cost after every accepted step, and in ``extra``: ``nfev``/``njev`` (residual and
        Jacobian evaluations), ``iterations`` and scipy's ``status`` and ``message`` (``-3``: stopped
        by ``max_iterations``).
        """
        params = problem.parameters
        x0 = finite_vector("start", start, params.names)
        bounded = self.method != "lm"
        if bounded:
            x0 = np.clip(x0, params.lower, params.upper)
        trace = _Trace(problem, self.max_iterations)
        # a tall, thin Jacobian (3T x k): BLAS threads only slow its SVD down, several times on a busy machine
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                result = least_squares(
                    trace.residuals,
                    x0,
                    jac=trace.jacobian,
                    bounds=(params.lower, params.upper) if bounded else (-np.inf, np.inf),
                    method=self.method,
                    x_scale=params.scale,
                    ftol=self.ftol,
                    xtol=self.xtol,
                    gtol=self.gtol,
                )
                x, status, message = np.asarray(result.x, dtype=float), int(result.status), str(result.message)
            except _IterationLimit:
                assert trace.x is not None
                x, status, message = trace.x, -3, f"stopped after max_iterations={self.max_iterations} accepted steps"
        trace.finish(x)
        extra: dict[str, Any] = {
            "method": self.method,
            "nfev": trace.nfev,
            "njev": trace.njev,
            "iterations": len(trace.history),
            "status": status,
            "message": message,
        }
        return SearchResult(theta=x, cost_history=trace.history, extra=extra)


class LevenbergMarquardt(LeastSquaresPolish):
    """Least squares on the gyro residuals from one start (registry name ``lm``); see the module docstring.

    Args:
        x0: the start (k,); ``None`` (default): the nominal moved :data:`INTERIOR_FRACTION` of the width
            away from any bound it sits on or near (for ``fuel``: mdf = 16.5 kg, tank at the full-tank CoM).
        **options: ``method``, ``ftol``, ``xtol``, ``gtol``, ``max_iterations``, ``seed``
            (see :class:`LeastSquaresPolish`).
    """

    name: ClassVar[str] = "lm"

    def __init__(self, *, x0: ArrayLike | None = None, **options: Any) -> None:
        super().__init__(**options)
        self.x0 = None if x0 is None else finite_vector("x0", x0)

    def start(self, problem: IdentificationProblem) -> FloatArray:
        """The start (k,) used on ``problem``: ``x0`` or the nominal moved inside the box (see ``x0``)."""
        params = problem.parameters
        if self.x0 is None:
            return interior_start(params)
        finite_vector("x0", self.x0, params.names)
        if self.method != "lm" and not np.all((params.lower <= self.x0) & (self.x0 <= params.upper)):
            raise SpaceIdInputError(
                f"x0: {self.x0.tolist()} is outside the search box [{params.lower.tolist()}, {params.upper.tolist()}] "
                f"(method {self.method!r} honours the bounds)"
            )
        return self.x0.copy()

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        return self.polish(problem, self.start(problem))
