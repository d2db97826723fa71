"""Which joint effect is the arm model missing, and where does it fail? The fixed-base counterpart of :mod:`estimators.diagnostics.diagnose`.

:func:`diagnose_arm` fits the model as it is and, for each candidate joint term not in it, the model with that term
added (every fit by least squares on the same prepared training movements, rows weighted by fixed per-joint noise
levels), and ranks them:

* candidates (:data:`CANDIDATES`): ``friction`` (Coulomb + viscous, the source's model), ``coulomb``, ``viscous``,
  ``stribeck``, ``offset`` (a constant torque or current bias), ``armature`` (rotor inertia) and
  ``coulomb_asymmetric`` (one Coulomb level per direction, replacing the symmetric term: one more parameter per
  joint);
* weights: each joint's noise std ``s_j`` from the fit with every candidate term at once (the best-fitting model, as
  the free-floating diagnosis takes the smallest residual std); ``chi2 = sum_rows (r / s_j)^2 / kappa`` with
  ``kappa`` the movement's :meth:`~estimators.arm.identification.Preparation.correlation_factor`: the prepared
  rows are low-pass filtered, so ``kappa`` (about 3.5) of them carry one independent sample's information about the
  slowly varying columns; the sample count ``N`` of the excess and the BIC is ``sum N_m / kappa_m`` likewise;
* scores: likelihood ratio ``chi2_baseline - chi2_candidate`` against chi-square with as many degrees of freedom as
  base parameters added (Bonferroni over the candidates: significant below ``alpha / m``), BIC ``chi2 + k ln N``, and
  the fraction of the baseline's excess over the noise (``chi2_baseline - (N - k)``) the candidate explains;
* evidence in the residual: per joint, the correlation of the baseline residual with ``sign(dq_j)``, ``dq_j`` and
  ``|s(dq_j)|`` (the signatures of Coulomb friction, viscous friction, and a friction level that differs with the
  direction, or an offset, against a model with symmetric Coulomb friction), with a two-sided test;
* verdict: the significant candidate with the lowest BIC if it explains at least
  :data:`~estimators.diagnostics.diagnose.EXPLAINED_FRACTION` of the excess; ``"none"`` when no candidate is
  significant; ``"unexplained"`` otherwise. ``family`` says ``"friction"`` for the four friction terms.

:func:`where_it_fails` finds the time windows of each movement whose held-out residual (model fitted on the other
movements) is far above the model's typical error, with
:func:`~estimators.diagnostics.residuals.failing_segments`; on the real UR5 logs these are the periods a person
pushed the arm (``WDist``, ``w_disturbance``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from estimators.arm.identification import Preparation, fit, raw_period
from estimators.arm.linear_ls import weighted_lstsq
from estimators.arm.model import ArmIdentificationModel, IdentificationRows
from estimators.diagnostics.diagnose import (
    EXPLAINED_FRACTION,
    NO_MISSING_EFFECT,
    UNEXPLAINED,
    CandidateScores,
    explained_fraction,
)
from estimators.diagnostics.residuals import Segment, failing_segments
from estimators.registry import make_estimator
from spaceid_gym.arm.friction import FRICTION_TERMS
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

#: candidate label -> (friction terms added, armature added)
CANDIDATES: dict[str, tuple[tuple[str, ...], bool]] = {
    "friction": (("coulomb", "viscous"), False),
    "coulomb": (("coulomb",), False),
    "viscous": (("viscous",), False),
    "stribeck": (("stribeck",), False),
    "offset": (("offset",), False),
    "armature": ((), True),
    "coulomb_asymmetric": (("coulomb_asymmetric",), False),
}
#: candidates that are friction
FRICTION_FAMILY = ("friction", "coulomb", "viscous", "stribeck", "coulomb_asymmetric")


def extended_model(model: ArmIdentificationModel, candidate: str) -> ArmIdentificationModel | None:
    """``model`` with the candidate's terms added (same robot and torque constants), or ``None`` if it has them all."""
    if candidate not in CANDIDATES:
        raise SpaceIdInputError(f"candidate: unknown {candidate!r}; expected one of {', '.join(CANDIDATES)}")
    return _with_terms(model, *CANDIDATES[candidate])


