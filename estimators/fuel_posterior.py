"""The posterior mean and covariance of the fuel unknowns on one window, and through the later windows of a mission,
by importance sampling under the physical prior.

Why (measured on the first windows of missions 230-259, ``benchmarks/track_first_window.py``): ``hybrid``'s fit of
a window is the cost's minimum (a local polish from the truth lands on it to 1e-3 std) and its Cramér-Rao std per
unknown is right (mean ``z^2`` 0.95, 1.14, 0.95, 0.96 for the fuel and the tank's x, y, z), but the joint NEES
against that covariance averaged 11.4 (median 4.5; chi-square(4): 4) while the likelihood ratio of the truth
averaged 4.7. The error lies along the valley of the cost, which is curved: with little fuel consumed (27.5 kg in a
mission's first window) the rates see mostly the fuel's first moment ``g = mdf bf`` (kg m), so ``bf = g / mdf``
bends along a hyperbola in ``(mdf, bf)`` and the Gauss-Newton ellipse, tangent to it at the fit, is far too thin
across its bend (seed 244: NEES 160 against the bound, likelihood ratio 5.0). A covariance from the curvature at
one point cannot see this; the posterior's moments do.

The posterior: ``p(theta | log) ~ exp(-RSS(theta) / (2 sigma^2)) x prior(theta)``, ``RSS`` the window's residual
sum of squares (the cost the batch estimators minimise, times ``3T``), ``sigma`` the gyro noise per sample and axis
(the residual RMS at the fit, as the bound uses it), and the physical prior uniform: the fuel consumed between 0 and
the tank's usable capacity (``FuelSchedule.usable_fraction`` of the wet base mass: 137.5 kg for paper6) and the
tank inside the box of the satellite it is mounted in (``FuelSchedule.tank_half_width_m`` about the full-tank CoM,
per axis: 0.40 m for paper6). Its mean and covariance are estimated by self-normalised importance sampling.

Proposal (sets only the Monte Carlo efficiency, not the moments it estimates): a multivariate Student-t in
``(mdf, g)``, where the rates are nearest linear, centred at the fit and with the fit's Cramér-Rao covariance
carried there by the delta method, widened by :data:`PROPOSAL_WIDTH` and with :data:`PROPOSAL_DOF` degrees of
freedom (heavy tails: the posterior's bend reaches several of its linearised std from the fit); its density in
``theta`` carries the Jacobian ``|d(mdf, g) / d(mdf, bf)| = mdf^3``. Draws are added in batches of ``samples`` until
the effective sample size ``(sum w)^2 / sum w^2`` reaches :data:`MIN_EFFECTIVE_SAMPLES`; after
:data:`MAX_BATCHES` batches without it the function raises (never a silent fallback to the linearised covariance).
Every draw comes from the given seeded generator.

Through a mission (:class:`FuelPaths`, used by ``spaceid track`` until it hands the mission to the unscented filter,
:mod:`spaceid_gym.tracking`). Between two windows the fuel consumed takes a random-walk step of std ``step_std_kg``
(the filter's own process noise over the gap) and the tank does not move; the prior of each window is the physical
box. The first window's weighted draws are paths; :meth:`FuelPaths.extend` pushes each path over the gap (one
seeded step, dropped if it leaves the box) and multiplies its weight by the next window's likelihood: exact
sequential importance sampling of ``p(theta_w | windows 0..w)``, with no new physics (the window's cost). Why
(mission 241, ``benchmarks/track_second_window.py``): the first posterior 10.5 +- 7.1 kg (truth 27.5) is wide and
curved; the filter's plain pass over window 1 from its moments ended at 20.3 +- 5.1 kg against 44.3 (NEES 125),
the exact posterior is 29.2 +- 7.5 kg (NEES 7.3); the filter's own Gaussian prior times the exact likelihood gives
25.7 +- 6.7 kg (NEES 12.5): most of the excess is the filter's Gaussian update, the rest the prior's shape.

The paths degenerate as the windows sharpen the tank (the tank has no process noise): when fewer than
:data:`MIN_EFFECTIVE_SAMPLES` stay effective after a window, that window is sampled afresh under a
:class:`PredictedPrior`, a Gaussian kernel density of the last window's paths (a regularised particle filter:
Musso, Oudjane and Le Gland 2001; the kernel's bandwidth by Silverman's rule for the effective number of draws,
0.49 std at 200, with Liu and West's 2001 shrinkage so the mean and covariance are kept) plus the gap's step in the
fuel; the draws come from an equal mixture of that prior, a Student-t matched as above to a Gaussian guess of the
new posterior (the filter's) and the window's valley (below), with weights ``prior x likelihood / mixture``. The kernel smooths the last
posterior: on mission 241's window 1 a forced kernel step gives 26.9 +- 7.2 kg (NEES 9.3) where the exact push
gives 29.2 +- 7.5 kg (NEES 7.3), so it is used only where the exact push has too few effective draws. New whole
paths from the first window instead (from its proposal, or one matched to the paths' first window under every
window so far) reached at most 99 effective draws in 88 000 on window 2 of mission 241: the gap's walk is far wider
than the later windows' posteriors.

Mirrored basins (:func:`basin_minima`; issue 23, missions 309 and 218): the rates see the tank through its first
moment and through inertia terms even in ``bf``, so a first window's fit can stop at the tank mirrored along some
axes. Seed 309's ``hybrid`` fit (8.1 kg, tank y, z +0.47, -0.50 m) and the posterior around it sat there (NEES 9866);
a local polish from the fit's mirror image in y and z ends 67 chi-square units (``Delta RSS / sigma^2``) lower, in the
truth's basin (the truth 5.4 above that minimum); seed 218's fit (11.5 kg, tank x -0.50 m) lies 36 units above the
basin a polish from its x mirror reaches (28.2 kg, the truth 1.7 above it). So the sampler is built around every
distinct minimum that a polish from the fit and from each of its mirror images reaches, and the fit handed on is the
lowest. Rather than pick one basin by a threshold, the proposal is a mixture of one :class:`MomentProposal` per
basin, centred at the posterior's mode in it (:func:`prior_modes`: the polish again inside the physical prior's box,
from the minimum clipped into it; seed 309's minimum has the tank at z +0.50 m, outside the box's 0.40, and a
proposal centred there reached 182 effective draws in 64 000, 439 in 8000 from the mode), each weighted by Laplace's
approximation of its basin's posterior mass, ``exp(-Delta RSS_j / (2 sigma^2)) sqrt(det C_j)`` (``C_j`` the
Cramér-Rao covariance at the mode): two basins within a few
chi-square units both get draws in proportion to their mass, one 36 units above gets ``e^-18`` of them, and the
importance weights correct whatever the Laplace masses miss (a proposal only has to cover the posterior).

The valley along the fuel (:func:`valley_slices`; issue 23, mission 322): the cost can be nearly flat along the fuel
and the posterior's mass lie far from the fit. Mission 322's first window: the fit, 47.5 kg (truth 27.5, Cramér-Rao
std 21 kg), is the minimum of the cost's profile (the tank polished at each fuel), which rises only 3.1 chi-square
units down to 3.9 kg, while the tank's conditional spread ``sqrt(det C_bb)`` grows about as ``mdf^-3`` (the rates
see ``mdf bf``; inertia terms bend the valley, ``g`` from (-6.5, -0.8, -6.0) to (-1.3, -0.2, -1.5) kg m): per kg
the posterior is densest at low fuel, flat in ``log mdf`` from 4 to 60 kg until the box's edge cuts the tank below
3 kg (18.8 +- 15.4 kg by plain sampling from the prior). The proposal around the fit reached 64-91 effective draws
in 64 000. So the proposal is a defensive mixture (Hesterberg 1995): half its draws from the basins' components,
half from one component per slice of a geometric grid in the fuel (:data:`VALLEY_RATIO`), centred on the profile,
with the tank's conditional Cramér-Rao covariance, the valley's local slope and a fuel spread of one cell, weighted
by the slice's Laplace mass (the profile's likelihood times the tank's conditional volume times the cell: a
quadrature of the posterior's marginal in the fuel). The valley's half follows the cost whatever the fit, so it
covers a posterior anywhere along the valley by construction; where the posterior is narrow around the fit the
basins' half covers it, at the cost of at most half the draws. A later window sampled afresh draws a third from its
own valley, from its least-squares minimum nearest the guess, each slice weighted also by the kernel prior at its
centre (mission 322's window 1: the filter's guess 17.8 +- 2.8 kg against a posterior of 40-44 +- 10 kg). The
mixtures weigh full densities (the t's and the Gaussians' normalising constants). The effective-size error stays
for a posterior no part covers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.special import gammaln
from threadpoolctl import threadpool_limits

from estimators.least_squares import LevenbergMarquardt
from estimators.problem import IdentificationModel, IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.mission import FuelSchedule

#: the proposal's degrees of freedom: few, for tails heavier than the posterior's (a t with 4 has a finite covariance)
PROPOSAL_DOF = 4.0

#: the proposal's scale over the linearised std: 2, so the proposal's central 95 % holds the posterior's bend out to
#: about 4 linearised std (efficiency only: the importance weights correct any proposal that covers the posterior)
PROPOSAL_WIDTH = 2.0

#: the log of the multivariate Student-t's normalising constant in 4 dimensions, ``Gamma((nu + 4) / 2) / (Gamma(nu / 2)
#: (nu pi)^2)``: a mixture of the t's and the kernels' Gaussians weighs densities, not densities up to different constants
LOG_T_CONSTANT = float(gammaln(0.5 * (PROPOSAL_DOF + 4.0)) - gammaln(0.5 * PROPOSAL_DOF) - 2.0 * np.log(PROPOSAL_DOF * np.pi))

#: the effective sample size the moments need: a variance from n effective draws has a relative std of about
#: sqrt(2 / n), 0.1 at 200
MIN_EFFECTIVE_SAMPLES = 200.0

#: at most this many batches of draws before giving up with an error
MAX_BATCHES = 8

#: particles whose weight is below this fraction of the largest do not enter the predicted prior (together they
#: carry under 1e-8 of its mass even at 64 000 particles)
NEGLIGIBLE_WEIGHT = 1e-12

#: the valley's grid in the fuel consumed (:func:`valley_slices`): a slice every 25 % of the fuel, so the tank's
#: conditional mode, which moves as ``1 / mdf`` where the rates see its first moment, moves by at most 20 % between two
#: neighbours
VALLEY_RATIO = 1.25

#: the grid's lowest slice, a fraction of the tank's capacity (1.4 kg for paper6): below it the tank is barely seen
#: and the prior's own box, covered by the components' heavy tails, holds the posterior
VALLEY_FLOOR = 0.01

#: particles per call of the window's cost (bounds the memory of one batched prediction)
CHUNK = 1000


@dataclass(frozen=True)
class FuelPosterior:
    """The posterior's ``mean`` (4,) and ``covariance`` (4, 4) in ``(mdf kg, bf m)``, the draws made and their
    effective sample size."""

    mean: FloatArray
    covariance: FloatArray
    draws: int
    effective_samples: float


def physical_prior_box(problem: IdentificationProblem, schedule: FuelSchedule | None = None) -> tuple[FloatArray, FloatArray]:
    """The physical prior's box ``(lower, upper)`` (4,) of the fuel unknowns (see the module docstring)."""
    if problem.parameters.name != "fuel":
        raise SpaceIdInputError(f"fuel posterior: expected the fuel parameters, got {problem.parameters.name!r}")
    schedule = schedule or FuelSchedule()
    base_full = problem.model.robot.base_full
    half = schedule.tank_half_width_m(base_full)
    return np.array([0.0, -half, -half, -half]), np.array([schedule.usable_fraction * base_full.mass_kg, half, half, half])


