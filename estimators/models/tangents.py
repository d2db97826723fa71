"""Forward-mode derivatives of the momentum model and the slosh oscillator along a log, for analytic Jacobians.

The prediction with effect terms (:class:`~estimators.models.effect_models.EffectPrediction`) goes through two
per-sample computations: the base twist from the composite's spatial inertia (:func:`twist_tangents`, the linear
solve ``M v = extra - h`` of :mod:`estimators.models.momentum_model`) and the slosh oscillator integrated along the
log (:func:`slosh_tangents`, the RK4 of :class:`~estimators.models.mass_effects.Slosh`). Each kernel here computes
the same values as the prediction and, alongside, their derivatives along ``K`` directions of the unknowns, given the
derivatives of its inputs. A Jacobian then costs one pass over the log (per direction for the slosh) instead of the
``2k`` of central differences.

* twist: ``M v = -h`` (``h`` the arm's momentum less the extra momentum) gives ``M dv = -dh - dM v``, with ``dM v =
  [dm v_lin - dh_c x omega; dh_c x v_lin + dJ omega]`` for a change ``(dm, dh_c, dJ)`` of the composite's 10 parameters;
  the same closed-form solve as the prediction's.
* slosh: the same integration (:func:`~estimators.models.slosh_dynamics.integrate_slosh`) in complex numbers, every
  input stepped by ``i h`` times its derivative (the complex step: exact derivatives of the nonlinear pendulum, its
  rod's tension included, without hand-written tangents of every RK4 stage).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimators.models.momentum_model import _add_product, composite_inverse, twist_from_inverse
from estimators.models.slosh_dynamics import cross3 as _cross
from estimators.models.slosh_dynamics import integrate_slosh
from spaceid_gym.arrays import FloatArray


@njit(cache=True)
def twist_tangents(
    params10: FloatArray,
    d_params10: FloatArray,
    payload10: FloatArray,
    d_payload10: FloatArray,
    with_payload: bool,
    extra: FloatArray,
    d_extra: FloatArray,
    with_extra: bool,
    moving: FloatArray,
    d_moving: FloatArray,
    with_moving: bool,
    arm_mass: float,
    first: FloatArray,
    inertia6: FloatArray,
    momentum: FloatArray,
    to_base: FloatArray,
    momentum_map: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """The twist (T, 6) of :meth:`~estimators.models.momentum_model.MomentumModel.predict_twist` for one parameter set
    and its derivatives (K, T, 6) along K directions.

    ``params10`` (1, 10) and ``d_params10`` (K, 10): the base's parameters and their derivatives; ``payload10``
    (1, 10), ``d_payload10`` (K, 10); ``extra`` (1, T, 6), ``d_extra`` (K, T, 6): the extra momentum; ``moving``
    (1, T, 10), ``d_moving`` (K, T, 10): parameters added per sample; each used only with its ``with_`` flag (the
    arrays may then be placeholders). The arm's terms as in the momentum model."""
    n_k, n_t = d_params10.shape[0], first.shape[0]
    out = np.empty((1, n_t, 6))
    d_out = np.empty((n_k, n_t, 6))
    j = np.empty(6)
    h = np.empty(6)
    comp = np.empty(10)
    d_comp = np.empty(10)
    rhs = np.empty(6)
    # the directions along which the payload or the extra momentum change (elsewhere their products are zero)
    payload_moves = np.array([with_payload and np.any(d_payload10[k] != 0.0) for k in range(n_k)])
    extra_moves = np.array([with_extra and np.any(d_extra[k] != 0.0) for k in range(n_k)])
    for t in range(n_t):
        # the composite and its momentum, written out as in _base_twist (a shared helper made numba's loop 2x slower)
        for c in range(10):
            comp[c] = params10[0, c]
        for c in range(6):
            h[c] = momentum[t, c]
        if with_payload:
            _add_product(comp, to_base[t], payload10[0])
            _add_product(h, momentum_map[t], payload10[0])
        if with_extra:
            for c in range(6):
                h[c] -= extra[0, t, c]
        if with_moving:
            for c in range(10):
                comp[c] += moving[0, t, c]
        for c in range(6):
            j[c] = comp[4 + c] + inertia6[t, c]
        mass, hx, hy, hz = comp[0] + arm_mass, comp[1] + first[t, 0], comp[2] + first[t, 1], comp[3] + first[t, 2]
        inverse = composite_inverse(mass, hx, hy, hz, (j[0], j[1], j[2], j[3], j[4], j[5]))
        twist_from_inverse(mass, inverse, h, out, 0, t)
        vx, vy, vz, wx, wy, wz = out[0, t, 0], out[0, t, 1], out[0, t, 2], out[0, t, 3], out[0, t, 4], out[0, t, 5]
        for k in range(n_k):
            # the change of the composite and of the momentum it carries (the arm's terms do not vary)
            for c in range(10):
                d_comp[c] = d_params10[k, c]
            for c in range(6):
                rhs[c] = 0.0
            if payload_moves[k]:
                _add_product(d_comp, to_base[t], d_payload10[k])
                _add_product(rhs, momentum_map[t], d_payload10[k])
            if extra_moves[k]:
                for c in range(6):
                    rhs[c] -= d_extra[k, t, c]
            if with_moving:
                for c in range(10):
                    d_comp[c] += d_moving[k, t, c]
            # M dv = -(dh + dM v): solved as the twist of a composite carrying -(dh + dM v)
            dm, dhx, dhy, dhz = d_comp[0], d_comp[1], d_comp[2], d_comp[3]
            jxx, jxy, jyy, jxz, jyz, jzz = d_comp[4], d_comp[5], d_comp[6], d_comp[7], d_comp[8], d_comp[9]
            p_cross = _cross(dhx, dhy, dhz, wx, wy, wz)
            l_cross = _cross(dhx, dhy, dhz, vx, vy, vz)
            rhs[0] += dm * vx - p_cross[0]
            rhs[1] += dm * vy - p_cross[1]
            rhs[2] += dm * vz - p_cross[2]
            rhs[3] += l_cross[0] + jxx * wx + jxy * wy + jxz * wz
            rhs[4] += l_cross[1] + jxy * wx + jyy * wy + jyz * wz
            rhs[5] += l_cross[2] + jxz * wx + jyz * wy + jzz * wz
            twist_from_inverse(mass, inverse, rhs, d_out, k, t)
    return out[0], d_out


