"""A derivative-free Newton step from a swarm's own evaluations: fit a quadratic, go to its minimum.

Near its minimum a least-squares cost is a quadratic in the parameters up to third-order terms.
A swarm that has gathered round the minimum has already evaluated the cost at many points there,
so a quadratic fitted to those evaluations predicts where the minimum is, to within the
third-order terms, without any derivative (the *quadratic approximation* of Deep and Bansal's
qPSO, "Quadratic approximation PSO for economic dispatch problems with valve-point effects",
2009, and of Pant et al.'s quadratic-interpolation PSO, 2007; here a least-squares fit of the whole
second-order model instead of a three-point interpolation per coordinate).

**Costs measured on different parts of the log.** The improved PSO evaluates each particle on one
of ``K`` subsets of the log (sequential evaluation), so the evaluations are of ``K`` different
functions. Relative to a reference point ``x0`` evaluated on every subset, the excess cost on
subset ``s`` is, to second order,

``c_s(x0 + d) - c_s(x0) = g_s . d + 1/2 d' H d``,

with a gradient ``g_s`` of its own (the subset's noise enters it) and one shared curvature ``H``
(interleaved subsets of a smooth signal have the same ``J' J / n``; the residual-curvature term
differs per subset but is small near the minimum). The whole log's excess is the sample-weighted
sum, ``(sum_s w_s g_s) . d + 1/2 d' H d``, whose minimum is the step.

**Conditioning.** The points of a converging swarm lie in a narrow, tilted valley (the fuel
problem's Fisher information has condition numbers up to ~1e4 in the unit box), so the fit is
made in coordinates whitened by the points' own second moment about ``x0``. The step is the
minimum of the fitted model within the region the points cover (no longer than the farthest
fitted point, in the whitened coordinates: a quadratic is not extrapolated); where the fitted
curvature is not positive definite that is a point on the region's boundary. Either way it is
only a candidate, which the caller evaluates.

The shared curvature holds for *interleaved* subsets (each sees the whole excitation). For
contiguous blocks of a log the curvatures differ, and the step is only as good as their mean.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray

IntArray = NDArray[np.intp]

#: fitted points per coefficient of the second-order model (least squares, not interpolation)
POINTS_PER_COEFFICIENT = 3
#: directions whose spread of points is below this fraction of the largest one's variance are not fitted
SPREAD_TOLERANCE = 1e-12
#: relative size below which an eigenvalue counts as the lowest one, and a gradient component as zero
HARD_CASE_TOLERANCE = 1e-12


def n_coefficients(n_params: int, n_subsets: int) -> int:
    """Coefficients of the model: a gradient per subset (``K k``) and a symmetric curvature (``k (k + 1) / 2``)."""
    return n_subsets * n_params + n_params * (n_params + 1) // 2


def quadratic_step(offsets: FloatArray, subset: IntArray, excess: FloatArray, weights: FloatArray) -> FloatArray | None:
    """Offset (k,) from the reference to the minimum of the fitted whole-log quadratic, or ``None``.

    Args:
        offsets: (m, k) points minus the reference point ``x0`` (any consistent units; the step
            comes back in the same units).
        subset: (m,) index of the subset each point was evaluated on, in ``0..K-1``.
        excess: (m,) each point's cost on its subset minus the reference's cost on that subset.
        weights: (K,) each subset's share of the whole log's samples (sums to 1).

    Directions in which neither the points nor the reference differ (all on a face of the search
    box that the reference is on, say) are left out of the fit and of the step. Returns ``None``
    when there are fewer points than ``POINTS_PER_COEFFICIENT`` times the coefficients, when the
    model cannot be fitted (rank-deficient: a subset without points, or points on a face the
    reference is not on), or when the data are not finite.
    """
    m = len(offsets)
    n_subsets = len(weights)
    if not (np.all(np.isfinite(offsets)) and np.all(np.isfinite(excess))):
        return None
    variances, axes = np.linalg.eigh(offsets.T @ offsets / m)
    spread = variances > SPREAD_TOLERANCE * max(float(variances[-1]), np.finfo(float).tiny)
    scale = axes[:, spread] * np.sqrt(variances[spread])  # offsets ~ z @ scale.T, z whitened (m, k')
    k = int(spread.sum())
    if k == 0 or m < POINTS_PER_COEFFICIENT * n_coefficients(k, n_subsets):
        return None
    z = offsets @ axes[:, spread] / np.sqrt(variances[spread])
    upper = np.triu_indices(k)
    linear = np.zeros((m, n_subsets * k))
    for s in range(n_subsets):
        on = subset == s
        linear[on, s * k : (s + 1) * k] = z[on]
    design = np.hstack([linear, z[:, upper[0]] * z[:, upper[1]]])
    coef, _, rank, _ = np.linalg.lstsq(design, excess, rcond=None)
    if rank < design.shape[1]:
        return None
    gradient = weights @ coef[: n_subsets * k].reshape(n_subsets, k)
    curvature = np.zeros((k, k))
    curvature[upper] = coef[n_subsets * k :]
    curvature = curvature + curvature.T  # off-diagonal c_ab z_a z_b -> H_ab = c_ab; diagonal c_aa z_a^2 -> H_aa = 2 c_aa
    reach = float(np.max(np.linalg.norm(z, axis=1)))
    return scale @ trust_region_minimum(gradient, curvature, reach)


def trust_region_minimum(gradient: FloatArray, curvature: FloatArray, radius: float) -> FloatArray:
    """Minimiser (k,) of ``g . z + 1/2 z' H z`` over ``|z| <= radius`` (the trust-region subproblem).

    The Newton step when ``H`` is positive definite and the step fits. Otherwise the minimiser is
    on the boundary: ``z(lam) = -(H + lam I)^-1 g`` with ``lam > max(0, -lambda_min(H))`` found by
    bisection on ``|z(lam)| = radius``; in the "hard case" (``g`` without a component along the
    lowest eigenvector ``v``, so ``|z(lam)|`` stays below ``radius`` however close ``lam`` comes to
    ``-lambda_min``) it is ``z(-lambda_min) + tau v`` with ``tau`` taking it to the boundary
    (Moré and Sorensen, "Computing a trust region step", 1983).
    """
    values, vectors = np.linalg.eigh(curvature)
    g = vectors.T @ gradient
    if values[0] > 0.0:
        newton = -g / values
        if np.linalg.norm(newton) <= radius:
            return vectors @ newton
    shift = max(0.0, -float(values[0]))
    lowest = values + shift <= HARD_CASE_TOLERANCE * max(float(np.abs(values).max()), np.finfo(float).tiny)
    if np.all(np.abs(g[lowest]) <= HARD_CASE_TOLERANCE * max(float(np.linalg.norm(g)), np.finfo(float).tiny)):
        z = np.zeros_like(g)
        z[~lowest] = -g[~lowest] / (values[~lowest] + shift)
        if np.linalg.norm(z) <= radius:  # the hard case: the rest of the way along the lowest eigenvector
            z[np.flatnonzero(lowest)[0]] = np.sqrt(radius**2 - float(z @ z))
            return vectors @ z
    low, high = shift, shift + float(np.linalg.norm(g)) / radius  # |z(high)| <= radius
    for _ in range(200):
        lam = 0.5 * (low + high)
        if not low < lam < high:
            break
        if np.linalg.norm(g / (values + lam)) > radius:
            low = lam
        else:
            high = lam
    return vectors @ (-g / (values + high))