def _first_moment(theta: FloatArray) -> FloatArray:
    """``(mdf, mdf bf)`` of ``theta = (mdf, bf)`` (..., 4)."""
    return np.concatenate([theta[..., :1], theta[..., :1] * theta[..., 1:]], axis=-1)


class MomentProposal:
    """A multivariate Student-t in ``(mdf, g = mdf bf)`` (module docstring) matching a Gaussian ``(centre, covariance)``
    of ``theta`` by the delta method, widened by :data:`PROPOSAL_WIDTH`, with :data:`PROPOSAL_DOF` degrees of freedom."""

    def __init__(self, centre: FloatArray, covariance: FloatArray) -> None:
        centre = np.asarray(centre, dtype=float)
        if not (centre.shape == (4,) and centre[0] > 0.0 and np.all(np.isfinite(centre))):
            raise SpaceIdInputError(f"fuel posterior: expected a centre with fuel consumed > 0 kg, got {centre.tolist()}")
        to_moment = np.eye(4)
        to_moment[1:, 0] = centre[1:]
        to_moment[1:, 1:] *= centre[0]
        moment_cov = to_moment @ np.asarray(covariance, dtype=float) @ to_moment.T
        self.factor = PROPOSAL_WIDTH * np.linalg.cholesky(0.5 * (moment_cov + moment_cov.T))
        self.centre = _first_moment(centre)
        self.log_det = float(np.sum(np.log(np.diag(self.factor))))

    def draw(self, rng: np.random.Generator, samples: int) -> FloatArray:
        """``samples`` draws in ``(mdf, g)`` (n, 4)."""
        chi = rng.chisquare(PROPOSAL_DOF, samples) / PROPOSAL_DOF
        whitened = rng.standard_normal((samples, 4)) / np.sqrt(chi)[:, None]
        return self.centre + whitened @ self.factor.T

    def log_density(self, theta: FloatArray) -> FloatArray:
        """The log density (n,) in ``theta`` (n, 4): the t's in ``(mdf, g)`` times the Jacobian ``mdf^3``."""
        whitened = np.linalg.solve(self.factor, (_first_moment(theta) - self.centre).T).T
        log_t = -0.5 * (PROPOSAL_DOF + 4.0) * np.log1p(np.sum(whitened * whitened, axis=1) / PROPOSAL_DOF)
        return LOG_T_CONSTANT + log_t - self.log_det + 3.0 * np.log(theta[:, 0])


