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
from estimators.models.slosh_dynamics import check_times, frame_terms, slosh_outputs, tank_forcing
from estimators.models.slosh_dynamics import cross3 as _cross
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
    arrays may then be placeholders). The arm's terms as in the momentum model: ``first`` (T, 3), ``inertia6`` (T, 6),
    ``momentum`` (T, 6), ``to_base`` (T, 10, 10) carries the payload's 10 parameters into the composite's,
    ``momentum_map`` (T, 6, 10) into the momentum. The loops below are written for these sizes: each array used
    is checked against them (a wrong size raises ``ValueError`` rather than reading past an array's end)."""
    n_k, n_t = d_params10.shape[0], first.shape[0]
    if params10.shape[1] != 10 or d_params10.shape[1] != 10:
        raise ValueError("twist_tangents: the parameter sets must hold the 10 inertial parameters")
    if inertia6.shape[0] != n_t or momentum.shape[0] != n_t:
        raise ValueError("twist_tangents: the arm's terms must have one row per sample")
    if with_payload and (
        payload10.shape[1] != 10
        or d_payload10.shape[0] != n_k
        or d_payload10.shape[1] != 10
        or to_base.shape[0] != n_t
        or to_base.shape[1] != 10
        or to_base.shape[2] != 10
        or momentum_map.shape[0] != n_t
        or momentum_map.shape[1] != 6
        or momentum_map.shape[2] != 10
    ):
        raise ValueError("twist_tangents: the payload must be (1, 10), (K, 10), to_base (T, 10, 10), momentum_map (T, 6, 10)")
    if with_extra and (extra.shape[1] != n_t or d_extra.shape[0] != n_k or d_extra.shape[1] != n_t):
        raise ValueError("twist_tangents: the extra momentum must be (1, T, 6) and (K, T, 6)")
    if with_moving and (moving.shape[1] != n_t or d_moving.shape[0] != n_k or d_moving.shape[1] != n_t):
        raise ValueError("twist_tangents: the moved parameters must be (1, T, 10) and (K, T, 10)")
    out = np.empty((1, n_t, 6))
    # the directions side by side, a lane each (the last axis): every direction's derivative is computed by the same
    # operations in the same order as one at a time, and the compiler vectorises them (25 % faster than a loop over
    # the directions per sample, the same numbers to the last bit)
    d_lanes = np.empty((n_t, 6, n_k))
    j = np.empty(6)
    h = np.empty(6)
    comp = np.empty(10)
    d_comp = np.empty((10, n_k))
    rhs = np.empty((6, n_k))
    d_base = np.ascontiguousarray(d_params10.T)
    d_payload = np.ascontiguousarray(d_payload10.T)
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
        cx, cy, cz, c00, c01, c02, c11, c12, c22, inv_det = inverse
        # the change of the composite and of the momentum it carries (the arm's terms do not vary)
        for c in range(10):
            for k in range(n_k):
                d_comp[c, k] = d_base[c, k]
        for c in range(6):
            for k in range(n_k):
                rhs[c, k] = 0.0
        for k in range(n_k):
            if payload_moves[k]:  # _add_product's sums, per direction
                for r in range(10):
                    total = 0.0
                    for c in range(10):
                        total += to_base[t, r, c] * d_payload[c, k]
                    d_comp[r, k] += total
                for r in range(6):
                    total = 0.0
                    for c in range(10):
                        total += momentum_map[t, r, c] * d_payload[c, k]
                    rhs[r, k] += total
            if extra_moves[k]:
                for c in range(6):
                    rhs[c, k] -= d_extra[k, t, c]
        if with_moving:
            for c in range(10):
                for k in range(n_k):
                    d_comp[c, k] += d_moving[k, t, c]
        for k in range(n_k):
            # M dv = -(dh + dM v): solved as the twist of a composite carrying -(dh + dM v) (twist_from_inverse's
            # arithmetic, written out on the lanes)
            dm, dhx, dhy, dhz = d_comp[0, k], d_comp[1, k], d_comp[2, k], d_comp[3, k]
            jxx, jxy, jyy, jxz, jyz, jzz = d_comp[4, k], d_comp[5, k], d_comp[6, k], d_comp[7, k], d_comp[8, k], d_comp[9, k]
            p_cross = _cross(dhx, dhy, dhz, wx, wy, wz)
            l_cross = _cross(dhx, dhy, dhz, vx, vy, vz)
            m0 = rhs[0, k] + (dm * vx - p_cross[0])
            m1 = rhs[1, k] + (dm * vy - p_cross[1])
            m2 = rhs[2, k] + (dm * vz - p_cross[2])
            m3 = rhs[3, k] + (l_cross[0] + jxx * wx + jxy * wy + jxz * wz)
            m4 = rhs[4, k] + (l_cross[1] + jxy * wx + jyy * wy + jyz * wz)
            m5 = rhs[5, k] + (l_cross[2] + jxz * wx + jyz * wy + jzz * wz)
            rx = -(m3 - (cy * m2 - cz * m1))
            ry = -(m4 - (cz * m0 - cx * m2))
            rz = -(m5 - (cx * m1 - cy * m0))
            ox = (c00 * rx + c01 * ry + c02 * rz) * inv_det
            oy = (c01 * rx + c11 * ry + c12 * rz) * inv_det
            oz = (c02 * rx + c12 * ry + c22 * rz) * inv_det
            d_lanes[t, 0, k] = -m0 / mass - (oy * cz - oz * cy)
            d_lanes[t, 1, k] = -m1 / mass - (oz * cx - ox * cz)
            d_lanes[t, 2, k] = -m2 / mass - (ox * cy - oy * cx)
            d_lanes[t, 3, k], d_lanes[t, 4, k], d_lanes[t, 5, k] = ox, oy, oz
    return out[0], np.ascontiguousarray(d_lanes.transpose(2, 0, 1))


#: the complex step of the slosh's cheap stages in :func:`slosh_tangents` (the tank's forcing, the momentum and
#: displaced parameters from the state): ``f(x + i h d)`` has the imaginary part ``h f'(x) d`` to the last bit (no
#: difference is taken, so no cancellation), whatever small ``h``
COMPLEX_STEP = 1e-30


#: the rows of :func:`_slope_tangent`'s scratch (4, 3) of the slope itself, indexed rather than taken as views (a view
#: per stage cost its reference counts, 5 % of the kernel): the spring and damper's force ``f``, ``C f - b``, the rod's
#: direction ``n`` and ``C n``
_F, _ACC, _N, _CN = 0, 1, 2, 3

#: the directions of :func:`slosh_tangents` integrated side by side (a lane each, in groups of this many; the
#: prediction's :data:`~estimators.models.slosh_dynamics.LANES` are parameter sets)
DIRECTION_LANES = 4

#: the rows of the directions' scratch of :func:`slosh_tangents` (a lane per direction: everything a direction's
#: tangent reads or writes in one array, as :func:`~estimators.models.slosh_dynamics.integrate_slosh` has its lanes,
#: which lets the compiler vectorise the directions): the state's derivative (6), the RK4 stage's (6), the four
#: slopes' (4 x 6), the forcing's at the step's start, middle and end (3 x 9), the coupling's (9, row-major), the rod
#: axis's (3), those of ``[w^2, 2 zeta w, kappa]`` (3)
D_STATE, D_STAGE, D_SLOPES, D_STEP, D_COUPLING, D_AXIS, D_OSCILLATOR, N_DIRECTION_ROWS = 0, 6, 12, 36, 63, 72, 75, 78


@njit(cache=True, inline="always")
def _slope_tangent(
    point: FloatArray,
    step: FloatArray,
    row: int,
    inputs: FloatArray,
    coupling: FloatArray,
    axis: FloatArray,
    rod: bool,
    slopes: FloatArray,
    s: int,
    work: FloatArray,
    d: FloatArray,
    d_point: int,
) -> None:
    """``slopes[s]`` = the slope of :func:`~estimators.models.slosh_dynamics.slosh_slope` at ``point`` (6,) for the forcing
    ``step[row]`` (9,) and the inputs (N_INPUTS,; their ``coupling`` (3, 3) and ``axis`` (3,) given), and in each
    lane of the directions' scratch ``d`` (groups, :data:`N_DIRECTION_ROWS`, :data:`DIRECTION_LANES`) the slope's
    derivative (rows of slope ``s``) from the point's (rows ``d_point``, an offset, to ``d_point + 6``), the forcing's,
    the coupling's, the axis's and the oscillator's: the slope's forward-mode derivative written out (the spring, the
    frame's terms, the rod's restoring force and tension), every direction alike (a direction along which the forcing
    and the coupling do not change has zeros there, which add nothing where the state is finite). ``work`` (4, 3) is
    scratch (rows :data:`_F` to :data:`_CN`)."""
    omega_n, zeta, kappa = inputs[4], inputs[5], inputs[6]
    stiff, damp = omega_n * omega_n, 2.0 * zeta * omega_n
    wx, wy, wz = step[row, 3], step[row, 4], step[row, 5]
    ex, ey, ez = step[row, 6], step[row, 7], step[row, 8]
    x0, x1, x2, v0, v1, v2 = point[0], point[1], point[2], point[3], point[4], point[5]
    w_x = _cross(wx, wy, wz, x0, x1, x2)
    ax = axis[0] * x0 + axis[1] * x1 + axis[2] * x2
    for c in range(3):
        spring = point[c] + ax * axis[c] + kappa * ax * point[c] if rod else point[c]
        work[_F, c] = -stiff * spring - damp * point[3 + c]
    g = frame_terms((wx, wy, wz, ex, ey, ez), (x0, x1, x2), (v0, v1, v2))
    for c in range(3):  # C f - b, before the rod's tension
        work[_ACC, c] = (
            coupling[c, 0] * work[_F, 0] + coupling[c, 1] * work[_F, 1] + coupling[c, 2] * work[_F, 2] - (step[row, c] + g[c])
        )
        work[_N, c] = axis[c] + kappa * point[c]
    for c in range(3):
        work[_CN, c] = coupling[c, 0] * work[_N, 0] + coupling[c, 1] * work[_N, 1] + coupling[c, 2] * work[_N, 2]
    den = work[_N, 0] * work[_CN, 0] + work[_N, 1] * work[_CN, 1] + work[_N, 2] * work[_CN, 2]
    if rod and den == 0.0:
        raise ZeroDivisionError("slosh: the rod's tension divides by n.C n = 0")
    vv = v0 * v0 + v1 * v1 + v2 * v2
    tension = (
        (work[_N, 0] * work[_ACC, 0] + work[_N, 1] * work[_ACC, 1] + work[_N, 2] * work[_ACC, 2] + kappa * vv) / den
        if rod
        else 0.0
    )
    for c in range(3):  # the slope itself, as slosh_slope has it (the test holds the two to the same values)
        slopes[s, c] = point[3 + c]
        slopes[s, 3 + c] = work[_ACC, c] - tension * work[_CN, c]
    # the scalars every direction reads
    f0, f1, f2 = work[_F, 0], work[_F, 1], work[_F, 2]
    c00, c01, c02 = coupling[0, 0], coupling[0, 1], coupling[0, 2]
    c10, c11, c12 = coupling[1, 0], coupling[1, 1], coupling[1, 2]
    c20, c21, c22 = coupling[2, 0], coupling[2, 1], coupling[2, 2]
    a0, a1, a2 = axis[0], axis[1], axis[2]
    s0 = x0 + ax * a0 + kappa * ax * x0 if rod else x0
    s1 = x1 + ax * a1 + kappa * ax * x1 if rod else x1
    s2 = x2 + ax * a2 + kappa * ax * x2 if rod else x2
    acc0, acc1, acc2 = work[_ACC, 0], work[_ACC, 1], work[_ACC, 2]
    n0, n1, n2 = work[_N, 0], work[_N, 1], work[_N, 2]
    cn0, cn1, cn2 = work[_CN, 0], work[_CN, 1], work[_CN, 2]
    o, r, cc = D_SLOPES + 6 * s, D_STEP + 9 * row, D_COUPLING
    for g in range(d.shape[0]):
        for q in range(DIRECTION_LANES):
            dx0, dx1, dx2 = d[g, d_point, q], d[g, d_point + 1, q], d[g, d_point + 2, q]
            dv0, dv1, dv2 = d[g, d_point + 3, q], d[g, d_point + 4, q], d[g, d_point + 5, q]
            d_stiff, d_damp, d_kappa = d[g, D_OSCILLATOR, q], d[g, D_OSCILLATOR + 1, q], d[g, D_OSCILLATOR + 2, q]
            da0, da1, da2 = d[g, D_AXIS, q], d[g, D_AXIS + 1, q], d[g, D_AXIS + 2, q]
            if rod:
                d_ax = da0 * x0 + da1 * x1 + da2 * x2 + a0 * dx0 + a1 * dx1 + a2 * dx2
                ds0 = dx0 + d_ax * a0 + ax * da0 + (d_kappa * ax + kappa * d_ax) * x0 + kappa * ax * dx0
                ds1 = dx1 + d_ax * a1 + ax * da1 + (d_kappa * ax + kappa * d_ax) * x1 + kappa * ax * dx1
                ds2 = dx2 + d_ax * a2 + ax * da2 + (d_kappa * ax + kappa * d_ax) * x2 + kappa * ax * dx2
            else:
                ds0, ds1, ds2 = dx0, dx1, dx2
            df0 = -d_stiff * s0 - stiff * ds0 - d_damp * v0 - damp * dv0
            df1 = -d_stiff * s1 - stiff * ds1 - d_damp * v1 - damp * dv1
            df2 = -d_stiff * s2 - stiff * ds2 - d_damp * v2 - damp * dv2
            # d g = 2 (dw x x' + w x dx') + d(dw/dt) x x + dw/dt x dx + dw x (w x x) + w x (dw x x + w x dx)
            e2 = _cross(wx, wy, wz, dv0, dv1, dv2)
            e4 = _cross(ex, ey, ez, dx0, dx1, dx2)
            inner = _cross(wx, wy, wz, dx0, dx1, dx2)
            e6 = _cross(wx, wy, wz, inner[0], inner[1], inner[2])
            dacc0 = c00 * df0 + c01 * df1 + c02 * df2 - (2.0 * e2[0] + e4[0] + e6[0])
            dacc1 = c10 * df0 + c11 * df1 + c12 * df2 - (2.0 * e2[1] + e4[1] + e6[1])
            dacc2 = c20 * df0 + c21 * df1 + c22 * df2 - (2.0 * e2[2] + e4[2] + e6[2])
            # the forcing's and the coupling's own changes
            dwx, dwy, dwz = d[g, r + 3, q], d[g, r + 4, q], d[g, r + 5, q]
            e1 = _cross(dwx, dwy, dwz, v0, v1, v2)
            e3 = _cross(d[g, r + 6, q], d[g, r + 7, q], d[g, r + 8, q], x0, x1, x2)
            e5 = _cross(dwx, dwy, dwz, w_x[0], w_x[1], w_x[2])
            inner = _cross(dwx, dwy, dwz, x0, x1, x2)
            e7 = _cross(wx, wy, wz, inner[0], inner[1], inner[2])
            dc00, dc01, dc02 = d[g, cc, q], d[g, cc + 1, q], d[g, cc + 2, q]
            dc10, dc11, dc12 = d[g, cc + 3, q], d[g, cc + 4, q], d[g, cc + 5, q]
            dc20, dc21, dc22 = d[g, cc + 6, q], d[g, cc + 7, q], d[g, cc + 8, q]
            dacc0 += dc00 * f0 + dc01 * f1 + dc02 * f2 - (d[g, r, q] + 2.0 * e1[0] + e3[0] + e5[0] + e7[0])
            dacc1 += dc10 * f0 + dc11 * f1 + dc12 * f2 - (d[g, r + 1, q] + 2.0 * e1[1] + e3[1] + e5[1] + e7[1])
            dacc2 += dc20 * f0 + dc21 * f1 + dc22 * f2 - (d[g, r + 2, q] + 2.0 * e1[2] + e3[2] + e5[2] + e7[2])
            d[g, o, q], d[g, o + 1, q], d[g, o + 2, q] = dv0, dv1, dv2
            if rod:
                dn0, dn1, dn2 = (
                    da0 + d_kappa * x0 + kappa * dx0,
                    da1 + d_kappa * x1 + kappa * dx1,
                    da2 + d_kappa * x2 + kappa * dx2,
                )
                dcn0 = c00 * dn0 + c01 * dn1 + c02 * dn2 + (dc00 * n0 + dc01 * n1 + dc02 * n2)
                dcn1 = c10 * dn0 + c11 * dn1 + c12 * dn2 + (dc10 * n0 + dc11 * n1 + dc12 * n2)
                dcn2 = c20 * dn0 + c21 * dn1 + c22 * dn2 + (dc20 * n0 + dc21 * n1 + dc22 * n2)
                d_num = d_kappa * vv + 2.0 * kappa * (v0 * dv0 + v1 * dv1 + v2 * dv2)
                d_num += dn0 * acc0 + n0 * dacc0
                d_num += dn1 * acc1 + n1 * dacc1
                d_num += dn2 * acc2 + n2 * dacc2
                d_den = 0.0
                d_den += dn0 * cn0 + n0 * dcn0
                d_den += dn1 * cn1 + n1 * dcn1
                d_den += dn2 * cn2 + n2 * dcn2
                d_tension = (d_num - tension * d_den) / den
                dacc0 -= d_tension * cn0 + tension * dcn0
                dacc1 -= d_tension * cn1 + tension * dcn1
                dacc2 -= d_tension * cn2 + tension * dcn2
            d[g, o + 3, q], d[g, o + 4, q], d[g, o + 5, q] = dacc0, dacc1, dacc2


@njit(cache=True, error_model="numpy")  # no division check in the directions' loop, which would stop its vectorising
def slosh_tangents(
    twist: FloatArray, d_twist: FloatArray, t_s: FloatArray, inputs: FloatArray, d_inputs: FloatArray, rod: bool
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The slosh mass's relative momentum (T, 6) and displaced parameters (T, 10) of
    :func:`~estimators.models.slosh_dynamics.integrate_slosh` for one parameter set, and their derivatives (K, T, 6)
    and (K, T, 10) along K directions, from the rest's twist (T, 6) and its derivatives (K, T, 6) and the inputs
    (:data:`~estimators.models.slosh_dynamics.N_INPUTS`,) and their derivatives (K, N_INPUTS): RK4 of the oscillator
    and of its tangents (:func:`_slope_tangent`, the directions side by side), the forcing's and the outputs'
    derivatives by complex steps.

    Raises:
        ZeroDivisionError: the rod's tension has a zero divisor ``n.C n`` (as the prediction's integration does).
        ValueError: times ``t_s`` that do not increase strictly (the forcing's differences would divide by zero)."""
    n_k, n_t = d_twist.shape[0], twist.shape[0]
    check_times(t_s)
    h = COMPLEX_STEP
    tank, mass, coupling, axis = inputs[0:3], inputs[3], inputs[7:16].reshape(3, 3), inputs[16:19]
    work = np.empty((4, 3))
    n_groups = (n_k + DIRECTION_LANES - 1) // DIRECTION_LANES  # in groups of lanes, the last padded with zero directions
    forcing, d_forcing = np.empty((n_t, 9)), np.zeros((n_t, n_groups, 9, DIRECTION_LANES))
    c_forcing = np.empty((n_t, 9), dtype=np.complex128)
    for k in range(n_t):
        tank_forcing(twist, t_s, tank, k, forcing)
    omega_n, zeta = inputs[4], inputs[5]
    d = np.zeros((n_groups, N_DIRECTION_ROWS, DIRECTION_LANES))
    for direction in range(n_k):
        g, q = direction // DIRECTION_LANES, direction % DIRECTION_LANES
        for i in range(9):
            d[g, D_COUPLING + i, q] = d_inputs[direction, 7 + i]
        for i in range(3):
            d[g, D_AXIS + i, q] = d_inputs[direction, 16 + i]
        d_omega_n, d_zeta = d_inputs[direction, 4], d_inputs[direction, 5]
        d[g, D_OSCILLATOR, q] = 2.0 * omega_n * d_omega_n
        d[g, D_OSCILLATOR + 1, q] = 2.0 * (d_zeta * omega_n + zeta * d_omega_n)
        d[g, D_OSCILLATOR + 2, q] = d_inputs[direction, 6]
        # the forcing's derivative where it changes along the direction (elsewhere zeros)
        if np.any(d_twist[direction] != 0.0) or np.any(d_inputs[direction, 0:3] != 0.0):
            c_twist, c_tank = twist + 1j * h * d_twist[direction], tank + 1j * h * d_inputs[direction, 0:3]
            for k in range(n_t):
                tank_forcing(c_twist, t_s, c_tank, k, c_forcing)
            d_forcing[:, g, :, q] = c_forcing.imag / h
    state, stage, slopes, step = np.zeros(6), np.empty(6), np.empty((4, 6)), np.empty((3, 9))
    states, d_states = np.zeros((n_t, 6)), np.zeros((n_k, n_t, 6))
    for k in range(1, n_t):
        dt = t_s[k] - t_s[k - 1]
        for i in range(9):
            step[0, i], step[2, i] = forcing[k - 1, i], forcing[k, i]
            step[1, i] = 0.5 * (step[0, i] + step[2, i])
        for g in range(n_groups):
            for i in range(9):
                for q in range(DIRECTION_LANES):
                    d[g, D_STEP + i, q], d[g, D_STEP + 18 + i, q] = d_forcing[k - 1, g, i, q], d_forcing[k, g, i, q]
                    d[g, D_STEP + 9 + i, q] = 0.5 * (d[g, D_STEP + i, q] + d[g, D_STEP + 18 + i, q])
        for s in range(4):  # RK4 stages: the step's start, its middle twice, its end
            fraction = 0.0 if s == 0 else (1.0 if s == 3 else 0.5)
            if s > 0:
                for i in range(6):
                    stage[i] = state[i] + fraction * dt * slopes[s - 1, i]
                for g in range(n_groups):
                    for i in range(6):
                        for q in range(DIRECTION_LANES):
                            d[g, D_STAGE + i, q] = d[g, D_STATE + i, q] + fraction * dt * d[g, D_SLOPES + 6 * (s - 1) + i, q]
            row = 0 if s == 0 else (1 if s < 3 else 2)
            _slope_tangent(state if s == 0 else stage, step, row, inputs, coupling, axis, rod, slopes, s, work, d,
                           D_STATE if s == 0 else D_STAGE)  # fmt: skip
        for i in range(6):
            state[i] += (dt / 6.0) * (slopes[0, i] + 2.0 * slopes[1, i] + 2.0 * slopes[2, i] + slopes[3, i])
            states[k, i] = state[i]
        for g in range(n_groups):
            for i in range(6):
                for q in range(DIRECTION_LANES):
                    d[g, D_STATE + i, q] += (dt / 6.0) * (
                        d[g, D_SLOPES + i, q]
                        + 2.0 * d[g, D_SLOPES + 6 + i, q]
                        + 2.0 * d[g, D_SLOPES + 12 + i, q]
                        + d[g, D_SLOPES + 18 + i, q]
                    )
        for direction in range(n_k):
            for i in range(6):
                d_states[direction, k, i] = d[direction // DIRECTION_LANES, D_STATE + i, direction % DIRECTION_LANES]
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
