"""The motor torque constants, identified with the dynamic parameters from the currents: ``arm ... --identify-gains``.

A current log predicts ``i_j = (Y_j beta) / k_j`` (joint ``j``, ``Y_j`` the base regressor in N m per unit base
parameter, ``beta`` the base parameters in SI units, ``k_j`` the torque constant in N m/A, gear included). The model
rows of :class:`~estimators.arm.model.ArmIdentificationModel` hold ``Y_j / k0_j`` with the model's constants ``k0``
(the UR5's approximate published ones by default), so with the correction ``c_j = k0_j / k_j``::

    i_j  =  c_j  (Y_j / k0_j) beta                  bilinear in (c, beta)

What is identifiable
--------------------
* **The overall scale is not**: ``(c, beta) -> (c / s, s beta)`` predicts the same currents for every ``s > 0``; so is
  a physically consistent ``beta`` (the consistent set is a cone). Currents alone give the gains' **ratios**, never
  the gains. A reference fixes the scale (``reference``):

  - ``"joint:J"``: joint ``J``'s torque constant is the model's (``c_J = 1``), the others are relative to it;
  - ``"gravity"`` (default): the scale whose identified gravity torques best match the URDF's (UR's published link
    masses and centres of mass) along the training movements' configurations, in least squares over all joints. It
    leans on the published masses, not on any joint's gain; the base parameters that do not enter gravity (the
    inertias, friction, armature) follow from the currents.
* **The ratios are** identifiable when every joint's torque shares parameters with the others (a serial arm's do: the
  torque on joint ``j`` carries the dynamics of links ``j..n``), with the precision the data give: ``gain_std_relative``
  (the Cramér-Rao std of ``log k_j`` with the reference's scale fixed; from the prepared rows, whose correlated noise
  the factor ``sqrt(kappa)`` of :meth:`~estimators.arm.identification.Preparation.correlation_factor` accounts for when
  given).

Method
------
Alternating least squares on the weighted output-error cost ``sum_j w_j |i_j - c_j X_j beta|^2`` (``X_j`` the rows,
``w_j = 1 / s_j^2`` each joint's noise from an OLS fit at ``c = 1``, Gautier's weights): ``beta`` given ``c`` is
weighted least squares; each free ``c_j`` given ``beta`` is a one-dimensional least squares. Both steps work on the
per-joint Gram blocks ``X_j^T X_j``, ``X_j^T i_j``, so an iteration costs ``O(n r^3)``, not a pass over the data.
Alternation alone crawls along the weakly informed gains (20 000 iterations did not meet 1e-10 on a simulated 20 s
log), so after ``ALS_ITERATIONS`` of it the iteration takes Newton steps with the cost's exact Hessian (halved until
the cost falls; an alternation step where no halving does). During the iteration one joint's gain is held (the reference joint, or for the gravity
reference the joint with the most signal over noise; the gauge changes no prediction). Every step lowers the cost;
the iteration stops when a Newton step's predicted decrease (the Newton decrement ``g^T H^-1 g / 2``) is below
``tolerance`` times the cost, or after ``max_iterations`` (then ``converged`` is False). A gain the data do not
determine (a flat direction of the cost) stops the iteration too, since nothing is left to gain along it; its
Cramér-Rao std says so. The final
parameters are then fitted by the chosen estimator (``wls``, ``sdp``, a colony) on the rows with the gains fixed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: default convergence tolerance: a Newton step's predicted decrease relative to the cost
GAIN_TOLERANCE = 1e-12
#: default iteration cap
GAIN_MAX_ITERATIONS = 2000
#: alternating least-squares iterations before the Newton steps
ALS_ITERATIONS = 20
#: configurations (every k-th prepared sample) on which the gravity reference compares gravity torques
GRAVITY_STRIDE = 5


@dataclass
class GainFit:
    """What :func:`identify_gains` found.

    Attributes:
        correction: (n,) ``c_j = k0_j / k_j``.
        torque_constants_Nm_A: (n,) the identified ``k_j``, N m/A.
        nominal_Nm_A: (n,) the model's ``k0``.
        reference: the scale's reference (module docstring).
        theta: (r,) the base parameters of the last least-squares step (SI units).
        iterations, converged: the alternation's count and whether it met the tolerance.
        cost_history: the weighted cost after each iteration (A^2 / A^2: sum of squares in noise units).
        gain_std_relative: (n,) Cramér-Rao std of ``log k_j`` (0 for a fixed reference joint).
    """

    correction: FloatArray
    torque_constants_Nm_A: FloatArray
    nominal_Nm_A: FloatArray
    reference: str
    theta: FloatArray
    iterations: int
    converged: bool
    cost_history: list[float] = field(default_factory=list, repr=False)
    gain_std_relative: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return {
            "torque_constants_Nm_A": self.torque_constants_Nm_A.tolist(),
            "nominal_Nm_A": self.nominal_Nm_A.tolist(),
            "reference": self.reference,
            "iterations": self.iterations,
            "converged": self.converged,
            "gain_std_relative": None if self.gain_std_relative is None else self.gain_std_relative.tolist(),
        }


def _reference_joints(reference: str, n_joints: int) -> list[int] | None:
    """The held joints' indices for ``"joint:J"`` or ``"joint:J1,J2,..."`` (1-based), ``None`` for ``"gravity"``; else
    an error naming the option."""
    if reference == "gravity":
        return None
    joints: list[int] = []
    if reference.startswith("joint:"):
        try:
            joints = sorted({int(text) - 1 for text in reference.split(":", 1)[1].split(",")})
        except ValueError:
            joints = []
    if joints and all(0 <= j < n_joints for j in joints) and len(joints) < n_joints:
        return joints
    raise SpaceIdInputError(
        f"--gain-reference: expected 'gravity' or 'joint:J' / 'joint:J1,J2' with J in 1..{n_joints} (not all), got {reference!r}"
    )


def scaled_rows(rows: Mapping[str, IdentificationRows], correction: FloatArray) -> dict[str, IdentificationRows]:
    """The rows with joint ``j``'s regressor times ``correction[j]``: the model with torque constants ``k0 / c``."""
    c = np.asarray(correction, dtype=float)
    return {name: replace(item, regressor=item.regressor * c[None, :, None]) for name, item in rows.items()}


