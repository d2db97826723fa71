"""Identification models: predict measurements from a log for a batch of parameter vectors."""

from estimators.models.momentum_model import MomentumModel

__all__ = ["MomentumModel"]
