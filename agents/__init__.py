"""Excitation: joint motions that make the dynamics observable (hand-designed and learnt).

``agents.train_excitation`` and ``agents.ExcitationPolicy`` (:mod:`agents.policy`) need torch and stable-baselines3
(the ``agents`` extra): importing this package imports them (a few seconds).
"""

from agents.policy import ExcitationPolicy, train_excitation
from spaceid_gym.excitation import FourierExcitation

__all__ = ["ExcitationPolicy", "FourierExcitation", "train_excitation"]
