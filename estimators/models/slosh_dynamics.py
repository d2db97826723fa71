"""The slosh mass's equations of motion in the base frame, integrated along a log (the kernels of
:class:`~estimators.models.mass_effects.Slosh`).

The mass ``m_s`` sits at the tank point ``r`` at rest; ``x`` is its displacement (base axes). Per unit mass,

``x'' = C (f_s + f_d - t n) - a_tank - g``

* ``C = E + m_s Lambda^-1`` (the coupling): the force on the mass also pushes the rest of the robot at the tank, whose
  inverse operational mass is ``Lambda^-1``;
* ``a_tank``: the tank point's inertial acceleration from the rest's twist (base axes), and ``g = 2 omega x x' +
  domega/dt x x + omega x (omega x x)`` the rotating base frame's Coriolis, Euler and centripetal terms on ``x``
  (:func:`frame_terms`);
* the spring-mass (no rod): ``f_s = -w^2 x``, ``f_d = -2 zeta w x'``, ``t = 0``;
* the pendulum: a massless rod of signed curvature ``kappa`` (1/m; ``kappa = 1 / L`` with the hinge at ``r - L a``,
  ``a`` the rod's unit axis at rest) keeps the mass on the sphere ``|L a + x| = L``, i.e. on ``phi(x) = a.x + kappa |x|^2
  / 2 = 0``, whose normal ``n = a + kappa x`` is the rod's direction. The restoring force is that of a pendulum under
  the effective acceleration ``L w^2`` along ``a`` (Abramson, NASA SP-106, ch. 6: the settled liquid under a small
  residual acceleration), its component normal to the rod: ``w^2 L (a - n (n.a))`` = ``-w^2 (x + (a.x) a + kappa (a.x)
  x)``, finite for any ``kappa`` (``kappa = 0``: a mass moving in the plane normal to ``a`` on a spring, the small-angle
  limit); the damping ``f_d = -2 zeta w x'`` is along the motion; the rod's tension ``t`` keeps the mass on the sphere:
  ``n.x'' + kappa |x'|^2 = 0`` (the second derivative of ``phi`` along the motion) gives
  ``t = (n.C (f_s + f_d) - n.(a_tank + g) + kappa |x'|^2) / n.C n``.

Integrated with classical RK4 at the log's sample period, starting at rest, the forcing ``a_tank`` and the base's
rates linear between samples. Every kernel here is written for real and complex numbers alike: the forward-mode
derivatives (:func:`~estimators.models.tangents.slosh_tangents`) take the cheap ones along complex steps, and their
test runs the whole integration in complex numbers as the exact reference.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from spaceid_gym.arrays import FloatArray


@njit(cache=True, inline="always")
def cross3(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> tuple[float, float, float]:
    """``a x b`` of two 3-vectors given by their components."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def frame_terms(
    spin: tuple[float, float, float, float, float, float], x: tuple[float, float, float], v: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The acceleration terms of a displacement ``x`` moving at ``v`` = ``x'`` (base axes) in the rotating base frame,
    ``2 omega x x' + domega/dt x x + omega x (omega x x)``, for ``spin`` = ``[omega; domega/dt]`` (base axes):
    Coriolis, Euler and centripetal."""
    wx, wy, wz = spin[0], spin[1], spin[2]
    c1 = cross3(wx, wy, wz, v[0], v[1], v[2])
    c2 = cross3(spin[3], spin[4], spin[5], x[0], x[1], x[2])
    w_x = cross3(wx, wy, wz, x[0], x[1], x[2])
    c3 = cross3(wx, wy, wz, w_x[0], w_x[1], w_x[2])
    return 2.0 * c1[0] + c2[0] + c3[0], 2.0 * c1[1] + c2[1] + c3[1], 2.0 * c1[2] + c2[2] + c3[2]


#: the rows of the lanes' scratch of :func:`integrate_slosh` (one column per lane: everything a lane's RK4 reads or
#: writes in one array, which lets the compiler prove the lanes' loads and stores independent and vectorise them):
#: the state ``[x; x']`` (6), the RK4 stage's point (6), its four slopes (4 x 6), the forcing at the step's start,
#: middle and end (3 x 9), the coupling ``C`` (9, row-major), the rod's axis (3), ``[w^2, 2 zeta w, kappa]`` (3) and
#: the count of zero divisors of the rod's tension met (1)
STATE, STAGE, SLOPES, STEP, COUPLING, AXIS, OSCILLATOR, ZERO_DIVISORS, N_LANE_ROWS = 0, 6, 12, 36, 63, 72, 75, 78, 79


@njit(cache=True, inline="always")
def slosh_slope(lanes: FloatArray, point: int, row: int, rod: bool, s: int, lane: int) -> None:
    """The slope ``[x'; x'']`` (module docstring) of one lane of the scratch ``lanes`` (:data:`N_LANE_ROWS`, L) at
    the point in its rows ``point`` to ``point + 6`` (``[x; x']``), for the forcing at the step's ``row`` (``[a_tank;
    omega; domega/dt]``, the tank's acceleration and the base's rates), written to the rows of slope ``s``; with
    ``rod`` the pendulum's (a zero divisor of its tension counted). Real or complex, all alike; indices rather than
    views, which cost in the integration's innermost loop."""
    w = lanes
    x0, x1, x2 = w[point, lane], w[point + 1, lane], w[point + 2, lane]
    v0, v1, v2 = w[point + 3, lane], w[point + 4, lane], w[point + 5, lane]
    stiff, damp, kappa = w[OSCILLATOR, lane], w[OSCILLATOR + 1, lane], w[OSCILLATOR + 2, lane]
    a_0, a_1, a_2 = w[AXIS, lane], w[AXIS + 1, lane], w[AXIS + 2, lane]
    if rod:
        ax = a_0 * x0 + a_1 * x1 + a_2 * x2
        f0 = -stiff * (x0 + ax * a_0 + kappa * ax * x0) - damp * v0
        f1 = -stiff * (x1 + ax * a_1 + kappa * ax * x1) - damp * v1
        f2 = -stiff * (x2 + ax * a_2 + kappa * ax * x2) - damp * v2
    else:
        f0, f1, f2 = -stiff * x0 - damp * v0, -stiff * x1 - damp * v1, -stiff * x2 - damp * v2
    r = STEP + 9 * row
    spin = (w[r + 3, lane], w[r + 4, lane], w[r + 5, lane], w[r + 6, lane], w[r + 7, lane], w[r + 8, lane])
    g = frame_terms(spin, (x0, x1, x2), (v0, v1, v2))
    b0, b1, b2 = w[r, lane] + g[0], w[r + 1, lane] + g[1], w[r + 2, lane] + g[2]
    c = COUPLING
    cf0 = w[c, lane] * f0 + w[c + 1, lane] * f1 + w[c + 2, lane] * f2
    cf1 = w[c + 3, lane] * f0 + w[c + 4, lane] * f1 + w[c + 5, lane] * f2
    cf2 = w[c + 6, lane] * f0 + w[c + 7, lane] * f1 + w[c + 8, lane] * f2
    a0, a1, a2 = cf0 - b0, cf1 - b1, cf2 - b2
    if rod:
        n0, n1, n2 = a_0 + kappa * x0, a_1 + kappa * x1, a_2 + kappa * x2
        cn0 = w[c, lane] * n0 + w[c + 1, lane] * n1 + w[c + 2, lane] * n2
        cn1 = w[c + 3, lane] * n0 + w[c + 4, lane] * n1 + w[c + 5, lane] * n2
        cn2 = w[c + 6, lane] * n0 + w[c + 7, lane] * n1 + w[c + 8, lane] * n2
        den = n0 * cn0 + n1 * cn1 + n2 * cn2
        w[ZERO_DIVISORS, lane] += 1.0 if den == 0.0 else 0.0
        tension = (n0 * a0 + n1 * a1 + n2 * a2 + kappa * (v0 * v0 + v1 * v1 + v2 * v2)) / den
        a0, a1, a2 = a0 - tension * cn0, a1 - tension * cn1, a2 - tension * cn2
    o = SLOPES + 6 * s
    w[o, lane], w[o + 1, lane], w[o + 2, lane], w[o + 3, lane], w[o + 4, lane], w[o + 5, lane] = v0, v1, v2, a0, a1, a2


@njit(cache=True, inline="always")
def tank_forcing(twist: FloatArray, t_s: FloatArray, tank: FloatArray, k: int, forcing: FloatArray) -> None:
    """At sample ``k`` of the rest's twists (T, 6) ``[v; omega]`` (base origin, base axes): ``forcing[k]`` = ``[a_tank;
    omega; domega/dt]``, the tank point's inertial acceleration ``dv/dt + omega x v + domega/dt x r + omega x (omega x
    r)`` and the base's rates, the time derivatives by central differences (one-sided at the ends)."""
    n_t = twist.shape[0]
    lo, hi = max(k - 1, 0), min(k + 1, n_t - 1)
    inv = 1.0 / (t_s[hi] - t_s[lo])
    rx, ry, rz = tank[0], tank[1], tank[2]
    wx, wy, wz = twist[k, 3], twist[k, 4], twist[k, 5]
    dwx = (twist[hi, 3] - twist[lo, 3]) * inv
    dwy = (twist[hi, 4] - twist[lo, 4]) * inv
    dwz = (twist[hi, 5] - twist[lo, 5]) * inv
    a1 = cross3(wx, wy, wz, twist[k, 0], twist[k, 1], twist[k, 2])
    a2 = cross3(dwx, dwy, dwz, rx, ry, rz)
    wr = cross3(wx, wy, wz, rx, ry, rz)
    a3 = cross3(wx, wy, wz, wr[0], wr[1], wr[2])
    for c in range(3):
        forcing[k, c] = (twist[hi, c] - twist[lo, c]) * inv + a1[c] + a2[c] + a3[c]
    forcing[k, 3], forcing[k, 4], forcing[k, 5], forcing[k, 6], forcing[k, 7], forcing[k, 8] = wx, wy, wz, dwx, dwy, dwz


@njit(cache=True, inline="always")
def slosh_outputs(states: FloatArray, tank: FloatArray, mass: float, out: FloatArray, moved: FloatArray) -> None:
    """From the displacements and rates ``states`` (T, 6): the mass's momentum relative to the base ``out`` (T, 6),
    ``[m x'; m (r + x) x x']`` about the base origin, and ``moved`` (T, 10) the change of the composite's parameters
    from the point mass at ``r + x`` instead of ``r`` (first moment and inertia about the origin)."""
    rx, ry, rz = tank[0], tank[1], tank[2]
    m = mass
    for k in range(states.shape[0]):
        x0, x1, x2 = states[k, 0], states[k, 1], states[k, 2]
        v0, v1, v2 = states[k, 3], states[k, 4], states[k, 5]
        px, py, pz = rx + x0, ry + x1, rz + x2
        ang = cross3(px, py, pz, v0, v1, v2)
        out[k, 0], out[k, 1], out[k, 2] = m * v0, m * v1, m * v2
        out[k, 3], out[k, 4], out[k, 5] = m * ang[0], m * ang[1], m * ang[2]
        moved[k, 0] = 0.0 * m
        moved[k, 1], moved[k, 2], moved[k, 3] = m * x0, m * x1, m * x2
        moved[k, 4] = m * ((py * py + pz * pz) - (ry * ry + rz * rz))
        moved[k, 5] = -m * (px * py - rx * ry)
        moved[k, 6] = m * ((px * px + pz * pz) - (rx * rx + rz * rz))
        moved[k, 7] = -m * (px * pz - rx * rz)
        moved[k, 8] = -m * (py * pz - ry * rz)
        moved[k, 9] = m * ((px * px + py * py) - (rx * rx + ry * ry))


#: the length of a parameter set's inputs to :func:`integrate_slosh`: the tank point ``r`` (3, m, base axes), ``[m_s,
#: w, zeta, kappa]`` (mass kg, natural frequency rad/s, damping ratio, the rod's curvature 1/m, 0 without a rod), the
#: coupling ``C`` (9, row-major) and the rod's unit axis at rest (3, base axes; unused without a rod)
N_INPUTS = 19


#: the parameter sets integrated side by side by :func:`slosh_momentum` (a lane each): one set's RK4 is scalar
#: arithmetic; the same operations on several sets at once compile to vector instructions (a grid of 64 sets 2.4x
#: faster than one by one, the same numbers to the last bit)
LANES = 8


@njit(cache=True)
def _lane_forcing(twist: FloatArray, t_s: FloatArray, tank: FloatArray, forcing: FloatArray, lane: int) -> None:
    """``forcing[:, :, lane]`` (T, 9) = :func:`tank_forcing` of every sample of ``twist`` (T, 6) (times checked by the
    callers, :func:`check_times`: numba compiles a function called from a caller of numpy's error model with that
    model, so a division by zero here gives inf, not an exception)."""
    one = np.empty((twist.shape[0], 9), dtype=forcing.dtype)
    for k in range(twist.shape[0]):
        tank_forcing(twist, t_s, tank, k, one)
    forcing[:, :, lane] = one


@njit(cache=True)
def check_times(t_s: FloatArray) -> None:
    """Raise ``ValueError`` unless the times ``t_s`` (T,) increase strictly: the forcing's central differences divide
    by their steps (:func:`tank_forcing`), and the kernels that use them run with numpy's error model."""
    for k in range(1, t_s.shape[0]):
        if not t_s[k] > t_s[k - 1]:
            raise ValueError("slosh: the times must increase strictly")


@njit(cache=True, inline="always")
def _slopes_at(lanes: FloatArray, point: int, row: int, rod: bool, s: int) -> None:
    """:func:`slosh_slope` of every lane."""
    for lane in range(lanes.shape[1]):
        slosh_slope(lanes, point, row, rod, s, lane)


@njit(cache=True, inline="always")
def _stage(lanes: FloatArray, s: int, step: float) -> None:
    """Every lane's RK4 stage point: the state plus ``step`` times slope ``s - 1``."""
    for i in range(6):
        for lane in range(lanes.shape[1]):
            lanes[STAGE + i, lane] = lanes[STATE + i, lane] + step * lanes[SLOPES + 6 * (s - 1) + i, lane]


# numpy's error model (a division by zero gives inf, not an exception) lets the lanes' divisions compile to vector
# instructions; the one division here, the rod's tension over n.C n, counts its zero divisors instead. Inlined where
# called, so that the compiler knows the scratch's number of lanes (its shape, set there), and vectorises for it
@njit(cache=True, error_model="numpy", inline="always")
def integrate_slosh(
    twist: FloatArray, t_s: FloatArray, inputs: FloatArray, rod: bool, out: FloatArray, moved: FloatArray, w: FloatArray
) -> None:
    """L parameter sets side by side, real or complex alike: :func:`slosh_outputs` ``out`` (L, T, 6) and ``moved``
    (L, T, 10) of the mass driven by the rest's twists ``twist`` (L, T, 6) ``[v; omega]`` (base origin, base axes) at
    times ``t_s``, for ``inputs`` (L, :data:`N_INPUTS`), with a rod or not; ``w`` (:data:`N_LANE_ROWS`, W), zeros, of
    the same type, is the lanes' scratch (W >= L lanes; those past L repeat the last set). Each set's numbers are
    those of its integration alone (every operation per lane, in the same order).

    Raises:
        ZeroDivisionError: the rod's tension has a zero divisor ``n.C n`` (as a division by zero would)."""
    n_l, n_t = twist.shape[0], twist.shape[1]
    dtype = twist.dtype
    width = w.shape[1]
    forcing = np.empty((n_t, 9, width), dtype=dtype)
    for column in range(width):
        lane = min(column, n_l - 1)
        if column < n_l:
            _lane_forcing(twist[lane], t_s, inputs[lane, 0:3], forcing, column)
        else:
            forcing[:, :, column] = forcing[:, :, lane]
        for i in range(9):
            w[COUPLING + i, column] = inputs[lane, 7 + i]
        for i in range(3):
            w[AXIS + i, column] = inputs[lane, 16 + i]
        omega_n, zeta = inputs[lane, 4], inputs[lane, 5]
        w[OSCILLATOR, column], w[OSCILLATOR + 1, column], w[OSCILLATOR + 2, column] = (
            omega_n * omega_n,
            2.0 * zeta * omega_n,
            inputs[lane, 6],
        )
    states = np.empty((n_t, 6, width), dtype=dtype)  # per sample [x; x'] of each lane
    for i in range(6):
        for lane in range(width):
            w[STATE + i, lane] = 0.0 * w[OSCILLATOR, lane]
            states[0, i, lane] = w[STATE + i, lane]
    for k in range(1, n_t):
        h = t_s[k] - t_s[k - 1]
        for i in range(9):
            for lane in range(width):
                w[STEP + i, lane], w[STEP + 18 + i, lane] = forcing[k - 1, i, lane], forcing[k, i, lane]
                w[STEP + 9 + i, lane] = 0.5 * (w[STEP + i, lane] + w[STEP + 18 + i, lane])
        _slopes_at(w, STATE, 0, rod, 0)  # RK4: the step's start, its middle twice, its end
        _stage(w, 1, 0.5 * h)
        _slopes_at(w, STAGE, 1, rod, 1)
        _stage(w, 2, 0.5 * h)
        _slopes_at(w, STAGE, 1, rod, 2)
        _stage(w, 3, 1.0 * h)
        _slopes_at(w, STAGE, 2, rod, 3)
        for i in range(6):
            for lane in range(width):
                slopes = (w[SLOPES + i, lane], w[SLOPES + 6 + i, lane], w[SLOPES + 12 + i, lane], w[SLOPES + 18 + i, lane])
                w[STATE + i, lane] = w[STATE + i, lane] + (h / 6.0) * (slopes[0] + 2.0 * slopes[1] + 2.0 * slopes[2] + slopes[3])
                states[k, i, lane] = w[STATE + i, lane]
    for lane in range(n_l):
        if w[ZERO_DIVISORS, lane] != 0.0:
            raise ZeroDivisionError("slosh: the rod's tension divides by n.C n = 0")
        slosh_outputs(np.ascontiguousarray(states[:, :, lane]), inputs[lane, 0:3], inputs[lane, 3], out[lane], moved[lane])


@njit(cache=True, error_model="numpy")  # the model of the integration inlined here
def slosh_momentum(twist: FloatArray, t_s: FloatArray, inputs: FloatArray, rod: bool) -> tuple[FloatArray, FloatArray]:
    """For P parameter sets: the slosh mass's relative momentum (P, T, 6) and the displaced parameters (P, T, 10)
    (:func:`integrate_slosh`, :data:`LANES` sets at a time), from the rest's twists (P, T, 6) and the inputs
    (P, :data:`N_INPUTS`).

    Raises:
        ValueError: times ``t_s`` that do not increase strictly (:func:`check_times`)."""
    check_times(t_s)
    n_p, n_t = twist.shape[0], twist.shape[1]
    out = np.zeros((n_p, n_t, 6))
    moved = np.zeros((n_p, n_t, 10))
    for first in range(0, n_p, LANES):
        last = min(first + LANES, n_p)
        if last - first == 1:  # one set: one lane
            integrate_slosh(
                twist[first:last], t_s, inputs[first:last], rod, out[first:last], moved[first:last], np.zeros((N_LANE_ROWS, 1))
            )
        else:
            lanes = np.zeros((N_LANE_ROWS, LANES))
            integrate_slosh(twist[first:last], t_s, inputs[first:last], rod, out[first:last], moved[first:last], lanes)
    return out, moved
