"""Analytic Jacobians of the prediction with effect terms: the base's own rate and the gyro's reading.

:func:`effect_jacobians` differentiates :meth:`~estimators.models.effect_models.EffectPrediction.predict` at one
parameter vector in one pass over the log (the forward-mode kernels of :mod:`estimators.models.tangents`), where
central differences evaluated the whole prediction at ``2k`` points:

* the composite's parameters: :meth:`~estimators.parameters.Parameterisation.composite_jacobian` (the payload's are
  its own unknowns);
* the extra momentum of the momentum terms (``initial_momentum``, ``external_torque``): linear in their unknowns,
  so each term evaluated at unit vectors is its derivative;
* the slosh oscillator: its per-fit inputs (the rest's parameters, the tank, the sloshing mass, the natural
  frequency, damping, rod curvature, coupling and rod axis: a few numbers per parameter vector, no sample dimension) by central
  differences, their propagation along the log forward-mode;
* the measurement terms (``delay``, ``gyro_scale``, ``gyro_bias``): linear in the rate, so the rate's derivatives pass
  through them (a bias adds nothing to a derivative); their own unknowns' columns by central differences of that
  stage alone, on the rate computed once.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from estimators.models.effect_base import EffectTerm
from estimators.models.effect_models import EffectPrediction
from estimators.models.mass_effects import _point_mass10
from estimators.models.momentum_model import MomentumModel
from estimators.models.tangents import slosh_tangents, twist_tangents
from spaceid_gym.arrays import FloatArray


class EffectParameters(Protocol):
    """What the Jacobian needs of the unknowns' parameterisation (:class:`~estimators.parameters.WithEffects` has it)."""

    def composite(self, theta: FloatArray) -> tuple[FloatArray, FloatArray | None]: ...

    def composite_jacobian(self, theta: FloatArray) -> tuple[FloatArray, FloatArray | None]: ...

    def base_part(self, theta: FloatArray) -> FloatArray: ...

    def term_parts(self, theta: FloatArray) -> dict[EffectTerm, FloatArray]: ...


