"""The fixed-base arm's identification (the UR5): ``tau = Y(q, dq, ddq) theta``, linear in its unknowns.

* :mod:`.model`: :class:`~estimators.arm.model.ArmIdentificationModel`, the base regressor in each log's
  effort unit, bound to the filtered rows of a movement;
* :mod:`.linear_problem`: :class:`~estimators.arm.linear_problem.LinearIdentificationProblem`, the weighted
  least-squares cost, its Fisher information and Cramér-Rao bound;
* :mod:`.consistency`: physical consistency (pseudo-inertia) and the log-Cholesky parameterisation;
* the estimators of the linear problem: :mod:`.linear_ls` (``ols``, ``wls``), :mod:`.sdp` (``sdp``) and
  :mod:`.improved_abc` (``abc``, ``improved-abc``);
* :mod:`.identification`: movements to rows, fits, torque-prediction error and leave-one-out validation;
* :mod:`.arm_diagnosis`: what the arm model misses and where;
* :mod:`.synthetic`: a synthetic arm with a known truth (tests and benchmarks).

The robot, its regressor, friction, logs and simulator (the physics) are in :mod:`spaceid_gym.arm`.
"""
