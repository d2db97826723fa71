"""Input checks shared by the residual-analysis modules: each raises a SpaceIdInputError naming the input."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


def _array(x: ArrayLike, name: str, ndim: tuple[int, ...], min_rows: int = 1) -> FloatArray:
    """``x`` as a finite float array with one of the allowed dimensions and at least ``min_rows`` rows."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim not in ndim:
        raise SpaceIdInputError(f"{name}: expected an array with {' or '.join(map(str, ndim))} dimensions, got shape {a.shape}")
    if a.shape[0] < min_rows:
        raise SpaceIdInputError(f"{name}: expected at least {min_rows} samples (rows), got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise SpaceIdInputError(f"{name}: expected finite values, got {a[tuple(bad)]} at index {tuple(int(i) for i in bad)}")
    return a


def _columns(x: ArrayLike, name: str, min_rows: int = 1) -> tuple[FloatArray, bool]:
    """``x`` (T,) or (T, C) as (T, C), and whether it was one-dimensional."""
    a = _array(x, name, (1, 2), min_rows)
    return (a[:, None], True) if a.ndim == 1 else (a, False)


def _check_lag(max_lag: int, n_samples: int, name: str) -> int:
    if not isinstance(max_lag, (int, np.integer)) or isinstance(max_lag, bool) or not 1 <= max_lag < n_samples:
        raise SpaceIdInputError(f"{name}: expected an integer 1 <= max_lag < T = {n_samples}, got {max_lag!r}")
    return int(max_lag)


def _check_probability(value: float, name: str) -> float:
    if not 0.0 < value < 1.0:
        raise SpaceIdInputError(f"{name}: expected a probability strictly between 0 and 1, got {value!r}")
    return float(value)


def _check_same_rows(n_samples: int, **arrays: FloatArray) -> None:
    for name, a in arrays.items():
        if a.shape[0] != n_samples:
            raise SpaceIdInputError(f"{name}: expected {n_samples} samples (rows, one per time step), got shape {a.shape}")
