"""spaceid-gym: identify the inertial parameters of robots from their own motion data.

Importing the package registers the Gymnasium environments ``FreeFloatingID-v0`` and ``ManipulatorID-v0``.
``FreeFloatingID-v0`` is built by :func:`spaceid_gym.envs.estimation.make_free_floating_env` (the physics env, wrapped
in the estimator hook when ``estimator=`` is given).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from spaceid_gym.envs.free_floating import WINDOW_STEPS
from spaceid_gym.envs.manipulator import WINDOW_STEPS as MANIPULATOR_WINDOW_STEPS
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.robots import Robot, available_robots, load_robot

__version__ = "0.1.0"
__all__ = ["Robot", "SpaceIdInputError", "__version__", "available_robots", "load_robot"]

if "FreeFloatingID-v0" not in registry:
    register(
        id="FreeFloatingID-v0",
        entry_point="spaceid_gym.envs.estimation:make_free_floating_env",  # a string: this package imports no estimator
        max_episode_steps=WINDOW_STEPS,
    )
if "ManipulatorID-v0" not in registry:
    register(
        id="ManipulatorID-v0",
        entry_point="spaceid_gym.envs.manipulator:ManipulatorIDEnv",
        max_episode_steps=MANIPULATOR_WINDOW_STEPS,
    )