def _with_terms(model: ArmIdentificationModel, terms: Iterable[str], armature: bool) -> ArmIdentificationModel | None:
    """``model`` with the friction ``terms`` (and ``armature``) added, or ``None`` if it has them all."""
    present = set(model.regressor.friction.terms)
    wanted = present | set(terms)
    if "coulomb_asymmetric" in wanted:  # it replaces the symmetric term (collinear with it)
        wanted.discard("coulomb")
    if wanted == present and (not armature or model.regressor.armature):
        return None
    friction = dataclasses.replace(model.regressor.friction, terms=tuple(t for t in FRICTION_TERMS if t in wanted))
    return ArmIdentificationModel.build(model.robot, friction, model.regressor.armature or armature, model.torque_constants_Nm_A)


@dataclass
class ArmModelFit(CandidateScores):
    """One weighted least-squares fit of a model on the training movements, and its scores (module docstring).

    ``n_rows`` is the effective number of independent rows, ``sum N_m / kappa_m``; ``residual_rms`` (n,) per joint;
    ``rows`` the movements' identification rows for this model.
    """

    label: str
    model: ArmIdentificationModel
    theta: FloatArray
    chi2: float
    n_rows: float
    residual_rms: FloatArray
    rows: dict[str, IdentificationRows] = field(default_factory=dict, repr=False)

    @property
    def n_params(self) -> int:
        """Base parameters of the model."""
        return self.model.n_params

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return {
            "candidate": self.label,
            "model": self.model.describe(),
            "n_params": self.n_params,
            "chi2": self.chi2,
            **self.scores(),
            "residual_rms_per_joint": self.residual_rms.tolist(),
        }


@dataclass
class ResidualCorrelation:
    """Per joint (n,): correlation of the baseline residual with ``sign(dq_j)``, ``dq_j`` and ``|s(dq_j)|`` (the smooth
    sign's magnitude: 1 when the joint moves, 0 at rest; the signature of asymmetric Coulomb friction, or of an offset,
    left out of a model with symmetric Coulomb friction), and two-sided p-values."""

    with_sign: FloatArray
    with_rate: FloatArray
    p_sign: FloatArray
    p_rate: FloatArray
    with_moving: FloatArray | None = None
    p_moving: FloatArray | None = None

    def describe(self, alpha: float) -> str:
        """The joints whose residual correlates significantly (Bonferroni over all the tests)."""
        n = len(self.with_sign)
        moving = (
            (np.zeros(n), np.ones(n)) if self.with_moving is None or self.p_moving is None else (self.with_moving, self.p_moving)
        )
        level = alpha / ((2 if self.with_moving is None else 3) * n)
        parts = []
        for j in range(n):
            hits = [
                f"{name} (r = {value:+.2f})"
                for name, value, p in (
                    (f"sign(dq{j + 1})", self.with_sign[j], self.p_sign[j]),
                    (f"dq{j + 1}", self.with_rate[j], self.p_rate[j]),
                    (f"|s(dq{j + 1})|", moving[0][j], moving[1][j]),
                )
                if p < level
            ]
            if hits:
                parts.append(f"joint {j + 1} with {' and '.join(hits)}")
        return "; ".join(parts) if parts else "no joint's residual correlates with sign(dq) or dq"


@dataclass
class ArmDiagnosis:
    """What :func:`diagnose_arm` found: verdict, reason, the fits (best BIC first) and the residual evidence."""

    verdict: str
    family: str | None
    reason: str
    baseline: ArmModelFit
    candidates: list[ArmModelFit]
    correlation: ResidualCorrelation
    noise_std: FloatArray
    alpha: float
    extra: dict[str, Any] = field(default_factory=dict)

    def best(self) -> ArmModelFit | None:
        """The fit of the named candidate, if any."""
        return next((f for f in self.candidates if f.label == self.verdict), None)

    def to_dict(self) -> dict[str, Any]:
        """The ``arm diagnose --out`` JSON."""
        c = self.correlation
        return {
            "verdict": self.verdict,
            "family": self.family,
            "reason": self.reason,
            "alpha": self.alpha,
            "baseline": self.baseline.to_dict(),
            "candidates": [f.to_dict() for f in self.candidates],
            "noise_std_per_joint": self.noise_std.tolist(),
            "residual_correlation": {
                "with_sign_dq": c.with_sign.tolist(),
                "with_dq": c.with_rate.tolist(),
                "p_sign_dq": c.p_sign.tolist(),
                "p_dq": c.p_rate.tolist(),
                "with_abs_smooth_sign_dq": None if c.with_moving is None else c.with_moving.tolist(),
                "p_abs_smooth_sign_dq": None if c.p_moving is None else c.p_moving.tolist(),
            },
            **self.extra,
        }