def effect_jacobians(
    prediction: EffectPrediction, params: EffectParameters, theta: FloatArray, step: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``d base_rate / d theta`` and ``d gyro reading / d theta``, each (3T, k), at ``theta`` (k,) over the whole log;
    ``step`` (k,): the central differences' steps of the few per-fit quantities (see the module docstring)."""
    theta = np.asarray(theta, dtype=float)
    n_k = theta.size
    row = theta[None]
    context = prediction.context
    model = prediction.momentum_model
    base10, payload10 = params.composite(row)
    d_base, d_payload = params.composite_jacobian(theta)
    units = params.term_parts(np.eye(n_k))  # each term's part of each unit direction (k, k_e)
    parts = params.term_parts(row)
    # the unknowns that move the base (the measurement terms' own only change the reading)
    reading_only = np.zeros(n_k, dtype=bool)
    for term in prediction.measurement_terms:
        reading_only |= np.any(units[term] != 0.0, axis=1)
    rotating = np.flatnonzero(~reading_only)
    extra, d_extra = None, None
    for term in prediction.momentum_terms:
        angular = term.angular_momentum(parts[term], context)[0]  # type: ignore[attr-defined]
        d_angular = term.angular_momentum(np.ascontiguousarray(units[term][rotating]), context)  # type: ignore[attr-defined]
        if extra is None:
            extra, d_extra = np.zeros((model.n_samples, 6)), np.zeros((len(rotating), model.n_samples, 6))
        assert d_extra is not None
        extra[:, 3:] += angular
        d_extra[..., 3:] += d_angular
    composite = (base10[0], d_base.T[rotating])
    payload = None if payload10 is None else (payload10[0], None if d_payload is None else d_payload.T[rotating])
    if prediction.slosh is None:
        twist, d_rotating = _twist(model, composite, payload, extra, d_extra)
    else:
        twist, d_rotating = _slosh_twist(prediction, params, theta, (rotating, step), composite, payload, extra, d_extra)
    true, d_true = twist[None, :, 3:], np.zeros((n_k, model.n_samples, 3))
    d_true[rotating] = d_rotating[..., 3:]
    measured, d_measured = true, d_true.copy()
    for term in prediction.measurement_terms:
        own = parts[term]
        if not term.additive:
            d_measured = term.measure(d_measured, np.repeat(own, n_k, axis=0), context)  # type: ignore[attr-defined]
        columns = np.flatnonzero(np.any(units[term] != 0.0, axis=1))
        shifts = np.repeat(own, 2 * len(columns), axis=0)
        for i, column in enumerate(columns):
            shifts[2 * i, i] += step[column]
            shifts[2 * i + 1, i] -= step[column]
        shifted = term.measure(np.repeat(measured, 2 * len(columns), axis=0), shifts, context)  # type: ignore[attr-defined]
        d_measured[columns] = (shifted[0::2] - shifted[1::2]) / (2.0 * step[columns, None, None])
        measured = term.measure(measured, own, context)  # type: ignore[attr-defined]
    return d_true.reshape(n_k, -1).T, d_measured.reshape(n_k, -1).T


def _twist(
    model: MomentumModel,
    composite: tuple[FloatArray, FloatArray],
    payload: tuple[FloatArray, FloatArray | None] | None,
    extra: FloatArray | None,
    d_extra: FloatArray | None,
    moving: FloatArray | None = None,
    d_moving: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """:func:`~estimators.models.tangents.twist_tangents` of the momentum model ``model`` for the composite's
    parameters and their derivatives ``(params10 (10,), d_params10 (K, 10))``, a payload's likewise (or ``None``), the
    extra momentum (T, 6) and its derivatives (K, T, 6) (or ``None``) and the parameters moved per sample (T, 10) and
    their derivatives (K, T, 10) (or ``None``)."""
    params10, d_params10 = composite
    n_k = d_params10.shape[0]
    first, inertia6, momentum, to_base, momentum_map = model.arm_terms(payload is not None)
    if payload is None:
        payload10, d_payload10 = np.zeros(10), np.zeros((n_k, 10))
    else:
        payload10 = payload[0]
        d_payload10 = np.zeros((n_k, 10)) if payload[1] is None else payload[1]
    c = np.ascontiguousarray
    return twist_tangents(  # type: ignore[no-any-return]
        c(params10[None], dtype=float),
        c(d_params10, dtype=float),
        c(payload10[None], dtype=float),
        c(d_payload10, dtype=float),
        payload is not None,
        c(np.zeros((1, 1, 6)) if extra is None else extra[None], dtype=float),
        c(np.zeros((n_k, 1, 6)) if d_extra is None else d_extra, dtype=float),
        extra is not None,
        c(np.zeros((1, 1, 10)) if moving is None else moving[None], dtype=float),
        c(np.zeros((n_k, 1, 10)) if d_moving is None else d_moving, dtype=float),
        moving is not None,
        model.arm_mass_kg,
        first,
        inertia6,
        momentum,
        to_base,
        momentum_map,
    )


def _slosh_twist(
    prediction: EffectPrediction,
    params: EffectParameters,
    theta: FloatArray,
    directions: tuple[NDArray[np.intp], FloatArray],
    composite: tuple[FloatArray, FloatArray],
    payload: tuple[FloatArray, FloatArray | None] | None,
    extra: FloatArray | None,
    d_extra: FloatArray | None,
) -> tuple[FloatArray, FloatArray]:
    """The twist (T, 6) with a slosh term and its derivatives (K, T, 6) along the K unknowns ``directions[0]`` (their
    steps among the k of ``directions[1]``), as :meth:`~estimators.models.effect_models.EffectPrediction._base_rate`
    computes the twist: the rest's twist, the oscillator driven by it, the twist carrying the oscillator's momentum
    and displaced mass (``composite``, ``payload``, ``d_extra``: the derivatives along the same K)."""
    slosh = prediction.slosh
    assert slosh is not None
    model = prediction.momentum_model
    columns, all_steps = directions
    n_k, step = len(columns), all_steps[columns]

    def per_fit(rows: FloatArray) -> FloatArray:
        """The rest's parameters and the oscillator's inputs for parameter vectors (P, k): (P, 10 + N_INPUTS)."""
        base10, payload10 = params.composite(rows)
        theta_base = params.base_part(rows)
        moving = slosh.moving_part(params.term_parts(rows)[slosh], theta_base)
        tank = np.ascontiguousarray(slosh.tank_of(theta_base), dtype=float)
        rest10 = base10 - _point_mass10(moving[:, 0], tank)
        return np.hstack((rest10, slosh.inputs(moving, tank, model.mean_composite10(base10, payload10))))

    points = np.repeat(theta[None], 2 * n_k, axis=0)
    index = np.arange(n_k)
    points[2 * index, columns] += step
    points[2 * index + 1, columns] -= step
    value = per_fit(theta[None])[0]
    shifted = per_fit(points)
    d_value = (shifted[0::2] - shifted[1::2]) / (2.0 * step[:, None])  # (k, 10 + N_INPUTS)
    rest_twist, d_rest_twist = _twist(model, (value[:10], d_value[:, :10]), payload, extra, d_extra)
    c = np.ascontiguousarray
    relative, d_relative, moved, d_moved = slosh_tangents(
        rest_twist, d_rest_twist, prediction.context.t_s, c(value[10:]), c(d_value[:, 10:]), slosh.has_rod
    )
    carried = -relative if extra is None else extra - relative
    d_carried = -d_relative if d_extra is None else d_extra - d_relative
    return _twist(model, composite, payload, carried, d_carried, moved, d_moved)
