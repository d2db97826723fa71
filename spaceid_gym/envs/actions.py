"""Action checking shared by the identification environments."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


def checked_action(action: ArrayLike, space: spaces.Box) -> FloatArray:
    """``action`` as a float array of the space's shape, finite; else :class:`SpaceIdInputError` naming what was expected.

    Values outside ``[-1, 1]`` are returned as given: each environment says what it does with them (clip, rate limit).
    """
    a = np.asarray(action, dtype=float)
    if a.shape != space.shape:
        raise SpaceIdInputError(f"action: expected shape {space.shape}, got {a.shape}")
    if not math.isfinite(a.sum()):  # NaN and +-inf propagate through the sum
        raise SpaceIdInputError(f"action: expected finite values in [-1, 1], got {a.tolist()}")
    return a
