"""The estimator hook of ``FreeFloatingID-v0``: a Gymnasium wrapper that identifies the fuel state of each window.

Top layer: it joins the physics env (:class:`~spaceid_gym.envs.free_floating.FreeFloatingIDEnv`, which imports no
estimator) and the estimators. ``gym.make("FreeFloatingID-v0", estimator="hybrid")`` builds the env through
:func:`make_free_floating_env`, which wraps it in :class:`EstimatorWrapper` when an estimator is given; without one
``gym.make`` returns the plain env.

* **At the window's end** (step ``identify_after_steps``) the estimator is fitted on the window's log, with the
  paper's model (or the model with ``estimator_effects``); that step's ``info`` holds ``estimate`` (the estimate
  file's content) and ``estimate_errors`` (``M``, ``r``, ``Ixx``, ``Iyy``, ``Izz`` in %, ``mdf`` in kg, ``bf`` in
  mm, as in :mod:`estimators.evaluation`).
* **At every step**, for a streaming estimator (:func:`~estimators.streaming.is_streaming`, e.g. ``ukf``): its
  tracker takes the newest sample, and ``info`` holds ``running_estimate`` and ``running_estimate_std`` (dicts by
  parameter name: ``fuel_consumed_kg`` in kg, ``tank_x_m``... in m), from the reset's sample on. The tracker sees
  a log of the newest sample alone (the paper's model predicts a sample's base rate from that sample's joints),
  so a step costs the same whatever the window's length; its gyro noise is the sensor model's (the datasheet's
  angle random walk; the default sensors' when the env's are noise-free), since one sample has no residual to
  estimate it from. The window's-end fit is the estimator's own (for ``ukf``: its tempered passes over the window),
  not the last running estimate.
"""

from __future__ import annotations

from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.evaluation import quantity_errors
from estimators.models.effect_models import parse_effects
from estimators.problem import IdentificationModel
from estimators.registry import make_estimator
from estimators.streaming import SampleTracker, StreamingEstimator, is_streaming
from spaceid_gym.envs.free_floating import WINDOW_STEPS, FreeFloatingIDEnv
from spaceid_gym.errors import SpaceIdInputError


