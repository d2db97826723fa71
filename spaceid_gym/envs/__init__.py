"""Gymnasium environments: ``FreeFloatingID-v0``."""

from spaceid_gym.envs.free_floating import FreeFloatingIDEnv, RewardWeights

__all__ = ["FreeFloatingIDEnv", "RewardWeights"]