def identify_gains(
    model: ArmIdentificationModel,
    rows: Mapping[str, IdentificationRows],
    reference: str = "gravity",
    tolerance: float = GAIN_TOLERANCE,
    max_iterations: int = GAIN_MAX_ITERATIONS,
    kappa: float = 1.0,
) -> GainFit:
    """The torque constants of the current logs ``rows`` (module docstring); ``kappa`` the prepared rows' correlation
    factor for the std (1: rows taken independent)."""
    items = list(rows.values())
    if not items or any(item.log.effort_kind != "current_A" for item in items):
        raise SpaceIdInputError("--identify-gains: needs current logs (A); torque logs have no torque constant to identify")
    held = _reference_joints(reference, model.n_joints)
    X = np.concatenate([item.regressor for item in items])  # (T, n, r)
    y = np.concatenate([item.log.effort for item in items])  # (T, n)
    beta0 = np.linalg.lstsq(X.reshape(-1, X.shape[-1]), y.reshape(-1), rcond=None)[0]
    dof = max(X.shape[0] * (1.0 - X.shape[-1] / y.size), 1.0)
    weight = 1.0 / np.maximum(np.sum((y - np.einsum("tjr,r->tj", X, beta0)) ** 2, axis=0) / dof, 1e-300)  # (n,)
    gram = np.einsum("tjr,tjs->jrs", X, X)  # (n, r, r)
    moment = np.einsum("tjr,tj->jr", X, y)  # (n, r)
    energy = np.sum(y * y, axis=0)  # (n,)
    # the gauge of the iteration: the reference joint(s), or (gravity) the joint with the most signal over noise
    free = np.ones(model.n_joints, dtype=bool)
    free[[int(np.argmax(weight * energy))] if held is None else held] = False
    c = np.ones(model.n_joints)

    def cost(c: FloatArray, beta: FloatArray) -> float:
        quadratic = np.einsum("r,jrs,s->j", beta, gram, beta)
        return float(weight @ (energy - 2.0 * c * (moment @ beta) + c**2 * quadratic))

    def beta_step(c: FloatArray) -> FloatArray:
        lhs = np.einsum("j,jrs->rs", weight * c**2, gram)
        rhs = (weight * c) @ moment
        return np.linalg.lstsq(lhs, rhs, rcond=None)[0]

    beta = beta_step(c)
    history = [cost(c, beta)]
    converged = False
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        newton = _newton_step(c, beta, free, weight, gram, moment, cost) if iterations > ALS_ITERATIONS else None
        if newton is None:  # alternation: the first iterations, and wherever Newton's step does not lower the cost
            quadratic = np.einsum("r,jrs,s->j", beta, gram, beta)
            new_c = c.copy()
            new_c[free] = (moment @ beta)[free] / np.maximum(quadratic[free], 1e-300)
            new_beta = beta_step(new_c)
        else:
            new_c, new_beta = newton[:2]
        if np.any(new_c <= 0.0):
            raise SpaceIdInputError(
                f"--identify-gains: joint(s) {np.flatnonzero(new_c <= 0.0) + 1} got a non-positive gain; "
                "their currents do not follow the model (check the logs' sign convention or the reference)"
            )
        c, beta = new_c, new_beta
        history.append(cost(c, beta))
        if newton is not None and newton[2] <= tolerance * abs(history[-2]):
            converged = True
            break
    scale_gradient = np.zeros_like(beta)
    if held is None:
        scale, scale_gradient = _gravity_scale(model, items, beta)
        c, beta = c / scale, beta * scale
        scale_gradient = scale_gradient / scale  # d log s / d beta at the rescaled beta (s is homogeneous of degree -1)
    std = _log_gain_std(X, weight, c, beta, free, scale_gradient, kappa)
    return GainFit(
        correction=c,
        torque_constants_Nm_A=model.torque_constants_Nm_A / c,
        nominal_Nm_A=model.torque_constants_Nm_A.copy(),
        reference=reference,
        theta=beta,
        iterations=iterations,
        converged=converged,
        cost_history=history,
        gain_std_relative=std,
    )


