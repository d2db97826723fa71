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
* slosh: the tangent of every RK4 stage (the oscillator's coupling, stiffness, damping and forcing all vary), of the
  tank's acceleration from the rest's twist and its central time differences, and of the momentum and displaced
  parameters formed from the state.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimators.models.mass_effects import _cross, frame_terms
from estimators.models.momentum_model import _add_product, composite_inverse, twist_from_inverse
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


@njit(cache=True, inline="always")
def _slope_and_tangent(
    coupling: FloatArray,
    d_coupling: FloatArray,
    stiff: float,
    damp: float,
    d_stiff: FloatArray,
    d_damp: FloatArray,
    point: FloatArray,
    d_point: FloatArray,
    force: FloatArray,
    d_force: FloatArray,
    row: int,
    slopes: FloatArray,
    d_slopes: FloatArray,
    s: int,
    spin: FloatArray,
    d_spin: FloatArray,
    projector: FloatArray,
    d_projector: FloatArray,
) -> None:
    """``slopes[s]`` = ``[x'; -A (stiff x + damp x') - f - Pi g]`` at ``point`` = ``[x; x']`` (6,) (the slosh
    oscillator's derivative, ``A = coupling`` (3, 3), ``f = force[row]``, ``Pi = projector`` (3, 3), ``g`` the base
    frame's terms of :func:`~estimators.models.mass_effects.frame_terms` for ``spin[row]``) and ``d_slopes[:, s]`` its
    derivatives along K directions from those of ``point`` (K, 6), ``coupling`` (K, 3, 3), ``stiff`` and ``damp``
    (K,), ``force`` (K, 3, 3), ``spin`` (K, 3, 6) and ``projector`` (K, 3, 3)."""
    s0 = stiff * point[0] + damp * point[3]
    s1 = stiff * point[1] + damp * point[4]
    s2 = stiff * point[2] + damp * point[5]
    g = frame_terms(spin, row, point)
    for c in range(3):
        slopes[s, c] = point[3 + c]
        slopes[s, 3 + c] = (
            -(coupling[c, 0] * s0 + coupling[c, 1] * s1 + coupling[c, 2] * s2)
            - force[row, c]
            - (projector[c, 0] * g[0] + projector[c, 1] * g[1] + projector[c, 2] * g[2])
        )
    wx, wy, wz = spin[row, 0], spin[row, 1], spin[row, 2]
    w_x = _cross(wx, wy, wz, point[0], point[1], point[2])
    for k in range(d_point.shape[0]):
        dp = d_point[k]
        dw = d_spin[k, row]
        # d g = 2 (dw x x' + w x dx') + d(dw/dt) x x + dw/dt x dx + dw x (w x x) + w x (dw x x + w x dx)
        e1 = _cross(dw[0], dw[1], dw[2], point[3], point[4], point[5])
        e2 = _cross(wx, wy, wz, dp[3], dp[4], dp[5])
        e3 = _cross(dw[3], dw[4], dw[5], point[0], point[1], point[2])
        e4 = _cross(spin[row, 3], spin[row, 4], spin[row, 5], dp[0], dp[1], dp[2])
        e5 = _cross(dw[0], dw[1], dw[2], w_x[0], w_x[1], w_x[2])
        inner = _cross(dw[0], dw[1], dw[2], point[0], point[1], point[2])
        inner2 = _cross(wx, wy, wz, dp[0], dp[1], dp[2])
        e6 = _cross(wx, wy, wz, inner[0] + inner2[0], inner[1] + inner2[1], inner[2] + inner2[2])
        dg0 = 2.0 * (e1[0] + e2[0]) + e3[0] + e4[0] + e5[0] + e6[0]
        dg1 = 2.0 * (e1[1] + e2[1]) + e3[1] + e4[1] + e5[1] + e6[1]
        dg2 = 2.0 * (e1[2] + e2[2]) + e3[2] + e4[2] + e5[2] + e6[2]
        for c in range(3):
            d_slopes[k, s, 3 + c] = -(
                d_projector[k, c, 0] * g[0]
                + d_projector[k, c, 1] * g[1]
                + d_projector[k, c, 2] * g[2]
                + projector[c, 0] * dg0
                + projector[c, 1] * dg1
                + projector[c, 2] * dg2
            )
    for k in range(d_point.shape[0]):
        ds0 = d_stiff[k] * point[0] + stiff * d_point[k, 0] + d_damp[k] * point[3] + damp * d_point[k, 3]
        ds1 = d_stiff[k] * point[1] + stiff * d_point[k, 1] + d_damp[k] * point[4] + damp * d_point[k, 4]
        ds2 = d_stiff[k] * point[2] + stiff * d_point[k, 2] + d_damp[k] * point[5] + damp * d_point[k, 5]
        for c in range(3):
            d_slopes[k, s, c] = d_point[k, 3 + c]
            d_slopes[k, s, 3 + c] += (
                -(d_coupling[k, c, 0] * s0 + d_coupling[k, c, 1] * s1 + d_coupling[k, c, 2] * s2)
                - (coupling[c, 0] * ds0 + coupling[c, 1] * ds1 + coupling[c, 2] * ds2)
                - d_force[k, row, c]
            )


@njit(cache=True)
def slosh_tangents(
    twist: FloatArray,
    d_twist: FloatArray,
    t_s: FloatArray,
    tank: FloatArray,
    d_tank: FloatArray,
    mass: float,
    d_mass: FloatArray,
    omega_n: float,
    d_omega_n: FloatArray,
    zeta: float,
    d_zeta: FloatArray,
    coupling: FloatArray,
    d_coupling: FloatArray,
    projector: FloatArray,
    d_projector: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The slosh mass's relative momentum (T, 6) and displaced parameters (T, 10) of
    :func:`~estimators.models.mass_effects._slosh_momentum` for one parameter set, and their derivatives (K, T, 6) and
    (K, T, 10) along K directions, from the rest's twist (T, 6) and its derivatives (K, T, 6) and the derivatives of
    the tank (K, 3), the mass, natural frequency (rad/s) and damping ratio (K,), the projected coupling and the
    projector (K, 3, 3)."""
    n_k, n_t = d_twist.shape[0], twist.shape[0]
    out = np.zeros((n_t, 6))
    d_out = np.zeros((n_k, n_t, 6))
    moved = np.zeros((n_t, 10))
    d_moved = np.zeros((n_k, n_t, 10))
    accel = np.empty((n_t, 3))
    d_accel = np.empty((n_k, n_t, 3))
    rates = np.empty((n_t, 6))  # [omega; domega/dt] per sample and their derivatives
    d_rates = np.empty((n_k, n_t, 6))
    free = np.empty(3)
    d_free = np.empty(3)
    rx, ry, rz = tank[0], tank[1], tank[2]
    for k in range(n_t):
        lo, hi = max(k - 1, 0), min(k + 1, n_t - 1)
        inv = 1.0 / (t_s[hi] - t_s[lo])
        vx, vy, vz, wx, wy, wz = twist[k, 0], twist[k, 1], twist[k, 2], twist[k, 3], twist[k, 4], twist[k, 5]
        dwx = (twist[hi, 3] - twist[lo, 3]) * inv
        dwy = (twist[hi, 4] - twist[lo, 4]) * inv
        dwz = (twist[hi, 5] - twist[lo, 5]) * inv
        a1 = _cross(wx, wy, wz, vx, vy, vz)
        a2 = _cross(dwx, dwy, dwz, rx, ry, rz)
        wr = _cross(wx, wy, wz, rx, ry, rz)
        a3 = _cross(wx, wy, wz, wr[0], wr[1], wr[2])
        for c in range(3):
            free[c] = (twist[hi, c] - twist[lo, c]) * inv + a1[c] + a2[c] + a3[c]
        for c in range(3):
            accel[k, c] = projector[c, 0] * free[0] + projector[c, 1] * free[1] + projector[c, 2] * free[2]
        rates[k, 0], rates[k, 1], rates[k, 2], rates[k, 3], rates[k, 4], rates[k, 5] = wx, wy, wz, dwx, dwy, dwz
        for q in range(n_k):
            tv = d_twist[q, k]
            drx, dry, drz = d_tank[q, 0], d_tank[q, 1], d_tank[q, 2]
            ddwx = (d_twist[q, hi, 3] - d_twist[q, lo, 3]) * inv
            ddwy = (d_twist[q, hi, 4] - d_twist[q, lo, 4]) * inv
            ddwz = (d_twist[q, hi, 5] - d_twist[q, lo, 5]) * inv
            d_rates[q, k, 0], d_rates[q, k, 1], d_rates[q, k, 2] = tv[3], tv[4], tv[5]
            d_rates[q, k, 3], d_rates[q, k, 4], d_rates[q, k, 5] = ddwx, ddwy, ddwz
            b1 = _cross(tv[3], tv[4], tv[5], vx, vy, vz)
            b2 = _cross(wx, wy, wz, tv[0], tv[1], tv[2])
            b3 = _cross(ddwx, ddwy, ddwz, rx, ry, rz)
            b4 = _cross(dwx, dwy, dwz, drx, dry, drz)
            d_wr = _cross(tv[3], tv[4], tv[5], rx, ry, rz)
            d_wr2 = _cross(wx, wy, wz, drx, dry, drz)
            b5 = _cross(tv[3], tv[4], tv[5], wr[0], wr[1], wr[2])
            b6 = _cross(wx, wy, wz, d_wr[0] + d_wr2[0], d_wr[1] + d_wr2[1], d_wr[2] + d_wr2[2])
            for c in range(3):
                d_free[c] = (d_twist[q, hi, c] - d_twist[q, lo, c]) * inv + b1[c] + b2[c] + b3[c] + b4[c] + b5[c] + b6[c]
            for c in range(3):
                d_accel[q, k, c] = (
                    d_projector[q, c, 0] * free[0]
                    + d_projector[q, c, 1] * free[1]
                    + d_projector[q, c, 2] * free[2]
                    + projector[c, 0] * d_free[0]
                    + projector[c, 1] * d_free[1]
                    + projector[c, 2] * d_free[2]
                )
    stiff, damp = omega_n**2, 2.0 * zeta * omega_n
    d_stiff = 2.0 * omega_n * d_omega_n
    d_damp = 2.0 * (d_zeta * omega_n + zeta * d_omega_n)
    state, stage, slopes, force = np.zeros(6), np.empty(6), np.empty((4, 6)), np.empty((3, 3))
    d_state, d_stage, d_slopes, d_force = np.zeros((n_k, 6)), np.empty((n_k, 6)), np.empty((n_k, 4, 6)), np.empty((n_k, 3, 3))
    spin, d_spin = np.empty((3, 6)), np.empty((n_k, 3, 6))
    states = np.zeros((n_t, 6))
    d_states = np.zeros((n_k, n_t, 6))
    for k in range(1, n_t):
        h = t_s[k] - t_s[k - 1]
        for c in range(3):
            force[0, c], force[2, c] = accel[k - 1, c], accel[k, c]
            force[1, c] = 0.5 * (force[0, c] + force[2, c])
            for q in range(n_k):
                d_force[q, 0, c], d_force[q, 2, c] = d_accel[q, k - 1, c], d_accel[q, k, c]
                d_force[q, 1, c] = 0.5 * (d_force[q, 0, c] + d_force[q, 2, c])
        for c in range(6):
            spin[0, c], spin[2, c] = rates[k - 1, c], rates[k, c]
            spin[1, c] = 0.5 * (spin[0, c] + spin[2, c])
            for q in range(n_k):
                d_spin[q, 0, c], d_spin[q, 2, c] = d_rates[q, k - 1, c], d_rates[q, k, c]
                d_spin[q, 1, c] = 0.5 * (d_spin[q, 0, c] + d_spin[q, 2, c])
        for s in range(4):  # RK4 stages: the step's start, its middle twice, its end
            if s > 0:
                fraction = 1.0 if s == 3 else 0.5
                for i in range(6):
                    stage[i] = state[i] + fraction * h * slopes[s - 1, i]
                    for q in range(n_k):
                        d_stage[q, i] = d_state[q, i] + fraction * h * d_slopes[q, s - 1, i]
            else:
                stage[:] = state
                d_stage[:] = d_state
            row = 0 if s == 0 else (1 if s < 3 else 2)
            _slope_and_tangent(
                coupling, d_coupling, stiff, damp, d_stiff, d_damp, stage, d_stage, force, d_force, row, slopes, d_slopes, s,
                spin, d_spin, projector, d_projector,
            )  # fmt: skip
        for i in range(6):
            state[i] = state[i] + (h / 6.0) * (slopes[0, i] + 2.0 * slopes[1, i] + 2.0 * slopes[2, i] + slopes[3, i])
            states[k, i] = state[i]
            for q in range(n_k):
                d_state[q, i] = d_state[q, i] + (h / 6.0) * (
                    d_slopes[q, 0, i] + 2.0 * d_slopes[q, 1, i] + 2.0 * d_slopes[q, 2, i] + d_slopes[q, 3, i]
                )
                d_states[q, k, i] = d_state[q, i]
    m = mass
    for k in range(n_t):
        x0, x1, x2, v0, v1, v2 = states[k, 0], states[k, 1], states[k, 2], states[k, 3], states[k, 4], states[k, 5]
        px, py, pz = rx + x0, ry + x1, rz + x2
        ang = _cross(px, py, pz, v0, v1, v2)
        out[k, 0], out[k, 1], out[k, 2] = m * v0, m * v1, m * v2
        out[k, 3], out[k, 4], out[k, 5] = m * ang[0], m * ang[1], m * ang[2]
        moved[k, 1], moved[k, 2], moved[k, 3] = m * x0, m * x1, m * x2
        moved[k, 4] = m * ((py * py + pz * pz) - (ry * ry + rz * rz))
        moved[k, 5] = -m * (px * py - rx * ry)
        moved[k, 6] = m * ((px * px + pz * pz) - (rx * rx + rz * rz))
        moved[k, 7] = -m * (px * pz - rx * rz)
        moved[k, 8] = -m * (py * pz - ry * rz)
        moved[k, 9] = m * ((px * px + py * py) - (rx * rx + ry * ry))
        for q in range(n_k):
            ds = d_states[q, k]
            dm = d_mass[q]
            drx, dry, drz = d_tank[q, 0], d_tank[q, 1], d_tank[q, 2]
            dpx, dpy, dpz = drx + ds[0], dry + ds[1], drz + ds[2]
            d_ang1 = _cross(dpx, dpy, dpz, v0, v1, v2)
            d_ang2 = _cross(px, py, pz, ds[3], ds[4], ds[5])
            for c in range(3):
                d_out[q, k, c] = dm * states[k, 3 + c] + m * ds[3 + c]
                d_out[q, k, 3 + c] = dm * ang[c] + m * (d_ang1[c] + d_ang2[c])
                d_moved[q, k, 1 + c] = dm * states[k, c] + m * ds[c]
            d_moved[q, k, 4] = dm * ((py * py + pz * pz) - (ry * ry + rz * rz)) + 2.0 * m * (
                (py * dpy + pz * dpz) - (ry * dry + rz * drz)
            )
            d_moved[q, k, 5] = -dm * (px * py - rx * ry) - m * ((dpx * py + px * dpy) - (drx * ry + rx * dry))
            d_moved[q, k, 6] = dm * ((px * px + pz * pz) - (rx * rx + rz * rz)) + 2.0 * m * (
                (px * dpx + pz * dpz) - (rx * drx + rz * drz)
            )
            d_moved[q, k, 7] = -dm * (px * pz - rx * rz) - m * ((dpx * pz + px * dpz) - (drx * rz + rx * drz))
            d_moved[q, k, 8] = -dm * (py * pz - ry * rz) - m * ((dpy * pz + py * dpz) - (dry * rz + ry * drz))
            d_moved[q, k, 9] = dm * ((px * px + py * py) - (rx * rx + ry * ry)) + 2.0 * m * (
                (px * dpx + py * dpy) - (rx * drx + ry * dry)
            )
    return out, d_out, moved, d_moved
