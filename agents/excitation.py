"""The hand-designed excitations, which live in the core (:mod:`spaceid_gym.excitation`) since the simulator's
datasets and the variation matrix use them; re-exported here beside the learnt ones."""

from spaceid_gym.excitation import FourierExcitation, SmoothRandomExcitation

__all__ = ["FourierExcitation", "SmoothRandomExcitation"]