def _newton_step(
    c: FloatArray,
    beta: FloatArray,
    free: FloatArray,
    weight: FloatArray,
    gram: FloatArray,
    moment: FloatArray,
    cost: Any,
) -> tuple[FloatArray, FloatArray, float] | None:
    """One Newton step on the cost in (free ``c``, ``beta``) with its exact gradient and Hessian (the cost is a
    polynomial of the Gram blocks), halved until the cost falls, with the Newton decrement ``-g . step / 2`` (the
    decrease it predicts); ``None`` if no halving lowers it (the bilinear cost
    is not convex: the Hessian can be indefinite away from the minimum)."""
    n, r = gram.shape[0], gram.shape[1]
    g_beta = gram @ beta  # (n, r)
    quadratic = g_beta @ beta  # (n,)
    linear = moment @ beta  # (n,)
    grad_c = 2.0 * weight * (c * quadratic - linear)
    grad_beta = 2.0 * ((weight * c**2) @ g_beta - (weight * c) @ moment)
    hessian = np.zeros((n + r, n + r))
    hessian[:n, :n] = np.diag(2.0 * weight * quadratic)
    cross = weight[:, None] * (4.0 * c[:, None] * g_beta - 2.0 * moment)  # (n, r)
    hessian[:n, n:], hessian[n:, :n] = cross, cross.T
    hessian[n:, n:] = 2.0 * np.einsum("j,jrs->rs", weight * c**2, gram)
    keep = np.concatenate((free, np.ones(r, dtype=bool)))
    gradient = np.concatenate((grad_c, grad_beta))[keep]
    step = -np.linalg.lstsq(hessian[np.ix_(keep, keep)], gradient, rcond=None)[0]
    decrement = max(-0.5 * float(gradient @ step), 0.0)
    full = np.zeros(n + r)
    full[keep] = step
    current = cost(c, beta)
    for _ in range(30):
        trial_c, trial_beta = c + full[:n], beta + full[n:]
        if np.all(trial_c > 0.0) and cost(trial_c, trial_beta) < current:
            return trial_c, trial_beta, decrement
        full *= 0.5
    return None


def _gravity_scale(model: ArmIdentificationModel, items: list[IdentificationRows], beta: FloatArray) -> tuple[float, FloatArray]:
    """``s`` minimising ``|tau_g,URDF - s Y_g beta|`` over every joint and every ``GRAVITY_STRIDE``-th configuration, and
    ``d log s / d beta`` (r,)."""
    q = np.concatenate([item.log.q_rad[::GRAVITY_STRIDE] for item in items])
    zero = np.zeros_like(q)
    base = model.base_regressor(q, zero, zero, "torque_Nm").reshape(-1, beta.size)  # N m per unit base parameter
    urdf = model.regressor.torque(q, zero, zero, model.regressor.nominal_parameters()).reshape(-1)  # N m
    predicted = base @ beta
    power = max(float(predicted @ predicted), 1e-300)
    scale = float(urdf @ predicted) / power
    if not scale > 0.0:
        raise SpaceIdInputError("--gain-reference gravity: the identified gravity torques oppose the URDF's; use joint:J")
    gradient = (base.T @ urdf) / power - 2.0 * scale * (base.T @ predicted) / power
    return scale, gradient / scale


def _log_gain_std(
    X: FloatArray, weight: FloatArray, c: FloatArray, beta: FloatArray, free: FloatArray, scale_gradient: FloatArray, kappa: float
) -> FloatArray:
    """Cramér-Rao std (n,) of ``log k_j = log k0_j - log c_j + log s(beta)``: the covariance of (free ``log c``, ``beta``)
    with the held joints' gains fixed (the iteration's gauge), carried to ``log k`` with ``scale_gradient`` =
    ``d log s / d beta`` (zero for a joint reference; the gravity scale's otherwise, which makes the result the same in
    any gauge). Rows weighted by ``w_j`` and taken ``kappa`` to one independent sample."""
    n, r = X.shape[1], X.shape[2]
    root = np.sqrt(weight)
    unit = np.einsum("tjr,r->tj", X, beta)  # (T, n) the rows' prediction at c = 1
    rows = []
    for j in range(n):
        block = np.zeros((X.shape[0], n + r))
        block[:, j] = c[j] * unit[:, j]  # d prediction / d log c_j
        block[:, n:] = c[j] * X[:, j, :]
        rows.append(root[j] * block)
    jacobian = np.concatenate(rows)
    keep = np.concatenate((np.asarray(free, dtype=bool), np.ones(r, dtype=bool)))
    fisher = jacobian[:, keep].T @ jacobian[:, keep] / kappa
    covariance = np.zeros((n + r, n + r))
    covariance[np.ix_(keep, keep)] = np.linalg.pinv(fisher)
    carry = np.zeros((n, n + r))
    carry[np.arange(n), np.arange(n)] = -1.0
    carry[:, n:] = scale_gradient
    return np.sqrt(np.maximum(np.einsum("ja,ab,jb->j", carry, covariance, carry), 0.0))
