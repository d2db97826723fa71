"""Identification models and estimators for spaceid-gym.

The data flow: :class:`~estimators.problem.IdentificationModel` (robot + unknowns) bound to a
:class:`~spaceid_gym.log.MeasurementLog` gives an :class:`~estimators.problem.IdentificationProblem`
(batched objective, analytic Jacobian, Cramér-Rao bound); an :class:`~estimators.base.Estimator`
(``fit(model, log)``, options in the constructor) returns an :class:`~estimators.estimate.Estimate`.
Estimators by name: :func:`~estimators.registry.make_estimator` (``pso``, ``improved-pso``, ``lm``,
``hybrid``, ``nn``, ``de``, ``cma-es``, ``pyswarms-local``, ``ukf``, the arm's ``ols``, ``wls``, ``sdp``, ``abc``,
``improved-abc``, and users' own via :func:`~estimators.registry.register_estimator`); importing the package
registers the shipped ones (:mod:`estimators.builtin`). The fixed-base arm's linear problem and its estimators are
in :mod:`estimators.arm`. :mod:`estimators.evaluation` (the harness, top layer) runs them episode by episode
against the truth and the bound.
"""

# registers the shipped estimators with the registry, whichever module of the package is imported first
from estimators import builtin as _builtin  # noqa: F401
