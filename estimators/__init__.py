"""Identification models and estimators for spaceid-gym.

So far: :class:`estimators.models.MomentumModel`, the batched identification model (base rate
over a log for many parameter vectors). The estimator protocol and the estimators (improved PSO
and the others) are the rest of the estimators issue.
"""
