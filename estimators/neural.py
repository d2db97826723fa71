"""The neural-network estimator ``nn``: the paper's comparison, a network trained on simulated logs.

The paper compares its PSO with a back-propagation network (two hidden layers of 35 and 45 tanh
units) trained on simulated samples to map features of a log to the parameters. This estimator
builds that network per log, from the identification model itself:

1. **Training set.** ``n_train`` parameter vectors are drawn uniformly in the parameterisation's
   bounds and the base rate they predict over *this log's* joint trajectory is computed with
   :meth:`~estimators.problem.IdentificationProblem.predict` (counted in the budget: ``n_train``
   whole-log evaluations; done in batches of at most :data:`MAX_PREDICT_SAMPLES` particle-samples
   so long logs do not need gigabytes, a single call on a 60 s / 50 Hz log with the defaults).
2. **Features.** The base rate averaged over ``n_windows`` equal time windows, per axis:
   ``3 x n_windows`` numbers (rad/s), standardised with the training set's mean and std. With
   20 windows they keep ~90 % of the log's Fisher information about the fuel parameters (the
   Cramér-Rao std of the window means is 1.1 x that of the full log; 1.4 x with 10, 1.03 x with 40).
3. **Noise.** Simulated gyro noise of the log's level (``noise_std_rad_s``; default the model's
   ``noise_std_rad_s``, else the default gyro of :class:`~spaceid_gym.sim.sensors.SensorModel` at
   the log's sample period) is added to the training features. White Gaussian noise of std
   ``sigma`` per sample averages to white Gaussian noise of std ``sigma / sqrt(n)`` on the mean
   of ``n`` samples, so it is drawn at that level on the window means directly (same
   distribution, ``3 x n_windows`` draws per vector instead of ``3 T``).
4. **Targets.** ``theta`` scaled to the unit box, ``u = (theta - lower) / width``; the output is
   clipped to ``[0, 1]`` and mapped back, so the estimate is always within the bounds.
5. **Network.** scikit-learn's :class:`~sklearn.neural_network.MLPRegressor`, hidden layers
   ``(35, 45)``, ``tanh``, L2 penalty ``alpha``, ``random_state`` drawn from the estimator's
   generator (same seed, same estimate). The measured log's window means go through the same
   standardisation and the network gives the estimate.

Solver (measured, 10 simulated 60 s episodes of ``paper6`` x 3 seeds, 1000 training vectors;
error in units of the Cramér-Rao std, RMS over episodes for ``[mdf, bf_x, bf_y, bf_z]``):
``lbfgs`` with 500 iterations: [4.4, 11.8, 9.0, 6.9] in 2.0 s; ``adam`` (the default stopping
rule stops after ~80 epochs): [8.3, 25.4, 18.0, 21.6] in 0.5 s, and with ``learning_rate_init
0.003`` and 500 epochs: [4.9, 15.7, 10.9, 14.2] in 2.7 s. The regression is small and smooth, and
a full-batch quasi-Newton method fits it better per second than stochastic gradients, so the
default is ``lbfgs`` (the paper's steepest descent is the slowest of the three). More training
vectors or iterations, other ``alpha`` or window counts gave no clear gain at up to 3 x the time:
the error is that of approximating the inverse map over the whole search box to a few per cent
of its width, while the Cramér-Rao std is ~0.5 % of it. The network is therefore several times
less accurate than the maximum-likelihood estimate (``lm``) on the same log; it needs no
starting point and no cost evaluations at the measured log.

Training runs with the BLAS limited to one thread: these matrices are small, so threads cost more
than they give (on a busy 2-core machine a fit took 24 s with 2 BLAS threads, 1.8 s with one),
and 500 L-BFGS iterations amplify the rounding differences between thread counts into estimates
that differ by a few Cramér-Rao std, so one thread keeps a seed's estimate the same whatever the
machine's core count.

The ``cost_history`` has one entry (the whole-log cost at the estimate, nothing is iterated on
the measured log); the training loss curve and the set-up are in the estimate's ``extra``
under ``training``.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor
from threadpoolctl import threadpool_limits

from estimators.base import Estimator, SearchResult
from estimators.options import check_float, check_int
from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.sim.sensors import SensorModel

IntArray = NDArray[np.intp]

#: largest batch of particle-samples per ``problem.predict`` call while building the training set
#: (the (P, T, 3) float64 prediction is 24 bytes per particle-sample: ~100 MB)
MAX_PREDICT_SAMPLES = 4_000_000

#: fewest log samples per feature window
MIN_SAMPLES_PER_WINDOW = 2

SOLVERS = ("lbfgs", "adam")


class NeuralNetworkEstimator(Estimator):
    """Back-propagation network mapping window-averaged base rates to the parameters (see the module docstring).

    Args:
        n_train: simulated training logs (parameter vectors drawn uniformly in the bounds), >= 10.
        n_windows: equal time windows whose mean base rate per axis are the features (3 x n_windows).
        hidden_layer_sizes: units per hidden layer (the paper's (35, 45)).
        solver: ``"lbfgs"`` (default, measured best) or ``"adam"``.
        max_iter: L-BFGS iterations or adam epochs.
        alpha: L2 penalty of the network weights (standardised features, unit-box targets), >= 0.
        noise_std_rad_s: gyro noise std per sample (rad/s) added to the training logs; ``None``:
            the model's ``noise_std_rad_s`` if set, else the default gyro at the log's sample period.
        seed: seed of the generator (training draws and the network's initial weights).
    """

    name = "nn"

    def __init__(
        self,
        *,
        n_train: int = 1000,
        n_windows: int = 20,
        hidden_layer_sizes: tuple[int, ...] = (35, 45),
        solver: str = "lbfgs",
        max_iter: int = 500,
        alpha: float = 1e-4,
        noise_std_rad_s: float | None = None,
        seed: int | None = 0,
    ) -> None:
        super().__init__(seed=seed)
        self.n_train = check_int("n_train", n_train, 10)
        self.n_windows = check_int("n_windows", n_windows, 1)
        if not isinstance(hidden_layer_sizes, (tuple, list)) or not hidden_layer_sizes:
            raise SpaceIdInputError(
                f"hidden_layer_sizes: expected a non-empty sequence of positive integers, got {hidden_layer_sizes!r}"
            )
        self.hidden_layer_sizes = tuple(check_int("hidden_layer_sizes", units, 1) for units in hidden_layer_sizes)
        if solver not in SOLVERS:
            raise SpaceIdInputError(f"solver: expected one of {', '.join(map(repr, SOLVERS))}, got {solver!r}")
        self.solver = solver
        self.max_iter = check_int("max_iter", max_iter, 1)
        self.alpha = check_float("alpha", alpha, 0.0, math.inf)
        self.noise_std_rad_s = None if noise_std_rad_s is None else check_float("noise_std_rad_s", noise_std_rad_s, 0.0, math.inf)

    def min_samples(self, problem: IdentificationProblem) -> int:
        """``MIN_SAMPLES_PER_WINDOW`` samples per feature window (and the base class's minimum)."""
        return max(MIN_SAMPLES_PER_WINDOW * self.n_windows, super().min_samples(problem))

    def _search(self, problem: IdentificationProblem, rng: np.random.Generator) -> SearchResult:
        params = problem.parameters
        edges = window_edges(problem.n_samples, self.n_windows)
        sigma, noise_source = self.training_noise_std(problem)

        unit = rng.uniform(size=(self.n_train, problem.n_params))  # targets, (n_train, k)
        features = simulated_window_means(problem, params.from_unit(unit), edges)
        per_window = sigma / np.sqrt(np.diff(edges))  # std of the noise mean over each window, (W,)
        features += rng.standard_normal(features.shape) * np.repeat(per_window, 3)
        centre = features.mean(axis=0)
        scale = features.std(axis=0)
        scale[scale == 0.0] = 1.0  # a feature no parameter moves (noise-free, motionless window)
        inputs = (features - centre) / scale

        network = _LossRecordingMLP(
            hidden_layer_sizes=self.hidden_layer_sizes,
            activation="tanh",
            solver=self.solver,
            alpha=self.alpha,
            max_iter=self.max_iter,
            random_state=int(rng.integers(2**31 - 1)),
        )
        with threadpool_limits(limits=1, user_api="blas"), warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # stopping at max_iter is the budget, not a failure
            network.fit(inputs, unit)
            fitted = np.reshape(network.predict(inputs), unit.shape)
            measured = (window_means(problem.measured[None], edges) - centre) / scale
            estimate = np.clip(np.reshape(network.predict(measured), problem.n_params), 0.0, 1.0)

        theta = params.from_unit(estimate)
        cost = float(problem.cost(theta[None], count=False)[0])
        train_rms = np.sqrt(np.mean((fitted - unit) ** 2, axis=0)) * params.width
        loss_curve = network.loss_curve_ if self.solver != "lbfgs" else network.lbfgs_losses
        return SearchResult(
            theta=theta,
            cost_history=[cost],
            extra={
                "training": {
                    "n_train": self.n_train,
                    "n_features": int(features.shape[1]),
                    "noise_std_rad_s": sigma,
                    "noise_source": noise_source,
                    "n_iter": int(network.n_iter_),
                    "reached_max_iter": bool(network.n_iter_ >= self.max_iter),
                    "final_loss": float(network.loss_),
                    # per adam epoch, or per L-BFGS function evaluation (line searches included)
                    "loss_curve": [float(v) for v in loss_curve],
                    "train_rms_error": dict(zip(params.names, train_rms.tolist(), strict=True)),
                }
            },
        )

    def training_noise_std(self, problem: IdentificationProblem) -> tuple[float, str]:
        """Gyro noise std per sample (rad/s) for the training logs and where it came from (``option``, ``model``, ``sensor default``)."""
        if self.noise_std_rad_s is not None:
            return self.noise_std_rad_s, "option"
        if problem.model.noise_std_rad_s is not None:
            return float(problem.model.noise_std_rad_s), "model"
        return SensorModel().gyro_std_rad_s(problem.log.sample_period_s), "sensor default"


class _LossRecordingMLP(MLPRegressor):
    """:class:`MLPRegressor` that also keeps the training loss at each L-BFGS function evaluation.

    scikit-learn records ``loss_curve_`` for the stochastic solvers only; L-BFGS evaluates the
    loss through ``_loss_grad_lbfgs``, whose value is appended to ``lbfgs_losses`` (the
    optimisation itself is unchanged).
    """

    lbfgs_losses: list[float]

    def fit(self, X: FloatArray, y: FloatArray, **kwargs: Any) -> _LossRecordingMLP:
        self.lbfgs_losses = []
        return super().fit(X, y, **kwargs)

    def _loss_grad_lbfgs(self, *args: Any, **kwargs: Any) -> tuple[float, FloatArray]:
        loss, grad = super()._loss_grad_lbfgs(*args, **kwargs)
        self.lbfgs_losses.append(float(loss))
        return loss, grad


def window_edges(n_samples: int, n_windows: int) -> IntArray:
    """Sample indices (n_windows + 1,) splitting ``n_samples`` into ``n_windows`` windows of equal size (+-1 sample)."""
    return np.linspace(0, n_samples, n_windows + 1).round().astype(np.intp)


def window_means(omega: FloatArray, edges: IntArray) -> FloatArray:
    """Mean base rate per window and axis: ``omega`` (P, T, 3) rad/s -> (P, 3 W), window-major."""
    sums = np.add.reduceat(omega, edges[:-1], axis=1)  # (P, W, 3)
    return (sums / np.diff(edges)[None, :, None]).reshape(len(omega), -1)


def simulated_window_means(problem: IdentificationProblem, theta: FloatArray, edges: IntArray) -> FloatArray:
    """Noise-free window means (P, 3 W) of the base rate predicted for ``theta`` (P, k); counted in the budget."""
    batch = max(1, MAX_PREDICT_SAMPLES // problem.n_samples)
    return np.concatenate([window_means(problem.predict(theta[i : i + batch]), edges) for i in range(0, len(theta), batch)])
