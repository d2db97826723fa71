"""Estimators by name: ``make_estimator("improved-pso", seed=1)``; users add their own with :func:`register_estimator`.

The table starts empty here; :mod:`estimators.builtin` fills it with the shipped estimators, and importing the
package :mod:`estimators` imports that module, so the shipped names are there whatever module a user imports first.
This module imports no estimator, so an estimator may itself resolve a name (``hybrid``'s global search does).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from estimators.base import Estimator
from spaceid_gym.errors import SpaceIdInputError

_FACTORIES: dict[str, Callable[..., Estimator]] = {}


def register_estimator(name: str, factory: Callable[..., Estimator], *, overwrite: bool = False) -> None:
    """Make ``factory(**options)`` available as ``name`` (in the CLI, the env and :func:`make_estimator`)."""
    if not name or not isinstance(name, str):
        raise SpaceIdInputError(f"estimator name: expected a non-empty string, got {name!r}")
    if name in _FACTORIES and not overwrite:
        raise SpaceIdInputError(f"estimator {name!r} is already registered (pass overwrite=True to replace it)")
    _FACTORIES[name] = factory


def available_estimators() -> list[str]:
    """Names of the registered estimators."""
    return sorted(_FACTORIES)


def make_estimator(name: str | Estimator, **options: Any) -> Estimator:
    """The estimator registered as ``name`` built with ``options`` (an :class:`Estimator` is returned as is)."""
    if isinstance(name, Estimator):
        return name
    if name not in _FACTORIES:
        raise SpaceIdInputError(f"unknown estimator {name!r}; available: {', '.join(sorted(_FACTORIES))}")
    try:
        return _FACTORIES[name](**options)
    except TypeError as exc:
        raise SpaceIdInputError(f"estimator {name!r}: bad options {options}: {exc}") from None
