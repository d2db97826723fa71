"""Registers the shipped estimators under their names (imported by the package :mod:`estimators` itself)."""

from __future__ import annotations

from collections.abc import Callable

from estimators.arm.improved_abc import ArtificialBeeColony, ImprovedABC
from estimators.arm.linear_ls import OrdinaryLeastSquares, WeightedLeastSquares
from estimators.arm.sdp import SemidefiniteLeastSquares
from estimators.base import Estimator
from estimators.hybrid import HybridEstimator
from estimators.improved_pso import ImprovedPSO
from estimators.least_squares import LevenbergMarquardt
from estimators.neural import NeuralNetworkEstimator
from estimators.pso import ParticleSwarm
from estimators.reference import CMAES, DifferentialEvolution, PyswarmsLocalBest
from estimators.registry import register_estimator
from estimators.ukf import UnscentedKalman

#: the shipped estimators by registry name
BUILTIN_ESTIMATORS: dict[str, Callable[..., Estimator]] = {
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


def builtin_estimators() -> dict[str, Callable[..., Estimator]]:
    """The shipped estimators by registry name (a copy)."""
    return dict(BUILTIN_ESTIMATORS)


for _name, _factory in BUILTIN_ESTIMATORS.items():
    register_estimator(_name, _factory)