class MixtureProposal:
    """A mixture of :class:`MomentProposal` components ``(centre, covariance)`` with log weights ``log_weights``
    (normalised here): draws split among them multinomially, the density the weighted sum of theirs."""

    def __init__(self, components: list[tuple[FloatArray, FloatArray]], log_weights: FloatArray) -> None:
        self.components = [MomentProposal(centre, cov) for centre, cov in components]
        log_weights = np.asarray(log_weights, dtype=float)
        self.log_weights = log_weights - np.logaddexp.reduce(log_weights)

    def draw(self, rng: np.random.Generator, samples: int) -> FloatArray:
        """``samples`` draws in ``(mdf, g)`` (n, 4)."""
        counts = rng.multinomial(samples, np.exp(self.log_weights))
        return np.concatenate([np.empty((0, 4))] + [c.draw(rng, n) for c, n in zip(self.components, counts, strict=True)])

    def log_density(self, theta: FloatArray) -> FloatArray:
        """The log density (n,) in ``theta`` (n, 4)."""
        logs = [w + c.log_density(theta) for c, w in zip(self.components, self.log_weights, strict=True)]
        return np.logaddexp.reduce(np.array(logs), axis=0)


def basin_minima(problem: IdentificationProblem, theta_fit: FloatArray) -> list[FloatArray]:
    """The distinct local minima (each (4,)) a least-squares polish reaches from ``theta_fit`` (4,) and from each of its
    :meth:`~estimators.parameters.FuelParameters.mirror_images`, lowest cost first (module docstring). Two minima
    are one basin when they differ by less than one Cramér-Rao std (at the lower one, with the residual's noise there)
    in every unknown: a polish converges to 1e-10 of the scale, distinct basins lie many std apart.
    Minima with no fuel consumed are left out (the tank is not seen there: no density around them in ``(mdf, bf)``)."""
    polish = LevenbergMarquardt()
    starts = [np.asarray(theta_fit, dtype=float), *problem.parameters.mirror_images(theta_fit)]
    minima = [polish.polish(problem, start).theta for start in starts]
    minima = [theta for theta in minima if theta[0] > problem.parameters.lower[0]]
    costs = problem.cost(np.array(minima), count=False) if minima else np.empty(0)
    distinct: list[tuple[FloatArray, FloatArray]] = []
    for index in np.argsort(costs, kind="stable"):
        theta = minima[index]
        if all(np.any(np.abs(theta - kept) > std) for kept, std in distinct):
            cov = np.linalg.inv(problem.fisher(theta, problem.noise_std(theta)[0]))
            distinct.append((theta, np.sqrt(np.diag(cov))))
    return [theta for theta, _ in distinct]


