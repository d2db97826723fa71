"""Identification models and estimators for spaceid-gym.

Empty so far: the identification model, the estimator protocol and the estimators are the work of
the next issue. The package exists so that the layout the users asked for is in place.
"""
