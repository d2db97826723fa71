"""Registers the shipped estimators under their names (imported lazily by :mod:`estimators.registry`)."""

from __future__ import annotations

from collections.abc import Callable

from estimators.base import Estimator


def builtin_estimators() -> dict[str, Callable[..., Estimator]]:
    """The shipped estimators by registry name."""
    from estimators.abc import ArtificialBeeColony, ImprovedABC
    from estimators.hybrid import HybridEstimator
    from estimators.improved_pso import ImprovedPSO
    from estimators.least_squares import LevenbergMarquardt
    from estimators.linear_ls import OrdinaryLeastSquares, WeightedLeastSquares
    from estimators.neural import NeuralNetworkEstimator
    from estimators.pso import ParticleSwarm
    from estimators.reference import CMAES, DifferentialEvolution, PyswarmsLocalBest
    from estimators.sdp import SemidefiniteLeastSquares
    from estimators.ukf import UnscentedKalman

    return {
        "pso": ParticleSwarm,
        "improved-pso": ImprovedPSO,
        "lm": LevenbergMarquardt,
        "hybrid": HybridEstimator,
        "nn": NeuralNetworkEstimator,
        "de": DifferentialEvolution,
        "cma-es": CMAES,
        "pyswarms-local": PyswarmsLocalBest,
        "ols": OrdinaryLeastSquares,
        "wls": WeightedLeastSquares,
        "sdp": SemidefiniteLeastSquares,
        "abc": ArtificialBeeColony,
        "improved-abc": ImprovedABC,
        "ukf": UnscentedKalman,
    }