def _weighted_fit(
    label: str, model: ArmIdentificationModel, logs: Mapping[str, ArmLog], preparation: Preparation, std: FloatArray | None
) -> ArmModelFit:
    """Least squares of ``model`` on the ``logs`` with per-joint std ``std`` (n,) (``None``: unweighted)."""
    rows = preparation.all_rows(model, logs)
    problem = model.problem(rows)
    row_std = None if std is None else std[problem.row_group]
    theta, _ = weighted_lstsq(problem, row_std)
    residual = problem.residuals(theta, count=False)
    kappa = np.concatenate(
        [np.full(item.log.effort.size, preparation.correlation_factor(raw_period(logs[name]))) for name, item in rows.items()]
    )
    weights = (np.ones_like(residual) if row_std is None else 1.0 / row_std**2) / kappa
    rms = np.sqrt(np.bincount(problem.row_group, residual**2) / np.bincount(problem.row_group))
    return ArmModelFit(label, model, theta, float(weights @ residual**2), float(np.sum(1.0 / kappa)), rms, rows)


def _correlation(model: ArmIdentificationModel, theta: FloatArray, rows: Mapping[str, IdentificationRows]) -> ResidualCorrelation:
    residual = np.concatenate([item.log.effort - model.predict(theta, item) for item in rows.values()])
    dq = np.concatenate([item.log.dq_rad_s for item in rows.values()])
    n = len(residual)

    def corr(a: FloatArray, b: FloatArray) -> tuple[float, float]:
        if np.std(a) == 0.0 or np.std(b) == 0.0:
            return 0.0, 1.0
        r = float(np.corrcoef(a, b)[0, 1])
        t = r * math.sqrt((n - 2) / max(1.0 - r * r, 1e-300))
        return r, float(2.0 * stats.t.sf(abs(t), n - 2))

    magnitude = np.abs(model.regressor.friction.smooth_sign(dq))
    sign = [corr(residual[:, j], np.sign(dq[:, j])) for j in range(dq.shape[1])]
    rate = [corr(residual[:, j], dq[:, j]) for j in range(dq.shape[1])]
    moving = [corr(residual[:, j], magnitude[:, j]) for j in range(dq.shape[1])]
    return ResidualCorrelation(
        np.array([s[0] for s in sign]),
        np.array([r[0] for r in rate]),
        np.array([s[1] for s in sign]),
        np.array([r[1] for r in rate]),
        np.array([m[0] for m in moving]),
        np.array([m[1] for m in moving]),
    )


def diagnose_arm(
    model: ArmIdentificationModel,
    logs: Mapping[str, ArmLog],
    preparation: Preparation | None = None,
    candidates: tuple[str, ...] | list[str] | None = None,
    alpha: float = 0.01,
) -> ArmDiagnosis:
    """Rank the candidate joint terms for ``model`` on the raw ``logs`` through ``preparation`` (default settings)
    (module docstring)."""
    preparation = preparation or Preparation()
    if not 0.0 < alpha < 1.0:
        raise SpaceIdInputError(f"alpha: expected a level in (0, 1), got {alpha!r}")
    names = list(CANDIDATES) if candidates is None else list(candidates)
    extended = {name: extended_model(model, name) for name in names}
    extended = {name: m for name, m in extended.items() if m is not None}
    added = [CANDIDATES[name] for name in extended]
    everything = _with_terms(model, [t for terms, _ in added for t in terms], any(a for _, a in added)) or model
    noise_std = _weighted_fit("all", everything, logs, preparation, None).residual_rms
    baseline = _weighted_fit("baseline", model, logs, preparation, noise_std)
    fits = [_weighted_fit(name, m, logs, preparation, noise_std) for name, m in extended.items()]
    n = baseline.n_rows
    baseline.bic = baseline.chi2 + baseline.n_params * math.log(n)
    excess = baseline.chi2 - (n - baseline.n_params)
    for f in fits:
        k = f.n_params - baseline.n_params
        f.bic = f.chi2 + f.n_params * math.log(n)
        f.delta_bic = f.bic - baseline.bic
        f.lr_statistic = baseline.chi2 - f.chi2
        f.p_value = float(stats.chi2.sf(max(f.lr_statistic, 0.0), max(k, 1)))
        f.significant = f.p_value < alpha / max(len(fits), 1)
        f.explained_fraction = explained_fraction(f.lr_statistic, excess)
    fits.sort(key=lambda f: f.bic)
    correlation = _correlation(model, baseline.theta, baseline.rows)
    significant = [f for f in fits if f.significant]
    if not significant:
        verdict, reason = NO_MISSING_EFFECT, "no candidate term is significant"
    else:
        best = significant[0]
        if best.explained_fraction >= EXPLAINED_FRACTION:
            verdict = best.label
            reason = (
                f"adding {best.label} lowers the BIC by {-best.delta_bic:.0f} (likelihood ratio {best.lr_statistic:.0f}, "
                f"p = {best.p_value:.2g}) and explains {100 * best.explained_fraction:.0f} % of the excess over the noise; "
                f"residual: {correlation.describe(alpha)}"
            )
        else:
            verdict = UNEXPLAINED
            reason = (
                f"the best significant candidate ({best.label}) explains only {100 * best.explained_fraction:.0f} % of the "
                f"excess over the noise; residual: {correlation.describe(alpha)}"
            )
    family = "friction" if verdict in FRICTION_FAMILY else (None if verdict in (NO_MISSING_EFFECT, UNEXPLAINED) else verdict)
    return ArmDiagnosis(verdict, family, reason, baseline, fits, correlation, noise_std, alpha)


