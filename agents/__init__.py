"""Excitation: joint motions that make the dynamics observable (hand-designed and learnt)."""

from agents.excitation import FourierExcitation

__all__ = ["FourierExcitation"]