class EstimatorWrapper(gym.Wrapper[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]):
    """Fits an estimator on each window of a :class:`~spaceid_gym.envs.free_floating.FreeFloatingIDEnv`.

    Args:
        env: the env (or a wrapper of it).
        estimator: a registered name such as ``"hybrid"`` or an :class:`~estimators.base.Estimator`.
        identify_after_steps: window length in steps after which the estimator is fitted; default
            :data:`~spaceid_gym.envs.free_floating.WINDOW_STEPS`, the registered ``max_episode_steps``: pass the same
            number to both when changing the window, as the time limit wrapper does not tell this wrapper.
        estimator_effects: effects the estimator's model includes, e.g. ``"initial_momentum"``; default none (the
            paper's model, so hidden effects are missing from it and show in ``estimate_errors``).
        stream: put a streaming estimator's running estimate in every step's ``info`` (default ``True``; ignored for
            an estimator without the streaming interface). The running estimate uses the model without effects:
            ``stream=True`` with ``estimator_effects`` is refused.
    """

    def __init__(
        self,
        env: gym.Env[NDArray[np.float32], NDArray[np.float32]],
        estimator: str | Estimator,
        *,
        identify_after_steps: int = WINDOW_STEPS,
        estimator_effects: str | None = None,
        stream: bool = True,
    ) -> None:
        super().__init__(env)
        if not isinstance(env.unwrapped, FreeFloatingIDEnv):
            raise SpaceIdInputError(
                f"env: expected a FreeFloatingIDEnv (or a wrapper of one), got {type(env.unwrapped).__name__}"
            )
        self.estimator = make_estimator(estimator)
        if estimator_effects is not None:
            parse_effects(estimator_effects)  # validates the spec now, not at the window's end
        if isinstance(identify_after_steps, bool) or not isinstance(identify_after_steps, int) or identify_after_steps < 1:
            raise SpaceIdInputError(f"identify_after_steps: expected a positive number of steps, got {identify_after_steps!r}")
        if not isinstance(stream, bool):
            raise SpaceIdInputError(f"stream: expected True or False, got {stream!r}")
        self.streaming = stream and is_streaming(self.estimator)
        if self.streaming and estimator_effects is not None:
            raise SpaceIdInputError(
                "estimator_effects: the running estimate of a streaming estimator uses the model without effects; "
                "pass stream=False to fit the model with effects at the window's end only"
            )
        self.identify_after_steps = identify_after_steps
        self.estimator_effects = estimator_effects
        self._steps = 0
        self._tracker: SampleTracker | None = None
        self._last_t_s = 0.0
        self._stream_model: IdentificationModel | None = None

    @property
    def physics(self) -> FreeFloatingIDEnv:
        """The wrapped physics env."""
        env = self.env.unwrapped
        assert isinstance(env, FreeFloatingIDEnv)
        return env

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self._steps = 0
        if self.streaming:
            self._tracker = None
            info.update(self._stream())
        return observation, info

    def step(self, action: NDArray[np.float32]) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        if self.streaming:
            info.update(self._stream())
        if self._steps == self.identify_after_steps:
            info.update(self._identify())
        return observation, reward, terminated, truncated, info

    # ------------------------------------------------------------------ internals
    def _stream(self) -> dict[str, Any]:
        """Feed the newest sample to the tracker; its running estimate and std by parameter name."""
        env = self.physics
        newest = env.measurement_log(last=1)
        t_s = float(newest.t_s[0])
        if self._tracker is None:  # the reset's sample: a new tracker at the estimator's initial state
            if self._stream_model is None or self._stream_model.robot is not env.robot:
                self._stream_model = IdentificationModel(env.robot, "fuel", noise_std_rad_s=env.gyro_std_rad_s)
            streaming = cast(StreamingEstimator, self.estimator)
            self._tracker = streaming.tracker(self._stream_model.problem(newest))
        else:
            assert self._stream_model is not None
            self._tracker.bind(self._stream_model.problem(newest))
            self._tracker.advance(t_s - self._last_t_s)
        self._tracker.update(0)
        self._last_t_s = t_s
        theta, covariance = self._tracker.estimate()
        names = self._stream_model.parameters.names
        std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
        return {
            "running_estimate": dict(zip(names, theta.tolist(), strict=True)),
            "running_estimate_std": dict(zip(names, std.tolist(), strict=True)),
        }

    def _identify(self) -> dict[str, Any]:
        """Fit the estimator on the window: ``estimate`` (the estimate file's dict) and ``estimate_errors``."""
        env = self.physics
        model = IdentificationModel(env.robot, "fuel", effects=self.estimator_effects)
        estimate = self.estimator.fit(model, env.measurement_log())
        truth = env.truth()
        theta_true = np.concatenate(([truth["fuel_consumed_kg"]], truth["tank_position_m"]))
        truth_physical = IdentificationModel(env.robot, "fuel").parameters.physical(theta_true)
        errors = quantity_errors(model.parameters.physical(estimate.theta), truth_physical)
        return {"estimate": estimate.to_dict(), "estimate_errors": errors}


def make_free_floating_env(
    *,
    estimator: str | Estimator | None = None,
    identify_after_steps: int = WINDOW_STEPS,
    estimator_effects: str | None = None,
    stream: bool = True,
    **env_options: Any,
) -> gym.Env[NDArray[np.float32], NDArray[np.float32]]:
    """``FreeFloatingID-v0``'s entry point: the env with ``env_options``, wrapped in :class:`EstimatorWrapper` when an
    ``estimator`` is given (the other arguments are the wrapper's; without an estimator they are not used)."""
    env = FreeFloatingIDEnv(**env_options)
    if estimator is None:
        return env
    return EstimatorWrapper(
        env, estimator, identify_after_steps=identify_after_steps, estimator_effects=estimator_effects, stream=stream
    )
