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
def frame_terms(spin: FloatArray, row: int, point: FloatArray) -> tuple[float, float, float]:
    """The acceleration terms of a displacement ``x`` moving at ``x'`` (``point`` = ``[x; x']``, base axes) in the
    rotating base frame, ``2 omega x x' + domega/dt x x + omega x (omega x x)``, for ``spin[row, 3:9]`` = ``[omega;
    domega/dt]`` (base axes): Coriolis, Euler and centripetal."""
    wx, wy, wz = spin[row, 3], spin[row, 4], spin[row, 5]
    c1 = cross3(wx, wy, wz, point[3], point[4], point[5])
    c2 = cross3(spin[row, 6], spin[row, 7], spin[row, 8], point[0], point[1], point[2])
    w_x = cross3(wx, wy, wz, point[0], point[1], point[2])
    c3 = cross3(wx, wy, wz, w_x[0], w_x[1], w_x[2])
    return 2.0 * c1[0] + c2[0] + c3[0], 2.0 * c1[1] + c2[1] + c3[1], 2.0 * c1[2] + c2[2] + c3[2]


@njit(cache=True, inline="always")
def slosh_slope(
    point: FloatArray,
    forcing: FloatArray,
    row: int,
    coupling: FloatArray,
    stiff: float,
    damp: float,
    axis: FloatArray,
    kappa: float,
    rod: bool,
    out: FloatArray,
    s: int,
) -> None:
    """``out[s]`` (6,) = ``[x'; x'']`` at ``point`` = ``[x; x']`` (module docstring), with ``forcing[row]`` = ``[a_tank;
    omega; domega/dt]`` (9,; the tank's acceleration and the base's rates), the coupling ``C`` (3, 3), ``stiff = w^2``,
    ``damp = 2 zeta w``, and with ``rod`` the pendulum's axis ``a`` (3,) and curvature ``kappa``. Real or complex, all
    alike; indices rather than views, which cost in the integration's innermost loop."""
    x0, x1, x2, v0, v1, v2 = point[0], point[1], point[2], point[3], point[4], point[5]
    if rod:
        ax = axis[0] * x0 + axis[1] * x1 + axis[2] * x2
        f0 = -stiff * (x0 + ax * axis[0] + kappa * ax * x0) - damp * v0
        f1 = -stiff * (x1 + ax * axis[1] + kappa * ax * x1) - damp * v1
        f2 = -stiff * (x2 + ax * axis[2] + kappa * ax * x2) - damp * v2
    else:
        f0, f1, f2 = -stiff * x0 - damp * v0, -stiff * x1 - damp * v1, -stiff * x2 - damp * v2
    g = frame_terms(forcing, row, point)
    b0, b1, b2 = forcing[row, 0] + g[0], forcing[row, 1] + g[1], forcing[row, 2] + g[2]
    cf0 = coupling[0, 0] * f0 + coupling[0, 1] * f1 + coupling[0, 2] * f2
    cf1 = coupling[1, 0] * f0 + coupling[1, 1] * f1 + coupling[1, 2] * f2
    cf2 = coupling[2, 0] * f0 + coupling[2, 1] * f1 + coupling[2, 2] * f2
    a0, a1, a2 = cf0 - b0, cf1 - b1, cf2 - b2
    if rod:
        n0, n1, n2 = axis[0] + kappa * x0, axis[1] + kappa * x1, axis[2] + kappa * x2
        cn0 = coupling[0, 0] * n0 + coupling[0, 1] * n1 + coupling[0, 2] * n2
        cn1 = coupling[1, 0] * n0 + coupling[1, 1] * n1 + coupling[1, 2] * n2
        cn2 = coupling[2, 0] * n0 + coupling[2, 1] * n1 + coupling[2, 2] * n2
        tension = (n0 * a0 + n1 * a1 + n2 * a2 + kappa * (v0 * v0 + v1 * v1 + v2 * v2)) / (n0 * cn0 + n1 * cn1 + n2 * cn2)
        a0, a1, a2 = a0 - tension * cn0, a1 - tension * cn1, a2 - tension * cn2
    out[s, 0], out[s, 1], out[s, 2], out[s, 3], out[s, 4], out[s, 5] = v0, v1, v2, a0, a1, a2


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


@njit(cache=True)
def integrate_slosh(
    twist: FloatArray, t_s: FloatArray, inputs: FloatArray, rod: bool, out: FloatArray, moved: FloatArray, work: FloatArray
) -> None:
    """One parameter set, real or complex alike: :func:`slosh_outputs` ``out`` (T, 6) and ``moved`` (T, 10) of the
    mass driven by the rest's twists ``twist`` (T, 6) ``[v; omega]`` (base origin, base axes) at times ``t_s``, for
    ``inputs`` (:data:`N_INPUTS`,), with a rod or not. ``work`` (2 T + 9, 9), of the same type, is scratch."""
    tank, coupling, axis = inputs[0:3], inputs[7:16].reshape(3, 3), inputs[16:19]
    mass, omega_n, zeta, kappa = inputs[3], inputs[4], inputs[5], inputs[6]
    n_t = twist.shape[0]
    forcing, states = work[:n_t], work[n_t : 2 * n_t, :6]  # per sample [a_tank; omega; domega/dt] and [x; x']
    state, stage, slopes = work[2 * n_t, :6], work[2 * n_t + 1, :6], work[2 * n_t + 2 : 2 * n_t + 6, :6]
    step = work[2 * n_t + 6 : 2 * n_t + 9]  # the forcing at a step's start, middle and end
    for k in range(n_t):
        tank_forcing(twist, t_s, tank, k, forcing)
    stiff, damp = omega_n * omega_n, 2.0 * zeta * omega_n
    for i in range(6):
        state[i] = 0.0 * stiff
        states[0, i] = state[i]
    for k in range(1, n_t):
        h = t_s[k] - t_s[k - 1]
        for i in range(9):
            step[0, i], step[2, i] = forcing[k - 1, i], forcing[k, i]
            step[1, i] = 0.5 * (step[0, i] + step[2, i])
        slosh_slope(state, step, 0, coupling, stiff, damp, axis, kappa, rod, slopes, 0)
        for s in range(1, 4):  # RK4: the step's middle twice, its end
            fraction = 1.0 if s == 3 else 0.5
            for i in range(6):
                stage[i] = state[i] + fraction * h * slopes[s - 1, i]
            slosh_slope(stage, step, 1 if s < 3 else 2, coupling, stiff, damp, axis, kappa, rod, slopes, s)
        for i in range(6):
            state[i] = state[i] + (h / 6.0) * (slopes[0, i] + 2.0 * slopes[1, i] + 2.0 * slopes[2, i] + slopes[3, i])
            states[k, i] = state[i]
    slosh_outputs(states, tank, mass, out, moved)


@njit(cache=True)
def slosh_momentum(twist: FloatArray, t_s: FloatArray, inputs: FloatArray, rod: bool) -> tuple[FloatArray, FloatArray]:
    """For P parameter sets: the slosh mass's relative momentum (P, T, 6) and the displaced parameters (P, T, 10)
    (:func:`integrate_slosh`), from the rest's twists (P, T, 6) and the inputs (P, :data:`N_INPUTS`)."""
    n_p, n_t = twist.shape[0], twist.shape[1]
    out = np.zeros((n_p, n_t, 6))
    moved = np.zeros((n_p, n_t, 10))
    work = np.empty((2 * n_t + 9, 9))
    for p in range(n_p):
        integrate_slosh(twist[p], t_s, inputs[p], rod, out[p], moved[p], work)
    return out, moved
