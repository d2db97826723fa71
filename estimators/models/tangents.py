"""Forward-mode derivatives of the momentum model and the slosh oscillator along a log, for analytic Jacobians.

The prediction with effect terms (:class:`~estimators.models.effect_models.EffectPrediction`) goes through two
per-sample computations: the base twist from the composite's spatial inertia (:func:`twist_tangents`, the linear
solve ``M v = extra - h`` of :mod:`estimators.models.momentum_model`) and the slosh oscillator integrated along the
log (:func:`slosh_tangents`, the RK4 of :class:`~estimators.models.mass_effects.Slosh`). Each kernel here computes
the same values as the prediction and, alongside, their derivatives along ``K`` directions of the unknowns, given the
derivatives of its inputs. A Jacobian then costs one pass over the log instead of the ``2k`` of central differences.

* twist: ``M v = -h`` (``h`` the arm's momentum less the extra momentum) gives ``M dv = -dh - dM v``, with ``dM v =
  [dm v_lin - dh_c x omega; dh_c x v_lin + dJ omega]`` for a change ``(dm, dh_c, dJ)`` of the composite's 10 parameters;
  the same closed-form solve as the prediction's.
* slosh: RK4 of the oscillator and of its tangents, each stage's derivative written out (:func:`_slope_tangent`:
  the spring, the rotating frame's terms, the pendulum rod's restoring force and tension); the tank's forcing and the
  momentum and displaced parameters formed from the state, cheap stages, by complex steps. The test holds it to the
  whole integration run in complex numbers to 1e-10.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimators.models.momentum_model import _add_product, composite_inverse, twist_from_inverse
from estimators.models.slosh_dynamics import cross3 as _cross
from estimators.models.slosh_dynamics import frame_terms, slosh_outputs, tank_forcing
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


#: the complex step of the slosh's cheap stages in :func:`slosh_tangents` (the tank's forcing, the momentum and
#: displaced parameters from the state): ``f(x + i h d)`` has the imaginary part ``h f'(x) d`` to the last bit (no
#: difference is taken, so no cancellation), whatever small ``h``
COMPLEX_STEP = 1e-30


#: the rows of :func:`_slope_tangent`'s scratch (8, 3), indexed rather than taken as views (a view per stage cost its
#: reference counts, 5 % of the kernel): the spring and damper's force ``f``, ``C f - b``, the rod's direction ``n``,
#: ``C n``, and the derivatives of each along a direction
_F, _ACC, _N, _CN, _DF, _DACC, _DN, _DCN = 0, 1, 2, 3, 4, 5, 6, 7


@njit(cache=True, inline="always")
def _slope_tangent(
    point: FloatArray,
    d_point: FloatArray,
    step: FloatArray,
    d_step: FloatArray,
    row: int,
    inputs: FloatArray,
    d_inputs: FloatArray,
    coupling: FloatArray,
    d_coupling: FloatArray,
    axis: FloatArray,
    rod: bool,
    slopes: FloatArray,
    d_slopes: FloatArray,
    s: int,
    work: FloatArray,
    moves: FloatArray,
) -> None:
    """``slopes[s]`` = the slope of :func:`~estimators.models.slosh_dynamics.slosh_slope` at ``point`` (6,) for the forcing
    ``step[row]`` (9,) and the inputs (N_INPUTS,; their ``coupling`` (3, 3) and ``axis`` (3,) given), and
    ``d_slopes[:, s]`` its derivatives along K directions from those of ``point`` (K, 6), ``step`` (K, 3, 9), the
    inputs (K, N_INPUTS) and the coupling (K, 3, 3): the slope's forward-mode derivative written out (the spring, the
    frame's terms, the rod's restoring force and tension). ``work`` (8, 3) is scratch (rows :data:`_F` to :data:`_DCN`).
    ``moves[q]`` (K,) is false for a direction along which the forcing and the coupling do not change (the
    oscillator's own frequency, damping and rod): their terms are skipped."""
    omega_n, zeta, kappa = inputs[4], inputs[5], inputs[6]
    stiff, damp = omega_n * omega_n, 2.0 * zeta * omega_n
    wx, wy, wz = step[row, 3], step[row, 4], step[row, 5]
    w_x = _cross(wx, wy, wz, point[0], point[1], point[2])
    ax = axis[0] * point[0] + axis[1] * point[1] + axis[2] * point[2]
    for c in range(3):
        spring = point[c] + ax * axis[c] + kappa * ax * point[c] if rod else point[c]
        work[_F, c] = -stiff * spring - damp * point[3 + c]
    g = frame_terms(
        (wx, wy, wz, step[row, 6], step[row, 7], step[row, 8]), (point[0], point[1], point[2]), (point[3], point[4], point[5])
    )
    for c in range(3):  # C f - b, before the rod's tension
        work[_ACC, c] = (
            coupling[c, 0] * work[_F, 0] + coupling[c, 1] * work[_F, 1] + coupling[c, 2] * work[_F, 2] - (step[row, c] + g[c])
        )
        work[_N, c] = axis[c] + kappa * point[c]
    for c in range(3):
        work[_CN, c] = coupling[c, 0] * work[_N, 0] + coupling[c, 1] * work[_N, 1] + coupling[c, 2] * work[_N, 2]
    den = work[_N, 0] * work[_CN, 0] + work[_N, 1] * work[_CN, 1] + work[_N, 2] * work[_CN, 2]
    vv = point[3] * point[3] + point[4] * point[4] + point[5] * point[5]
    tension = (
        (work[_N, 0] * work[_ACC, 0] + work[_N, 1] * work[_ACC, 1] + work[_N, 2] * work[_ACC, 2] + kappa * vv) / den
        if rod
        else 0.0
    )
    for c in range(3):  # the slope itself, as slosh_slope has it (the test holds the two to the same values)
        slopes[s, c] = point[3 + c]
        slopes[s, 3 + c] = work[_ACC, c] - tension * work[_CN, c]
    for q in range(d_point.shape[0]):
        dx0, dx1, dx2 = d_point[q, 0], d_point[q, 1], d_point[q, 2]
        dv0, dv1, dv2 = d_point[q, 3], d_point[q, 4], d_point[q, 5]
        d_omega_n, d_zeta, d_kappa = d_inputs[q, 4], d_inputs[q, 5], d_inputs[q, 6]
        d_stiff, d_damp = 2.0 * omega_n * d_omega_n, 2.0 * (d_zeta * omega_n + zeta * d_omega_n)
        da0, da1, da2 = d_inputs[q, 16], d_inputs[q, 17], d_inputs[q, 18]
        d_ax = da0 * point[0] + da1 * point[1] + da2 * point[2] + axis[0] * dx0 + axis[1] * dx1 + axis[2] * dx2
        for c in range(3):
            dxc = d_point[q, c]
            if rod:
                spring = point[c] + ax * axis[c] + kappa * ax * point[c]
                d_axis_c = d_inputs[q, 16 + c]
                d_spring = dxc + d_ax * axis[c] + ax * d_axis_c + (d_kappa * ax + kappa * d_ax) * point[c] + kappa * ax * dxc
            else:
                spring, d_spring = point[c], dxc
            work[_DF, c] = -d_stiff * spring - stiff * d_spring - d_damp * point[3 + c] - damp * d_point[q, 3 + c]
        # d g = 2 (dw x x' + w x dx') + d(dw/dt) x x + dw/dt x dx + dw x (w x x) + w x (dw x x + w x dx)
        e2 = _cross(wx, wy, wz, dv0, dv1, dv2)
        e4 = _cross(step[row, 6], step[row, 7], step[row, 8], dx0, dx1, dx2)
        inner = _cross(wx, wy, wz, dx0, dx1, dx2)
        e6 = _cross(wx, wy, wz, inner[0], inner[1], inner[2])
        for c in range(3):
            dg = 2.0 * e2[c] + e4[c] + e6[c]
            work[_DACC, c] = coupling[c, 0] * work[_DF, 0] + coupling[c, 1] * work[_DF, 1] + coupling[c, 2] * work[_DF, 2] - dg
            d_slopes[q, s, c] = d_point[q, 3 + c]
        if moves[q]:  # the forcing's and the coupling's own changes
            dwx, dwy, dwz = d_step[q, row, 3], d_step[q, row, 4], d_step[q, row, 5]
            e1 = _cross(dwx, dwy, dwz, point[3], point[4], point[5])
            e3 = _cross(d_step[q, row, 6], d_step[q, row, 7], d_step[q, row, 8], point[0], point[1], point[2])
            e5 = _cross(dwx, dwy, dwz, w_x[0], w_x[1], w_x[2])
            inner = _cross(dwx, dwy, dwz, point[0], point[1], point[2])
            e7 = _cross(wx, wy, wz, inner[0], inner[1], inner[2])
            for c in range(3):
                work[_DACC, c] += (
                    d_coupling[q, c, 0] * work[_F, 0] + d_coupling[q, c, 1] * work[_F, 1] + d_coupling[q, c, 2] * work[_F, 2]
                    - (d_step[q, row, c] + 2.0 * e1[c] + e3[c] + e5[c] + e7[c])
                )  # fmt: skip
        for c in range(3):
            d_slopes[q, s, 3 + c] = work[_DACC, c]
        if rod:
            for c in range(3):
                work[_DN, c] = d_inputs[q, 16 + c] + d_kappa * point[c] + kappa * d_point[q, c]
            d_num = d_kappa * vv + 2.0 * kappa * (point[3] * dv0 + point[4] * dv1 + point[5] * dv2)
            d_den = 0.0
            for c in range(3):
                work[_DCN, c] = coupling[c, 0] * work[_DN, 0] + coupling[c, 1] * work[_DN, 1] + coupling[c, 2] * work[_DN, 2]
                if moves[q]:
                    work[_DCN, c] += (
                        d_coupling[q, c, 0] * work[_N, 0] + d_coupling[q, c, 1] * work[_N, 1] + d_coupling[q, c, 2] * work[_N, 2]
                    )
                d_num += work[_DN, c] * work[_ACC, c] + work[_N, c] * work[_DACC, c]
            for c in range(3):
                d_den += work[_DN, c] * work[_CN, c] + work[_N, c] * work[_DCN, c]
            d_tension = (d_num - tension * d_den) / den
            for c in range(3):
                d_slopes[q, s, 3 + c] -= d_tension * work[_CN, c] + tension * work[_DCN, c]


@njit(cache=True)
def slosh_tangents(
    twist: FloatArray, d_twist: FloatArray, t_s: FloatArray, inputs: FloatArray, d_inputs: FloatArray, rod: bool
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The slosh mass's relative momentum (T, 6) and displaced parameters (T, 10) of
    :func:`~estimators.models.slosh_dynamics.integrate_slosh` for one parameter set, and their derivatives (K, T, 6)
    and (K, T, 10) along K directions, from the rest's twist (T, 6) and its derivatives (K, T, 6) and the inputs
    (:data:`~estimators.models.slosh_dynamics.N_INPUTS`,) and their derivatives (K, N_INPUTS): RK4 of the oscillator
    and of its tangents (:func:`_slope_tangent`), the forcing's and the outputs' derivatives by complex steps."""
    n_k, n_t = d_twist.shape[0], twist.shape[0]
    h = COMPLEX_STEP
    tank, mass, coupling, axis = inputs[0:3], inputs[3], inputs[7:16].reshape(3, 3), inputs[16:19]
    d_coupling = np.ascontiguousarray(d_inputs[:, 7:16]).reshape(n_k, 3, 3)
    work = np.empty((8, 3))
    forcing, d_forcing = np.empty((n_t, 9)), np.empty((n_k, n_t, 9))
    c_forcing = np.empty((n_t, 9), dtype=np.complex128)
    for k in range(n_t):
        tank_forcing(twist, t_s, tank, k, forcing)
    moves = np.zeros(n_k, dtype=np.bool_)  # whether the forcing or the coupling changes along a direction
    for q in range(n_k):
        moves[q] = np.any(d_twist[q] != 0.0) or np.any(d_inputs[q, 0:3] != 0.0) or np.any(d_inputs[q, 7:16] != 0.0)
        if not moves[q]:
            d_forcing[q] = 0.0
            continue
        c_twist, c_tank = twist + 1j * h * d_twist[q], tank + 1j * h * d_inputs[q, 0:3]
        for k in range(n_t):
            tank_forcing(c_twist, t_s, c_tank, k, c_forcing)
        d_forcing[q] = c_forcing.imag / h
    state, stage, slopes, step = np.zeros(6), np.empty(6), np.empty((4, 6)), np.empty((3, 9))
    d_state, d_stage = np.zeros((n_k, 6)), np.empty((n_k, 6))
    d_slopes, d_step = np.empty((n_k, 4, 6)), np.empty((n_k, 3, 9))
    states, d_states = np.zeros((n_t, 6)), np.zeros((n_k, n_t, 6))
    for k in range(1, n_t):
        dt = t_s[k] - t_s[k - 1]
        for i in range(9):
            step[0, i], step[2, i] = forcing[k - 1, i], forcing[k, i]
            step[1, i] = 0.5 * (step[0, i] + step[2, i])
            for q in range(n_k):
                d_step[q, 0, i], d_step[q, 2, i] = d_forcing[q, k - 1, i], d_forcing[q, k, i]
                d_step[q, 1, i] = 0.5 * (d_step[q, 0, i] + d_step[q, 2, i])
        for s in range(4):  # RK4 stages: the step's start, its middle twice, its end
            fraction = 0.0 if s == 0 else (1.0 if s == 3 else 0.5)
            for i in range(6):
                stage[i] = state[i] + fraction * dt * slopes[s - 1, i] if s > 0 else state[i]
                for q in range(n_k):
                    d_stage[q, i] = d_state[q, i] + fraction * dt * d_slopes[q, s - 1, i] if s > 0 else d_state[q, i]
            row = 0 if s == 0 else (1 if s < 3 else 2)
            _slope_tangent(
                stage, d_stage, step, d_step, row, inputs, d_inputs, coupling, d_coupling, axis, rod, slopes, d_slopes, s, work,
                moves,
            )  # fmt: skip
        for i in range(6):
            state[i] += (dt / 6.0) * (slopes[0, i] + 2.0 * slopes[1, i] + 2.0 * slopes[2, i] + slopes[3, i])
            states[k, i] = state[i]
            for q in range(n_k):
                d_state[q, i] += (dt / 6.0) * (
                    d_slopes[q, 0, i] + 2.0 * d_slopes[q, 1, i] + 2.0 * d_slopes[q, 2, i] + d_slopes[q, 3, i]
                )
                d_states[q, k, i] = d_state[q, i]
    out, moved = np.zeros((n_t, 6)), np.zeros((n_t, 10))
    slosh_outputs(states, tank, mass, out, moved)
    d_out, d_moved = np.zeros((n_k, n_t, 6)), np.zeros((n_k, n_t, 10))
    c_out, c_moved = np.zeros((n_t, 6), dtype=np.complex128), np.zeros((n_t, 10), dtype=np.complex128)
    for q in range(n_k):
        c_states = states + 1j * h * d_states[q]
        slosh_outputs(c_states, tank + 1j * h * d_inputs[q, 0:3], mass + 1j * h * d_inputs[q, 3], c_out, c_moved)
        d_out[q] = c_out.imag / h
        d_moved[q] = c_moved.imag / h
    return out, d_out, moved, d_moved