def prior_modes(
    problem: IdentificationProblem, minima: list[FloatArray], lower: FloatArray, upper: FloatArray
) -> list[FloatArray]:
    """The posterior's mode (4,) nearest each of ``minima``: a least-squares polish inside the physical prior's box
    ``lower``, ``upper`` (4,) from the minimum clipped into it (module docstring)."""
    model = problem.model
    inside = IdentificationModel(model.robot, "fuel", model.noise_std_rad_s, lower=lower, upper=upper).problem(problem.log)
    polish = LevenbergMarquardt()
    return [polish.polish(inside, np.clip(theta, lower, upper)).theta for theta in minima]


def _tank_at(
    problem: IdentificationProblem, fuel_kg: float, start: FloatArray, lower: FloatArray, upper: FloatArray
) -> FloatArray:
    """``theta`` (4,) with the fuel consumed ``fuel_kg`` and the tank polished by least squares inside the prior's box
    ``lower``, ``upper`` (4,) from ``start`` (3,)."""
    inner = lower[1:] + 1e-9 * (upper[1:] - lower[1:]), upper[1:] - 1e-9 * (upper[1:] - lower[1:])
    with threadpool_limits(limits=1, user_api="blas"):
        result = least_squares(
            lambda tank: problem.residuals(np.r_[fuel_kg, tank], count=False),
            np.clip(start, *inner),
            jac=lambda tank: problem.jacobian(np.r_[fuel_kg, tank], count=False)[:, 1:],
            bounds=(lower[1:], upper[1:]),
            x_scale=problem.parameters.scale[1:],
        )
    return np.r_[fuel_kg, result.x]