#: the complex step of :func:`slosh_tangents`: ``f(x + i h d)`` has the imaginary part ``h f'(x) d`` to the last
#: bit (no difference is taken, so no cancellation), whatever small ``h``
COMPLEX_STEP = 1e-30


#: :func:`~estimators.models.slosh_dynamics.integrate_slosh` compiled with fast math for the complex steps: without it
#: every complex product checks for infinities and NaNs (C99 Annex G), which doubled the derivatives' time
_integrate_slosh_fast = njit(cache=True, fastmath=True)(integrate_slosh.py_func)


@njit(cache=True)
def slosh_tangents(
    twist: FloatArray, d_twist: FloatArray, t_s: FloatArray, inputs: FloatArray, d_inputs: FloatArray, rod: bool
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The slosh mass's relative momentum (T, 6) and displaced parameters (T, 10) of
    :func:`~estimators.models.slosh_dynamics.integrate_slosh` for one parameter set, and their derivatives (K, T, 6)
    and (K, T, 10) along K directions, from the rest's twist (T, 6) and its derivatives (K, T, 6) and the inputs
    (:data:`~estimators.models.slosh_dynamics.N_INPUTS`,) and their derivatives (K, N_INPUTS): each direction is one
    integration in complex numbers along :data:`COMPLEX_STEP`."""
    n_k, n_t = d_twist.shape[0], twist.shape[0]
    out, moved = np.zeros((n_t, 6)), np.zeros((n_t, 10))
    integrate_slosh(twist, t_s, inputs, rod, out, moved, np.empty((2 * n_t + 9, 9)))
    d_out, d_moved = np.zeros((n_k, n_t, 6)), np.zeros((n_k, n_t, 10))
    c_out, c_moved = np.zeros((n_t, 6), dtype=np.complex128), np.zeros((n_t, 10), dtype=np.complex128)
    c_work = np.empty((2 * n_t + 9, 9), dtype=np.complex128)
    h = COMPLEX_STEP
    for q in range(n_k):
        _integrate_slosh_fast(twist + 1j * h * d_twist[q], t_s, inputs + 1j * h * d_inputs[q], rod, c_out, c_moved, c_work)
        d_out[q] = c_out.imag / h
        d_moved[q] = c_moved.imag / h
    return out, d_out, moved, d_moved
