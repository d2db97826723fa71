"""The streaming interface of an estimator: a tracker that takes the samples of a log one at a time.

An estimator that can also run sample by sample (the unscented Kalman filter, :class:`~estimators.ukf.UnscentedKalman`)
has ``tracker(problem)``, which returns a :class:`SampleTracker` at its initial state on ``problem``. The tracker
assimilates sample ``i`` of the problem it is bound to (``update(i)``), lets its parameter random walk run over a
time without samples (``advance(gap_s)``), continues on another problem of the same unknowns (``bind``: the next
window, or a log of the newest samples only) and reports its running estimate and covariance (``estimate()``).

:func:`is_streaming` tells such an estimator apart; :mod:`spaceid_gym.envs.estimation` uses it to put the running
estimate in each step's ``info``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray


@runtime_checkable
class SampleTracker(Protocol):
    """A running estimate updated sample by sample (see the module docstring)."""

    def bind(self, problem: IdentificationProblem) -> None:
        """Continue on ``problem`` (the same unknowns), keeping the state and covariance."""
        ...

    def advance(self, gap_s: float) -> None:
        """Let the parameters' random walk run ``gap_s`` seconds without a sample."""
        ...

    def update(self, sample_index: int, weight: float = 1.0) -> FloatArray:
        """Assimilate sample ``sample_index`` of the bound problem; returns the innovation."""
        ...

    def estimate(self) -> tuple[FloatArray, FloatArray]:
        """The running estimate ``theta`` (k,) and its covariance (k, k), in the parameterisation's units."""
        ...


@runtime_checkable
class StreamingEstimator(Protocol):
    """An estimator that can also run sample by sample."""

    def tracker(self, problem: IdentificationProblem) -> SampleTracker:
        """A tracker at the estimator's initial state on ``problem``."""
        ...


def is_streaming(estimator: Any) -> bool:
    """Whether ``estimator`` has the streaming interface (``tracker(problem)``)."""
    return isinstance(estimator, StreamingEstimator)
