"""Checks of estimator options: each returns the value in its proper type or raises a
:class:`~spaceid_gym.errors.SpaceIdInputError` naming the option and what was expected."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int >= ``minimum``, else :class:`SpaceIdInputError` naming the option."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise SpaceIdInputError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return int(value)


def check_float(name: str, value: Any, low: float, high: float, *, low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a float in the interval ``[low, high]`` (ends open if asked), else :class:`SpaceIdInputError`."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and math.isfinite(value)
    if ok:
        ok = (value > low if low_open else value >= low) and (value < high if high_open else value <= high)
    if not ok:
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        raise SpaceIdInputError(f"{name}: expected a number in {interval}, got {value!r}")
    return float(value)


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool (``True``/``False`` only), else :class:`SpaceIdInputError`."""
    if not isinstance(value, (bool, np.bool_)):
        raise SpaceIdInputError(f"{name}: expected True or False, got {value!r}")
    return bool(value)


def positive_option(name: str, value: Any, *, integer: bool = False) -> Any:
    """``value`` if it is a finite number > 0 (an int >= 1 if ``integer``), else :class:`SpaceIdInputError`."""
    return check_int(name, value, 1) if integer else check_float(name, value, 0.0, math.inf, low_open=True)


def finite_vector(name: str, value: ArrayLike, names: tuple[str, ...] | None = None) -> FloatArray:
    """``value`` as a vector of finite floats (of one entry per parameter in ``names`` if given), else :class:`SpaceIdInputError`."""
    try:
        vector = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        vector = np.array([np.nan])
    expected = "finite numbers" if names is None else f"{len(names)} finite numbers ({', '.join(names)})"
    if vector.ndim != 1 or not np.all(np.isfinite(vector)) or (names is not None and len(vector) != len(names)):
        raise SpaceIdInputError(f"{name}: expected {expected}, got {value!r}")
    return vector