def valley_slices(
    problem: IdentificationProblem,
    theta_min: FloatArray,
    noise_std_rad_s: float,
    lower: FloatArray,
    upper: FloatArray,
) -> tuple[list[tuple[FloatArray, FloatArray]], FloatArray]:
    """The valley's slices (module docstring): Gaussians ``(centre (4,), covariance (4, 4))`` along the profile of the
    cost in the fuel consumed from the minimum ``theta_min`` (4,), and their log Laplace masses.

    The grid: ``mdf_k = capacity VALLEY_RATIO^-k`` down to :data:`VALLEY_FLOOR` of the capacity (``upper[0]``), swept
    from the point nearest the minimum's fuel out both ways, each slice's tank polished from its neighbour's; a sweep
    stops where a slice's mass is below :data:`NEGLIGIBLE_WEIGHT` of the largest so far. At slice ``k``: the tank's
    conditional covariance ``C_bb = F_bb^-1`` and the valley's slope ``s = -C_bb F_bm`` (``F`` the Fisher
    information there), the fuel's std half the cell ``Delta_k`` (the proposal's width makes it a cell); the mass
    ``L(theta_k) sqrt(det C_bb) Delta_k``, the profile's Laplace integral over the tank times the cell."""
    capacity = float(upper[0])
    grid = capacity * VALLEY_RATIO ** -np.arange(int(np.log(1.0 / VALLEY_FLOOR) / np.log(VALLEY_RATIO)) + 1)
    reference = float(problem.cost(np.asarray(theta_min, dtype=float)[None], count=False)[0])
    start = int(np.argmin(np.abs(np.log(grid / max(float(theta_min[0]), grid[-1])))))
    slices: dict[int, tuple[FloatArray, FloatArray, float]] = {}
    for sweep in (range(start, len(grid)), range(start - 1, -1, -1)):
        tank = np.asarray(theta_min, dtype=float)[1:]
        for k in sweep:
            theta = _tank_at(problem, float(grid[k]), tank, lower, upper)
            tank = theta[1:]
            fisher = problem.fisher(theta, noise_std_rad_s)
            cov_tank = np.linalg.inv(fisher[1:, 1:])
            slope = -cov_tank @ fisher[1:, 0]
            cell = grid[k] * (VALLEY_RATIO - 1.0 / VALLEY_RATIO) / 2.0
            std = cell / 2.0
            cov = np.empty((4, 4))
            cov[0, 0] = std * std
            cov[0, 1:] = cov[1:, 0] = std * std * slope
            cov[1:, 1:] = cov_tank + std * std * np.outer(slope, slope)
            log_mass = _log_likelihood(problem, noise_std_rad_s, reference, theta[None])[0]
            log_mass += 0.5 * np.linalg.slogdet(cov_tank)[1] + np.log(cell)
            slices[k] = theta, cov, log_mass
            if log_mass < max(m for _, _, m in slices.values()) + np.log(NEGLIGIBLE_WEIGHT):
                break
    kept = [slices[k] for k in sorted(slices)]
    return [(theta, cov) for theta, cov, _ in kept], np.array([m for _, _, m in kept])


def kernel_bandwidth(effective_samples: float, dim: int = 4) -> float:
    """Silverman's rule for a Gaussian kernel density of ``effective_samples`` draws in ``dim`` dimensions, in units
    of the draws' std: ``(4 / ((dim + 2) n))^(1 / (dim + 4))`` (0.49 at 200 effective draws in 4 dimensions)."""
    return float((4.0 / ((dim + 2) * effective_samples)) ** (1.0 / (dim + 4)))


