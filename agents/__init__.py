"""Excitation: joint motions that make the dynamics observable (hand-designed and learnt).

``agents.train_excitation`` and ``agents.ExcitationPolicy`` (:mod:`agents.policy`) are loaded on first use: they
import torch and stable-baselines3 (the ``agents`` extra), which take seconds, and the command line imports this
package for every command.
"""

from typing import Any

from agents.excitation import FourierExcitation

__all__ = ["ExcitationPolicy", "FourierExcitation", "train_excitation"]

_LEARNT = ("ExcitationPolicy", "train_excitation")


def __getattr__(name: str) -> Any:
    if name in _LEARNT:
        from agents import policy  # heavy optional dependency (torch): loaded when first asked for

        return getattr(policy, name)
    raise AttributeError(f"module 'agents' has no attribute {name!r}")
