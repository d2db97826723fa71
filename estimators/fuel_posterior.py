"""The posterior mean and covariance of the fuel unknowns on one window, by importance sampling under the physical prior.

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.problem import IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.mission import FuelSchedule

#: the proposal's degrees of freedom: few, for tails heavier than the posterior's (a t with 4 has a finite covariance)
PROPOSAL_DOF = 4.0

#: the proposal's scale over the linearised std: 2, so the proposal's central 95 % holds the posterior's bend out to
#: about 4 linearised std (efficiency only: the importance weights correct any proposal that covers the posterior)
PROPOSAL_WIDTH = 2.0

#: the effective sample size the moments need: a variance from n effective draws has a relative std of about
#: sqrt(2 / n), 0.1 at 200
MIN_EFFECTIVE_SAMPLES = 200.0

#: at most this many batches of draws before giving up with an error
MAX_BATCHES = 8

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


def fuel_posterior(
    problem: IdentificationProblem,
    theta_fit: FloatArray,
    noise_std_rad_s: float,
    rng: np.random.Generator,
    samples: int = 8000,
    schedule: FuelSchedule | None = None,
) -> FuelPosterior:
    """The posterior mean and covariance of the fuel unknowns on ``problem`` (see the module docstring).

    ``theta_fit`` (4,): the window's least-squares fit (inside the prior box: its fuel above 0); ``noise_std_rad_s``:
    the gyro noise per sample and axis; ``samples``: draws per batch."""
    lower, upper = physical_prior_box(problem, schedule)
    theta_fit = np.asarray(theta_fit, dtype=float)
    if not (theta_fit[0] > 0.0 and np.all(np.isfinite(theta_fit))):
        raise SpaceIdInputError(f"fuel posterior: expected a fit with fuel consumed > 0 kg, got {theta_fit.tolist()}")
    if not (np.isfinite(noise_std_rad_s) and noise_std_rad_s > 0.0 and samples >= 1):
        raise SpaceIdInputError(f"fuel posterior: expected noise std > 0 and samples >= 1, got {noise_std_rad_s}, {samples}")
    covariance = np.linalg.inv(problem.fisher(theta_fit, noise_std_rad_s))
    to_moment = np.eye(4)
    to_moment[1:, 0] = theta_fit[1:]
    to_moment[1:, 1:] *= theta_fit[0]
    moment_cov = to_moment @ covariance @ to_moment.T
    factor = PROPOSAL_WIDTH * np.linalg.cholesky(0.5 * (moment_cov + moment_cov.T))
    centre = _first_moment(theta_fit)
    rss_scale = 3 * problem.n_samples / (2.0 * noise_std_rad_s**2)
    cost_fit = float(problem.cost(theta_fit[None], count=False)[0])
    thetas, log_weights = [], []
    for _ in range(MAX_BATCHES):
        chi = rng.chisquare(PROPOSAL_DOF, samples) / PROPOSAL_DOF
        whitened = rng.standard_normal((samples, 4)) / np.sqrt(chi)[:, None]
        moment = centre + whitened @ factor.T
        log_proposal = -0.5 * (PROPOSAL_DOF + 4.0) * np.log1p(np.sum(whitened * whitened, axis=1) / PROPOSAL_DOF)
        mass = moment[:, 0]
        inside = (mass > lower[0]) & (mass < upper[0])
        theta = np.column_stack([mass, moment[:, 1:] / np.where(inside, mass, 1.0)[:, None]])
        inside &= np.all((theta[:, 1:] > lower[1:]) & (theta[:, 1:] < upper[1:]), axis=1)
        kept = theta[inside]
        cost = np.concatenate(
            [np.empty(0)] + [problem.cost(kept[i : i + CHUNK], count=False) for i in range(0, len(kept), CHUNK)]
        )
        # density in theta: the t's in (mdf, g) times the Jacobian mdf^3; the prior is flat inside the box
        thetas.append(kept)
        log_weights.append(-(cost - cost_fit) * rss_scale - (log_proposal[inside] + 3.0 * np.log(kept[:, 0])))
        log_w = np.concatenate(log_weights)
        weights = np.exp(log_w - log_w.max()) if log_w.size else log_w
        effective = float(weights.sum() ** 2 / np.sum(weights * weights)) if log_w.size else 0.0
        if effective >= MIN_EFFECTIVE_SAMPLES:
            drawn = np.concatenate(thetas)
            weights = weights / weights.sum()
            mean = weights @ drawn
            centred = drawn - mean
            cov = (weights[:, None] * centred).T @ centred
            return FuelPosterior(mean, 0.5 * (cov + cov.T), samples * len(thetas), effective)
    raise SpaceIdInputError(
        f"fuel posterior: effective sample size {effective:.0f} after {MAX_BATCHES * samples} draws, below "
        f"{MIN_EFFECTIVE_SAMPLES:.0f}: the window's posterior is too far from the proposal to estimate its moments"
    )