class PredictedPrior:
    """The next window's prior from a window's weighted particles (module docstring): a Gaussian mixture, one kernel
    per particle, centred at ``a theta_i + (1 - a) mean`` with covariance ``h^2 C`` (``h`` :func:`kernel_bandwidth`,
    ``a = sqrt(1 - h^2)``: Liu and West's shrinkage keeps the particles' mean and covariance ``C``), plus the gap's
    random-walk variance ``step_std_kg^2`` in the fuel."""

    def __init__(self, theta: FloatArray, log_weights: FloatArray, step_std_kg: float) -> None:
        weights = np.exp(log_weights - log_weights.max())
        kept = weights > NEGLIGIBLE_WEIGHT
        effective = float(weights.sum() ** 2 / np.sum(weights * weights))
        self.weights = weights[kept] / weights[kept].sum()
        mean, cov = _moments(theta, log_weights)
        h = kernel_bandwidth(effective)
        shrink = np.sqrt(1.0 - h * h)
        self.centres = shrink * theta[kept] + (1.0 - shrink) * mean
        kernel = h * h * cov
        kernel[0, 0] += step_std_kg**2
        self.factor = np.linalg.cholesky(kernel)
        self.log_det = float(np.sum(np.log(np.diag(self.factor))))

    def draw(self, rng: np.random.Generator, samples: int) -> FloatArray:
        """``samples`` draws of ``theta`` (n, 4)."""
        index = rng.choice(len(self.weights), size=samples, p=self.weights)
        return self.centres[index] + rng.standard_normal((samples, 4)) @ self.factor.T

    def log_density(self, theta: FloatArray) -> FloatArray:
        """The log density (n,) at ``theta`` (n, 4)."""
        centres = np.linalg.solve(self.factor, self.centres.T).T
        norms = np.sum(centres * centres, axis=1)
        out = [np.empty(0)]
        for i in range(0, len(theta), CHUNK):
            z = np.linalg.solve(self.factor, theta[i : i + CHUNK].T).T
            squared = np.sum(z * z, axis=1)[:, None] + norms[None] - 2.0 * z @ centres.T
            out.append(np.logaddexp.reduce(np.log(self.weights)[None] - 0.5 * squared, axis=1))
        return np.concatenate(out) - self.log_det - 2.0 * np.log(2.0 * np.pi)


def _log_likelihood(problem: IdentificationProblem, noise_std_rad_s: float, reference: float, theta: FloatArray) -> FloatArray:
    """``-(RSS(theta) - RSS(reference)) / (2 sigma^2)`` (n,) on ``problem`` for ``theta`` (n, 4), in chunks of
    :data:`CHUNK` (``reference``: the cost, RSS / 3T, the log-likelihood is taken from)."""
    chunks = [problem.cost(theta[i : i + CHUNK], count=False) for i in range(0, len(theta), CHUNK)]
    return -(np.concatenate([np.empty(0), *chunks]) - reference) * 3 * problem.n_samples / (2.0 * noise_std_rad_s**2)


