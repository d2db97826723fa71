"""Identification models and estimators for spaceid-gym.

The data flow: :class:`~estimators.problem.IdentificationModel` (robot + unknowns) bound to a
:class:`~spaceid_gym.log.MeasurementLog` gives an :class:`~estimators.problem.IdentificationProblem`
(batched objective, analytic Jacobian, Cramér-Rao bound); an :class:`~estimators.base.Estimator`
(``fit(model, log)``, options in the constructor) returns an :class:`~estimators.estimate.Estimate`.
Estimators by name: :func:`~estimators.registry.make_estimator` (``pso``, ``improved-pso``, ``lm``,
``hybrid``, ``nn``, ``de``, ``cma-es``, ``pyswarms-local``, and users' own via
:func:`~estimators.registry.register_estimator`). :mod:`estimators.evaluation` runs them episode by
episode against the truth and the bound.
"""
