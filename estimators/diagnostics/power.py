"""Expected detection power: how often can ``diagnose``'s likelihood-ratio test call a hidden effect significant?

On a simulated log with one effect hidden, the Fisher information of the candidate model (the model's unknowns
plus the effect's) at the true parameters, from the gyro (white noise of the per-sample std recorded in the
truth's sensor settings, ``truth["noise"]["gyro_std_rad_s"]`` as in truth.json) and, when the log has an attitude
source, from the attitude channel (:class:`~estimators.attitude_channel.AttitudeChannel`, its error model
fitted at the truth, as ``diagnose`` fits it). With the model's own unknowns free, the effect's likelihood ratio is
non-central chi-square with ``k_e`` degrees of freedom (the effect's unknowns) and non-centrality
``lambda = d^T S d``: ``S`` the Schur complement of the effect's block (the information left once the other unknowns
have absorbed what they can), ``d`` the effect's true unknowns minus the nearest point without the effect (the
term's nominal, except the unknowns that only exist with the effect, :data:`ONLY_WITH_EFFECT`, which stay at the
truth: a slosh without mass has no frequency, and the nearest such model to the truth is the true frequency and
damping with zero mass). The power against the test's threshold (``alpha`` Bonferroni-divided over
``n_candidates``) is ``ncx2.sf(chi2.isf(alpha / n_candidates, k_e), k_e, lambda)``: an upper bound on how often
``diagnose`` can name the effect (naming also needs the lowest BIC, plausibility and the explained fraction).
Local approximation: the Fisher information at the truth. It holds while the other unknowns' linear absorption of
the effect is a small move; where it asks for a large one the nonlinear model cannot follow, and ``lambda`` is too
small (a 20 kg pendulum slosh on paper6, noise-free, 20 s: ``lambda`` 10.1 where the best fit without the effect
leaves 27.4, its linear absorption moving the fuel by 24 kg): the power is then a lower bound.

A slosh is tested with the model it was simulated with: a pendulum truth (``slosh_model = "pendulum"`` in
``hidden_effects``) with the pendulum term (:func:`candidate_spec`; six unknowns, its rod's axis and curvature at the
truth in the nearest model without the effect), a spring-mass with the spring; likewise a drifting torque (a non-zero
``external_torque_rate_Nm_s``) with the drifting term (nine unknowns), a constant one with the constant term.
``diagnose`` fits both models of each, so its Bonferroni divides ``alpha`` over two tests more than its candidates, and
the candidates have half of ``alpha`` (:data:`N_TESTS`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from scipy.stats import chi2, ncx2

from estimators.diagnostics.diagnose import (
    CANDIDATE_VARIANTS,
    CLEAN_LOG_FAMILIES,
    DEFAULT_CANDIDATES,
    candidate_model,
    simulated_variant,
)
from estimators.diagnostics.model_fit import independent_attitude_channel
from estimators.diagnostics.workflow import true_parameters
from estimators.problem import IdentificationModel, IdentificationProblem
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot

#: per effect, its unknowns that exist only when the effect does (they keep their true values in the nearest model
#: without the effect)
ONLY_WITH_EFFECT: dict[str, tuple[str, ...]] = {
    "slosh": (
        "slosh_frequency_hz",
        "slosh_damping_ratio",
        "slosh_axis_azimuth_rad",
        "slosh_axis_elevation_rad",
        "slosh_rod_curvature_per_m",
    )
}

#: the divisor of ``alpha`` in ``diagnose``'s significance with its default candidates: one likelihood-ratio test per
#: candidate and one more per extra model of an effect (:data:`~estimators.diagnostics.diagnose.CANDIDATE_VARIANTS`),
#: times the test families sharing ``alpha`` (:data:`~estimators.diagnostics.diagnose.CLEAN_LOG_FAMILIES`)
N_TESTS = CLEAN_LOG_FAMILIES * (len(DEFAULT_CANDIDATES) + sum(len(specs) - 1 for specs in CANDIDATE_VARIANTS.values()))


def candidate_spec(robot: Robot, effect: str, truth: dict[str, Any]) -> str:
    """The candidate spec of ``effect`` in the model the truth was simulated with
    (:func:`~estimators.diagnostics.diagnose.simulated_variant`): ``slosh[model=pendulum]`` for a pendulum slosh,
    ``external_torque[drift=true]`` for a drifting torque, else ``effect``."""
    return simulated_variant(robot, effect, truth.get("hidden_effects") or {}) or effect


def non_centrality(
    model_without_effect: IdentificationModel, effect: str, log: MeasurementLog, truth: dict[str, Any], alpha: float = 0.01
) -> float:
    """``lambda`` of ``effect``'s likelihood ratio against ``model_without_effect`` on ``log``, at ``truth``
    (truth.json's keys: the fuel state, ``hidden_effects`` and ``noise["gyro_std_rad_s"]``); see the module docstring.
    The attitude channel counts as ``diagnose`` uses it: given the gyro where its steps follow the gyro's noise
    (:func:`~estimators.diagnostics.model_fit.independent_attitude_channel` at the truth, at level ``alpha``).

    Raises:
        SpaceIdInputError: the truth lacks the model's unknowns or the gyro's noise, or the model already has ``effect``.
    """
    if effect in {spec.partition("[")[0] for spec in model_without_effect.effects}:
        raise SpaceIdInputError(f"expected power: the model already has the effect {effect!r}")
    model = candidate_model(model_without_effect, candidate_spec(model_without_effect.robot, effect, truth))
    theta = true_parameters(model, truth)
    if theta is None:
        raise SpaceIdInputError("expected power: needs the fuel unknowns in the model and the fuel state in the truth")
    problem = model.problem(log)
    term = problem.parameters.terms[-1]
    k = problem.parameters.n_params - term.n_params
    effect_off = _effect_off(term, effect, theta[k:])
    fisher, _ = _information(model, problem, log, theta, truth, alpha)
    schur = fisher[k:, k:] - fisher[k:, :k] @ np.linalg.solve(fisher[:k, :k], fisher[:k, k:])
    shift = theta[k:] - effect_off
    return float(shift @ schur @ shift)


class Separation(NamedTuple):
    """The true effect against one rival (:func:`separation`): ``non_centrality`` ``lambda_R`` and ``probability``
    that the effect's BIC is the lower."""

    non_centrality: float
    probability: float


def separation(
    model_without_effect: IdentificationModel,
    effect: str,
    log: MeasurementLog,
    truth: dict[str, Any],
    alpha: float = 0.01,
    rivals: tuple[str, ...] | None = None,
) -> dict[str, Separation]:
    """Per rival candidate (default: every other of :data:`~estimators.diagnostics.diagnose.DEFAULT_CANDIDATES`), the
    probability that the true ``effect`` wins the BIC comparison against it on ``log``: how often the log can tell
    the two apart, where :func:`expected_power` says only how often it can tell the effect from no effect.

    One model holds the fuel unknowns, the effect (at the truth) and every rival (off); its Fisher information at the
    truth (gyro and attitude channel, as :func:`non_centrality`). Against rival ``R``, ``lambda_R = d^T S_R d`` with
    ``S_R`` the Schur complement of the effect's block given the fuel unknowns AND ``R``'s (what of the effect's
    signature neither the fuel nor ``R`` can absorb, to first order; unknowns the information does not see at the
    truth, a rival slosh's frequency at zero mass, drop out by the pseudo-inverse). In the linear-Gaussian picture the
    rival's chi-square exceeds the effect's by ``X - Y``, ``X`` non-central chi-square (``k_E`` dof, ``lambda_R``: the
    effect's unknowns over the joint model's) and ``Y`` central chi-square (``k_R`` dof: the rival's over it), so the
    probability is ``P(X - Y > (k_E - k_R) ln n)``, ``n`` the values both channels give. Local and linear: a rival
    whose nonlinear unknowns (a slosh's frequency) could follow the effect only far from its nominal is judged at its
    nominal, so against it the probability is an upper bound."""
    names = rivals if rivals is not None else tuple(c for c in DEFAULT_CANDIDATES if c != effect)
    model = candidate_model(model_without_effect, candidate_spec(model_without_effect.robot, effect, truth))
    for rival in names:
        model = candidate_model(model, rival)
    theta = true_parameters(model, truth)
    if theta is None:
        raise SpaceIdInputError("separation: needs the fuel unknowns in the model and the fuel state in the truth")
    problem = model.problem(log)
    fisher, n_values = _information(model, problem, log, theta, truth, alpha)
    terms = problem.parameters.terms
    k_base = problem.parameters.base.n_params
    bounds = np.cumsum([k_base, *(t.n_params for t in terms)])
    effect_index = np.arange(bounds[0], bounds[1])
    base_index = np.arange(k_base)
    shift = theta[effect_index] - _effect_off(terms[0], effect, theta[effect_index])
    out = {}
    for r, rival in enumerate(names):
        rival_index = np.arange(bounds[r + 1], bounds[r + 2])
        nuisance = np.concatenate((base_index, rival_index))
        f_en = fisher[np.ix_(effect_index, nuisance)]
        schur = fisher[np.ix_(effect_index, effect_index)] - f_en @ np.linalg.pinv(fisher[np.ix_(nuisance, nuisance)]) @ f_en.T
        lam = float(shift @ schur @ shift)
        out[rival] = Separation(lam, wins_bic(lam, len(effect_index), len(rival_index), n_values))
    return out


def _information(
    model: IdentificationModel,
    problem: IdentificationProblem,
    log: MeasurementLog,
    theta: FloatArray,
    truth: dict[str, Any],
    alpha: float,
) -> tuple[FloatArray, int]:
    """The Fisher information (k, k) of ``model`` (``problem`` on ``log``) at ``theta``, and the values it comes from:
    the gyro's at the truth's noise, plus the attitude channel's as ``diagnose`` uses it (given the gyro where its
    steps follow the gyro's noise, at level ``alpha``; its error model fitted at ``theta``: the source's noise and the
    model's own wander)."""
    gyro_std = (truth.get("noise") or {}).get("gyro_std_rad_s")
    if gyro_std is None:
        raise SpaceIdInputError("expected power: the truth has no gyro noise (noise.gyro_std_rad_s, as in truth.json)")
    fisher = problem.fisher(theta, float(gyro_std))
    n_values = 3 * problem.n_samples
    channel = independent_attitude_channel(model, log, theta, alpha).channel
    if channel is not None:
        fisher = fisher + channel.fisher(theta, channel.estimate_noise(theta))
        n_values += channel.n_values
    return fisher, n_values


def _effect_off(term: Any, effect: str, truth_part: FloatArray) -> FloatArray:
    """The term's nominal (off) with the unknowns of :data:`ONLY_WITH_EFFECT` at their true values ``truth_part``."""
    off = term.nominal.copy()
    for name in ONLY_WITH_EFFECT.get(effect, ()):
        if name in term.names:
            off[term.names.index(name)] = truth_part[term.names.index(name)]
    return off


def wins_bic(lam: float, k_effect: int, k_rival: int, n_values: int) -> float:
    """``P(X - Y > (k_effect - k_rival) ln n_values)``, ``X ~ ncx2(k_effect, lam)``, ``Y ~ chi2(k_rival)``, by
    quadrature over ``Y`` (see :func:`separation`)."""
    margin = (k_effect - k_rival) * np.log(n_values)
    y = chi2.ppf(np.linspace(0.0, 1.0, 2001)[1:-1], k_rival)  # the rival's chi-square at its quantiles
    return float(np.mean(ncx2.sf(margin + y, k_effect, max(lam, 0.0))))


def power_of(lam: float, dof: int, alpha: float = 0.01, n_candidates: int = N_TESTS) -> float:
    """The power of a chi-square test with ``dof`` degrees of freedom at level ``alpha / n_candidates`` against a
    non-centrality ``lam``: ``ncx2.sf(chi2.isf(alpha / n_candidates, dof), dof, lam)``."""
    if not 0.0 < alpha < 1.0 or n_candidates < 1 or dof < 1:
        raise SpaceIdInputError(
            f"expected power: expected 0 < alpha < 1, n_candidates >= 1, dof >= 1, got {alpha}, {n_candidates}, {dof}"
        )
    return float(ncx2.sf(chi2.isf(alpha / n_candidates, dof), dof, max(lam, 0.0)))


def effect_dof(model_without_effect: IdentificationModel, effect: str, truth: dict[str, Any] | None = None) -> int:
    """The effect's unknowns ``k_e`` in the model ``truth`` was simulated with (:func:`candidate_spec`): the degrees
    of freedom of its likelihood ratio."""
    spec = effect if truth is None else candidate_spec(model_without_effect.robot, effect, truth)
    return candidate_model(model_without_effect, spec).parameters.terms[-1].n_params


def expected_power(
    model_without_effect: IdentificationModel,
    effect: str,
    log: MeasurementLog,
    truth: dict[str, Any],
    alpha: float = 0.01,
    n_candidates: int = N_TESTS,
) -> float:
    """The expected power of ``diagnose``'s test of ``effect`` on ``log`` (see the module docstring):
    :func:`power_of` of :func:`non_centrality`."""
    lam = non_centrality(model_without_effect, effect, log, truth, alpha)
    return power_of(lam, effect_dof(model_without_effect, effect, truth), alpha, n_candidates)