def _from_moment(moment: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """``theta`` (m, 4) of the draws ``(mdf, g)`` (n, 4) that lie inside the prior's box ``lower``, ``upper``."""
    mass = moment[:, 0]
    usable = (mass > lower[0]) & (mass < upper[0])
    theta = np.column_stack([mass, moment[:, 1:] / np.where(usable, mass, 1.0)[:, None]])[usable]
    return theta[np.all((theta[:, 1:] > lower[1:]) & (theta[:, 1:] < upper[1:]), axis=1)]


class FuelPaths:
    """Importance-sampled paths of the fuel unknowns' posterior through the windows of a mission (module docstring).

    Started on the first window around its least-squares fit ``theta_fit`` (4,) and the other ``basins``' minima (each
    (4,), :func:`basin_minima`; a mixture proposal, module docstring) with gyro noise ``noise_std_rad_s``;
    :meth:`extend` moves to the next window after a gap over which the fuel consumed takes a random-walk step (the
    tank does not move); :meth:`posterior` gives the mean and covariance of the current window's unknowns. Every
    draw comes from ``rng``; ``samples`` draws per batch. ``regularised``: whether the current window was sampled
    afresh under the :class:`PredictedPrior` (not an exact push of the paths).
    """

    def __init__(
        self,
        problem: IdentificationProblem,
        theta_fit: FloatArray,
        noise_std_rad_s: float,
        rng: np.random.Generator,
        samples: int = 8000,
        schedule: FuelSchedule | None = None,
        basins: Sequence[FloatArray] = (),
    ) -> None:
        self.lower, self.upper = physical_prior_box(problem, schedule)
        self.names = problem.parameters.names
        theta_fit = np.asarray(theta_fit, dtype=float)
        if not (theta_fit.shape == (4,) and theta_fit[0] > 0.0 and np.all(np.isfinite(theta_fit))):
            raise SpaceIdInputError(f"fuel posterior: expected a fit with fuel consumed > 0 kg, got {theta_fit.tolist()}")
        _check_noise(noise_std_rad_s, 0.0)
        if samples < 1:
            raise SpaceIdInputError(f"fuel posterior: expected samples >= 1, got {samples}")
        self.rng = rng
        self.samples = samples
        self.draws = 0
        self.windows = 1
        self.regularised = False
        centres = prior_modes(problem, [theta_fit, *(np.asarray(b, dtype=float) for b in basins)], self.lower, self.upper)
        covariances = [np.linalg.inv(problem.fisher(centre, noise_std_rad_s)) for centre in centres]
        reference = float(problem.cost(theta_fit[None], count=False)[0])
        log_mass = _log_likelihood(problem, noise_std_rad_s, reference, np.array(centres))
        log_mass += np.array([0.5 * np.linalg.slogdet(cov)[1] for cov in covariances])
        valley, valley_mass = valley_slices(problem, centres[0], noise_std_rad_s, self.lower, self.upper)
        log_mass = np.r_[log_mass - np.logaddexp.reduce(log_mass), valley_mass - np.logaddexp.reduce(valley_mass)]
        proposal = MixtureProposal([*zip(centres, covariances, strict=True), *valley], log_mass)

        def batch() -> tuple[FloatArray, FloatArray]:
            theta = _from_moment(proposal.draw(self.rng, self.samples), self.lower, self.upper)
            return theta, _log_likelihood(problem, noise_std_rad_s, reference, theta) - proposal.log_density(theta)

        self._sample(batch)

    def _sample(self, batch: Callable[[], tuple[FloatArray, FloatArray]]) -> None:
        """Pool ``batch()``'s draws and log weights until the effective sample size reaches
        :data:`MIN_EFFECTIVE_SAMPLES`; raises after :data:`MAX_BATCHES` (never a silent fallback)."""
        thetas, log_weights = [], []
        for _ in range(MAX_BATCHES):
            theta, log_w = batch()
            self.draws += self.samples
            thetas.append(theta)
            log_weights.append(log_w)
            self.theta, self.log_weights = np.concatenate(thetas), np.concatenate(log_weights)
            if self.effective_samples() >= MIN_EFFECTIVE_SAMPLES:
                return
        raise SpaceIdInputError(
            f"fuel posterior: effective sample size {self.effective_samples():.0f} after {self.draws} draws on window "
            f"{self.windows - 1} of the paths, below {MIN_EFFECTIVE_SAMPLES:.0f}: the posterior is too far from the "
            "proposal to estimate its moments"
        )

    def effective_samples(self) -> float:
        """``(sum w)^2 / sum w^2`` of the paths' weights."""
        if not self.log_weights.size:
            return 0.0
        weights = np.exp(self.log_weights - self.log_weights.max())
        return float(weights.sum() ** 2 / np.sum(weights * weights))

    def extend(
        self,
        problem: IdentificationProblem,
        noise_std_rad_s: float,
        step_std_kg: float,
        guess: tuple[FloatArray, FloatArray],
        regularise: bool = False,
    ) -> None:
        """Move to the next window (module docstring): each path takes the gap's random-walk step of std
        ``step_std_kg`` in the fuel (outside the box the prior is 0: dropped) and is weighted by the window's
        likelihood (noise ``noise_std_rad_s``); if fewer than :data:`MIN_EFFECTIVE_SAMPLES` remain effective, the
        window is sampled afresh under the :class:`PredictedPrior` of the last, from an equal mixture of that prior,
        a proposal matched to ``guess`` (mean (4,), covariance (4, 4): a Gaussian approximation of the new
        posterior, e.g. the filter's) and the window's :func:`valley_slices` from its least-squares minimum nearest
        the guess, each slice weighted by its Laplace mass times the prior at its centre; ``regularise``: sample
        afresh even if enough paths stay effective (to compare the two)."""
        if problem.parameters.names != self.names:
            raise SpaceIdInputError(f"fuel posterior: the window's unknowns {problem.parameters.names} differ")
        _check_noise(noise_std_rad_s, step_std_kg)
        centre = np.clip(np.asarray(guess[0], dtype=float), self.lower, self.upper)
        reference = float(problem.cost(centre[None], count=False)[0])
        before = self.theta, self.log_weights
        theta = self.theta.copy()
        theta[:, 0] += step_std_kg * self.rng.standard_normal(len(theta))
        inside = np.all((theta > self.lower) & (theta < self.upper), axis=1)
        self.theta = theta[inside]
        self.log_weights = self.log_weights[inside] + _log_likelihood(problem, noise_std_rad_s, reference, self.theta)
        self.windows += 1
        self.regularised = regularise or self.effective_samples() < MIN_EFFECTIVE_SAMPLES
        if not self.regularised:
            return
        prior = PredictedPrior(*before, step_std_kg)
        minimum = LevenbergMarquardt().polish(problem, centre).theta
        valley, valley_mass = valley_slices(problem, minimum, noise_std_rad_s, self.lower, self.upper)
        valley_mass = valley_mass + prior.log_density(np.array([theta for theta, _ in valley]))
        valley_mass -= np.logaddexp.reduce(valley_mass)
        proposal = MixtureProposal([(centre, guess[1]), *valley], np.r_[np.log(0.5), np.log(0.5) + valley_mass])

        def batch() -> tuple[FloatArray, FloatArray]:
            n_moment = int(self.rng.binomial(self.samples, 2.0 / 3.0))
            drawn = [_from_moment(proposal.draw(self.rng, n_moment), self.lower, self.upper)]
            drawn.append(prior.draw(self.rng, self.samples - n_moment))
            theta = np.concatenate(drawn)
            theta = theta[np.all((theta > self.lower) & (theta < self.upper), axis=1)]
            log_prior = prior.log_density(theta)
            log_q = np.logaddexp(np.log(2.0 / 3.0) + proposal.log_density(theta), np.log(1.0 / 3.0) + log_prior)
            return theta, log_prior + _log_likelihood(problem, noise_std_rad_s, reference, theta) - log_q

        self.draws = 0
        self._sample(batch)

    def posterior(self) -> FuelPosterior:
        """The weighted mean and covariance of the paths' current window."""
        mean, cov = _moments(self.theta, self.log_weights)
        return FuelPosterior(mean, cov, self.draws, self.effective_samples())


def _check_noise(noise_std_rad_s: float, step_std_kg: float) -> None:
    """Raise unless the noise std is > 0 and the random-walk step's std >= 0, both finite."""
    if not (np.isfinite(noise_std_rad_s) and noise_std_rad_s > 0.0 and np.isfinite(step_std_kg) and step_std_kg >= 0.0):
        raise SpaceIdInputError(f"fuel posterior: expected noise std > 0 and step std >= 0, got {noise_std_rad_s}, {step_std_kg}")


def _moments(theta: FloatArray, log_weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The weighted mean (4,) and covariance (4, 4) of ``theta`` (n, 4) with weights ``exp(log_weights)``."""
    weights = np.exp(log_weights - log_weights.max())
    weights /= weights.sum()
    mean = weights @ theta
    centred = theta - mean
    cov = (weights[:, None] * centred).T @ centred
    return mean, 0.5 * (cov + cov.T)


def fuel_posterior(
    problem: IdentificationProblem,
    theta_fit: FloatArray,
    noise_std_rad_s: float,
    rng: np.random.Generator,
    samples: int = 8000,
    schedule: FuelSchedule | None = None,
    basins: Sequence[FloatArray] = (),
) -> FuelPosterior:
    """The posterior mean and covariance of the fuel unknowns on ``problem`` alone (see the module docstring).

    ``theta_fit`` (4,): the window's least-squares fit (inside the prior box: its fuel above 0); ``noise_std_rad_s``:
    the gyro noise per sample and axis; ``samples``: draws per batch; ``basins``: other minima the proposal covers too."""
    return FuelPaths(problem, theta_fit, noise_std_rad_s, rng, samples, schedule, basins).posterior()


def expected_nees(posterior: FuelPosterior, x: FloatArray, P: FloatArray) -> float:
    """The mean NEES of a Gaussian estimate ``x`` (k,), ``P`` (k, k) when the truth is drawn from ``posterior``:
    ``tr(P^-1 C) + d^T P^-1 d``, ``C`` the posterior's covariance and ``d = x - mean`` (k when they agree)."""
    d = np.asarray(x, dtype=float) - posterior.mean
    cov = np.asarray(P, dtype=float)
    return float(np.trace(np.linalg.solve(cov, posterior.covariance)) + d @ np.linalg.solve(cov, d))