# ---------------------------------------------------------------------- where it fails
@dataclass
class FailingPeriods:
    """Per movement, the windows whose held-out residual is far above the model's typical error.

    Attributes:
        segments: movement -> ranked :class:`~estimators.diagnostics.residuals.Segment` list.
        reference_std: movement -> (n,) its typical error level per joint (the square root of the median over its
            windows of the window's mean square held-out residual), the "noise" of the tests.
        window_s: window length, s.
    """

    segments: dict[str, list[Segment]]
    reference_std: dict[str, FloatArray]
    window_s: float

    def ranked(self) -> list[tuple[str, Segment]]:
        """Every flagged window over all movements, worst (largest RMS over the reference) first."""
        pairs = [(name, s) for name, segments in self.segments.items() for s in segments]
        return sorted(pairs, key=lambda pair: -pair[1].rms_over_noise)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "typical_level_per_joint": {name: level.tolist() for name, level in self.reference_std.items()},
            "window_s": self.window_s,
            "segments": {
                name: [
                    {
                        "t_start_s": s.t_start_s,
                        "t_end_s": s.t_end_s,
                        "rms_over_typical": s.rms_over_noise,
                        "joint_rms_over_typical": s.channel_rms_over_noise.tolist(),
                        "p_value_holm": s.p_value,
                        "moving_joints": s.moving_joints,
                    }
                    for s in segments
                ]
                for name, segments in self.segments.items()
            },
        }


def where_it_fails(
    model: ArmIdentificationModel,
    rows: Mapping[str, IdentificationRows],
    estimator: str = "wls",
    window_s: float = 2.0,
    confidence: float = 0.999,
) -> FailingPeriods:
    """Held-out residual of every movement (``model`` fitted by ``estimator`` on the others), tested window by window
    against the movement's typical error level (:class:`FailingPeriods`): a window is flagged when its mean square
    exceeds that level at ``confidence`` (Holm-corrected F test with the level's degrees of freedom taken as one per
    window and joint). Model error that is the same all along a movement is not flagged; an outburst (a push on the
    arm, a collision, a payload picked up) is. ``rows``: the movements' identification rows for ``model``."""
    if len(rows) < 2:
        raise SpaceIdInputError(f"where it fails: needs at least two movements (held-out residuals), got {list(rows)}")
    residuals = {}
    for held, item in rows.items():
        estimate = fit(model, {n: r for n, r in rows.items() if n != held}, make_estimator(estimator))
        residuals[held] = item.log.effort - model.predict(estimate.theta, item)
    logs = {name: item.log for name, item in rows.items()}
    reference = {name: _typical_level(logs[name].t_s, residual, window_s) for name, residual in residuals.items()}
    segments = {
        name: failing_segments(
            logs[name].t_s,
            residual,
            reference[name],
            logs[name].q_rad,
            logs[name].dq_rad_s,
            window_s=window_s,
            confidence=confidence,
            noise_dof=float(residual.shape[1] * (np.ptp(logs[name].t_s) // window_s + 1)),
        )
        for name, residual in residuals.items()
    }
    return FailingPeriods(segments, reference, window_s)


def _typical_level(t_s: FloatArray, residual: FloatArray, window_s: float) -> FloatArray:
    """Per joint (n,): the square root of the median over ``window_s`` windows of the window's mean square residual,
    the movement's typical error level (a few outbursts do not move a median)."""
    window = np.floor((t_s - t_s[0]) / window_s).astype(int)
    counts = np.bincount(window)
    mean_square = np.stack([np.bincount(window, residual[:, j] ** 2) for j in range(residual.shape[1])], axis=1)
    return np.sqrt(np.median(mean_square[counts > 0] / counts[counts > 0, None], axis=0))
