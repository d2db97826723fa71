"""The identification model and the objective it defines on one log.

:class:`IdentificationModel` says *what* is identified (robot, parameterisation, search range,
noise); :meth:`IdentificationModel.problem` binds it to a log and gives the
:class:`IdentificationProblem` every estimator works on:

* ``cost(theta)`` (P, k) -> (P,): the paper's eq. 15, the mean squared difference between the
  measured and predicted base rate (rad/s, base body frame) over the log's samples and 3 axes,
  for a batch of P parameter vectors at once; ``samples=`` restricts it to part of the log;
* ``residuals``/``jacobian``: the same for least squares, with the analytic Jacobian;
* ``fisher``/``crlb_std``: Fisher information and Cramér-Rao bound of the log at ``theta``;
* a counter of model evaluations (particle-samples), so estimators are compared at equal budget.

Identifiability: a parameter whose Cramér-Rao standard deviation exceeds a quarter of its search
range (or that lies in a direction the log does not inform at all) is *not identifiable from this
log*: the data narrow it less than the prior range does, and the estimate reports a message instead
of a number.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.estimate import Estimate
from estimators.models.effect_jacobian import effect_jacobians
from estimators.models.effect_models import EffectContext, EffectPrediction, make_terms, parse_effects
from estimators.models.momentum_model import MomentumModel, Samples
from estimators.parameters import FuelParameters, Parameterisation, WithEffects, make_parameterisation
from spaceid_gym.arrays import FloatArray
from spaceid_gym.effects.draws import remaining_liquid_kg
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import cramer_rao_std
from spaceid_gym.log import MeasurementLog
from spaceid_gym.robots import Robot, load_robot

#: a parameter is identifiable if its Cramér-Rao std is below this fraction of its search range
IDENTIFIABLE_FRACTION = 0.25

#: the central differences' step, as a fraction of each unknown's search width (:meth:`IdentificationProblem.difference_jacobian`;
#: the per-fit quantities of the slosh's Jacobian, :func:`~estimators.models.effect_jacobian.effect_jacobians`)
DIFFERENCE_STEP = 1e-6

#: how many Jacobians a problem keeps, to answer a request at the same parameters again (:meth:`IdentificationProblem.jacobian`)
REMEMBERED_JACOBIANS = 4


class IdentificationModel:
    """What is identified: robot, parameterisation and noise model (independent of any log).

    Args:
        robot: a :class:`~spaceid_gym.robots.Robot`, a shipped name or a URDF path (full-tank base).
        params: ``"fuel"`` (default), ``"base"``, ``"payload"`` or a :class:`Parameterisation`.
        noise_std_rad_s: gyro noise std per sample and axis (rad/s) for the Cramér-Rao bound;
            ``None`` estimates it from the final residual (``sqrt(RSS / (3T - k))``).
        effects: effect terms added to the model, e.g. ``"initial_momentum,gyro_bias"`` or a list of names
            (see :mod:`estimators.models.effect_models`); their unknowns follow the parameterisation's.
        **param_options: options of the parameterisation (``lower``, ``upper``, ...: for the whole vector,
            effects included).
    """

    def __init__(
        self,
        robot: Robot | str,
        params: str | Parameterisation = "fuel",
        noise_std_rad_s: float | None = None,
        effects: str | list[str] | tuple[str, ...] | None = None,
        **param_options: Any,
    ) -> None:
        self.robot = robot if isinstance(robot, Robot) else load_robot(robot)
        if noise_std_rad_s is not None and not (np.isfinite(noise_std_rad_s) and noise_std_rad_s > 0.0):
            raise SpaceIdInputError(f"noise_std_rad_s: expected a positive number (rad/s) or None, got {noise_std_rad_s!r}")
        self.noise_std_rad_s = noise_std_rad_s
        self.parameters = _parameterisation(self.robot, params, effects, param_options)
        #: the effect specs in the model, e.g. ``("gyro_bias", "external_torque[drift=true]")``
        self.effects: tuple[str, ...] = (
            tuple(t.spec for t in self.parameters.terms) if isinstance(self.parameters, WithEffects) else ()
        )

    def problem(self, log: MeasurementLog) -> IdentificationProblem:
        """The objective of this model on ``log`` (sets up the per-log arm terms once)."""
        if log.n_joints != self.robot.n_joints:
            raise SpaceIdInputError(f"log: has {log.n_joints} joints, the robot {self.robot.name!r} has {self.robot.n_joints}")
        return IdentificationProblem(self, log)


def _parameterisation(
    robot: Robot, params: str | Parameterisation, effects: str | list[str] | tuple[str, ...] | None, options: dict[str, Any]
) -> Parameterisation:
    """The model's unknowns: the parameterisation, extended by the effect terms if any.

    With effects, ``lower``/``upper`` span the whole vector; the parameterisation's part goes to its constructor.
    """
    if not parse_effects(effects):
        return params if isinstance(params, Parameterisation) else make_parameterisation(params, robot, **options)
    bounds = {k: np.asarray(options.pop(k), dtype=float) for k in ("lower", "upper") if k in options}
    base = params if isinstance(params, Parameterisation) else make_parameterisation(params, robot, **options)
    terms = make_terms(effects, robot, *_slosh_locators(base, robot))
    n_total = base.n_params + sum(t.n_params for t in terms)
    for key, value in bounds.items():
        if value.shape != (n_total,):
            raise SpaceIdInputError(
                f"{key}: expected {n_total} bounds (the parameterisation's and the effects'), got {value.size}"
            )
    if bounds and not isinstance(params, Parameterisation):
        base = make_parameterisation(params, robot, **options, **{k: v[: base.n_params] for k, v in bounds.items()})
        terms = make_terms(effects, robot, *_slosh_locators(base, robot))
    offset = base.n_params
    for term in terms:
        part = slice(offset, offset + term.n_params)
        term.lower = bounds["lower"][part] if "lower" in bounds else term.lower
        term.upper = bounds["upper"][part] if "upper" in bounds else term.upper
        offset += term.n_params
    return WithEffects(base, terms)


def identifiability(
    names: tuple[str, ...], std: FloatArray, width: FloatArray, data: str = "log"
) -> tuple[NDArray[np.bool_], list[str]]:
    """Which parameters are identifiable (Cramér-Rao std (k,) below :data:`IDENTIFIABLE_FRACTION` of the search
    width (k,)), and an "insufficient excitation" message for each that is not (``data`` names the data)."""
    identifiable = std < IDENTIFIABLE_FRACTION * width
    messages = [
        f"insufficient excitation: {name} is not identifiable from this {data} "
        f"(Cramér-Rao std {'unbounded' if not np.isfinite(s) else f'{s:.3g}'} > {IDENTIFIABLE_FRACTION:g} x its search range {w:.3g})"
        for name, s, w, ok in zip(names, std, width, identifiable, strict=True)
        if not ok
    ]
    return identifiable, messages


def _slosh_locators(
    base: Parameterisation, robot: Robot
) -> tuple[Callable[[FloatArray], FloatArray] | None, Callable[[FloatArray], FloatArray] | None]:
    """Where a slosh mass sits (P, 3) and how much liquid is left to slosh (P,) kg, for ``theta_base`` (P, k_base):
    with the fuel parameters, the tank (full-tank CoM + bf) and the usable fuel minus the fuel consumed
    (:func:`~spaceid_gym.effects.draws.remaining_liquid_kg`, as in the simulator); else ``(None, None)`` (the term's
    defaults: the full-tank CoM and the usable fuel)."""
    if not isinstance(base, FuelParameters):
        return None, None
    full_com = np.asarray(base.base_full.com_m, dtype=float)

    def tank(theta_base: FloatArray) -> FloatArray:
        return full_com + np.asarray(theta_base, dtype=float)[:, 1:4]

    def liquid(theta_base: FloatArray) -> FloatArray:
        return np.asarray(remaining_liquid_kg(robot, np.asarray(theta_base, dtype=float)[:, 0]))

    return tank, liquid


#: the effect context of each log (:func:`_effect_context`), dropped with the log
_CONTEXTS: weakref.WeakKeyDictionary[MeasurementLog, EffectContext] = weakref.WeakKeyDictionary()


def _effect_context(log: MeasurementLog) -> EffectContext:
    """:meth:`~estimators.models.effect_models.EffectContext.from_log`, computed once per log and
    shared by every problem on it (its arrays read-only, as the log's)."""
    context = _CONTEXTS.get(log)
    if context is None:
        context = _CONTEXTS[log] = EffectContext.from_log(log)
        context.t_s.flags.writeable = context.rot_rel.flags.writeable = False
    return context


class IdentificationProblem:
    """The objective of an :class:`IdentificationModel` on one log; see the module docstring.

    Attributes:
        parameters: the parameterisation (names, nominal, bounds).
        n_samples: T; ``measured`` (T, 3) the logged base rate, rad/s, base body frame.
        n_model_samples: model evaluations so far (particles x samples), the budget counter.
    """

    def __init__(self, model: IdentificationModel, log: MeasurementLog) -> None:
        self.model = model
        self.parameters = model.parameters
        self.log = log
        self.momentum = MomentumModel.of(model.robot, log)
        params = model.parameters
        self._effects = (
            EffectPrediction(self.momentum, params.terms, _effect_context(log)) if isinstance(params, WithEffects) else None
        )
        self.measured = np.ascontiguousarray(log.omega_base_body_rad_s, dtype=float)
        self.n_samples = log.n_samples
        self.n_model_samples = 0
        self._jacobians: dict[tuple[str, bytes], FloatArray] = {}  # the last few Jacobians (:meth:`_remembered`)

    @property
    def n_params(self) -> int:
        """k."""
        return self.parameters.n_params

    @property
    def n_evaluations(self) -> float:
        """Objective evaluations so far, in whole-log equivalents."""
        return self.n_model_samples / self.n_samples

    # ------------------------------------------------------------------ objective
    def predict(self, theta: FloatArray, samples: Samples = slice(None), count: bool = True) -> FloatArray:
        """Predicted base rate (P, T', 3) for ``theta`` (P, k); counted in the budget unless ``count=False``."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if self._effects is None:
            omega = self.momentum.predict(*self.parameters.composite(theta), samples)
        else:
            omega = self._effect_rates(theta, samples)[1]
        if count:
            self.n_model_samples += omega.shape[0] * omega.shape[1]
        return omega

    def base_rate(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """The base's own rate (P, T, 3), rad/s, base body frame, for ``theta`` (P, k): :meth:`predict` without the
        measurement effects (``gyro_bias``, ``gyro_scale``, ``delay``), i.e. what rotates the base."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        if self._effects is None:
            return self.predict(theta, count=count)
        omega = self._effect_rates(theta, slice(None))[0]
        if count:
            self.n_model_samples += omega.shape[0] * omega.shape[1]
        return omega

    def base_rate_jacobian(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """``d base_rate / d theta`` (3T, k) at ``theta`` (k,): :meth:`jacobian` of :meth:`base_rate`."""
        if self._effects is None:
            return self.jacobian(theta, count)
        return self._remembered("base_rate", np.asarray(theta, dtype=float), count, self._base_rate_jacobian)

    def _effect_jacobians(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """With effects: ``d base_rate / d theta`` and ``d predict / d theta`` (3T, k), analytic
        (:func:`~estimators.models.effect_jacobian.effect_jacobians`), not counted."""
        params = self.parameters
        assert isinstance(params, WithEffects) and self._effects is not None
        return effect_jacobians(self._effects, params, theta, DIFFERENCE_STEP * params.width)

    def gyro_error(self, theta: FloatArray) -> FloatArray:
        """What the measurement effects add to the base rate, ``omega_gyro - omega_base`` (T, 3), rad/s, at ``theta`` (k,).

        Zero without measurement effects (``gyro_bias``, ``gyro_scale``, ``delay``); not counted in the budget.
        """
        if self._effects is None:
            return np.zeros((self.n_samples, 3))
        true, measured = self._effect_rates(np.atleast_2d(np.asarray(theta, dtype=float)), slice(None))
        return measured[0] - true[0]

    def _effect_rates(self, theta: FloatArray, samples: Samples) -> tuple[FloatArray, FloatArray]:
        """With effects: the base's own rate and the gyro's reading (P, T', 3) for ``theta`` (P, k)."""
        params = self.parameters
        assert isinstance(params, WithEffects) and self._effects is not None
        base10, payload10 = params.composite(theta)
        return self._effects.predict(base10, payload10, params.term_parts(theta), params.base_part(theta), samples)

    def cost(self, theta: FloatArray, samples: Samples = slice(None), count: bool = True) -> FloatArray:
        """Mean squared residual (rad/s)^2 over ``samples`` and the 3 axes, for ``theta`` (P, k): (P,)."""
        error = self.predict(theta, samples, count) - self.measured[samples]
        return np.mean(error * error, axis=(1, 2))

    def cost_on_subsets(self, theta: FloatArray, assignment: NDArray[np.intp], subsets: list[NDArray[np.intp]]) -> FloatArray:
        """Cost of particle ``i`` on the samples ``subsets[assignment[i]]``: (P,) for ``theta`` (P, k)."""
        theta = np.atleast_2d(theta)
        out = np.empty(len(theta))
        for s in np.unique(assignment):
            chosen = assignment == s
            out[chosen] = self.cost(theta[chosen], subsets[s])
        return out

    def subsets(self, n_subsets: int, kind: str = "interleaved") -> list[NDArray[np.intp]]:
        """Split the log's samples into ``n_subsets`` parts: every n-th sample (``interleaved``) or blocks (``contiguous``)."""
        if n_subsets < 1 or n_subsets > self.n_samples:
            raise SpaceIdInputError(f"n_subsets: expected 1..{self.n_samples} (the log's samples), got {n_subsets}")
        index = np.arange(self.n_samples)
        if kind == "interleaved":
            return [index[s::n_subsets] for s in range(n_subsets)]
        if kind == "contiguous":
            return list(np.array_split(index, n_subsets))
        raise SpaceIdInputError(f"subset kind: expected 'interleaved' or 'contiguous', got {kind!r}")

    def residuals(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """``predicted - measured`` (3T,), rad/s, at one ``theta`` (k,)."""
        return (self.predict(theta, count=count)[0] - self.measured).ravel()

    def jacobian(self, theta: FloatArray, count: bool = True) -> FloatArray:
        """``d predicted / d theta`` (3T, k) at ``theta`` (k,), analytic (counted as k evaluations; with effects as 2k,
        what the central differences it replaced cost, so that budgets compare with earlier runs)."""
        return self._remembered("predict", np.asarray(theta, dtype=float), count, self._predict_jacobian)

    def _predict_jacobian(self, theta: FloatArray) -> FloatArray:
        """:meth:`jacobian`, not counted."""
        if self._effects is not None:
            return self._effect_jacobians(theta)[1]
        base10, payload10 = self.parameters.composite(theta)
        d_base, d_payload = self.parameters.composite_jacobian(theta)
        j_base, j_payload = self.momentum.jacobian(base10[0], None if payload10 is None else payload10[0])
        jac = j_base @ d_base
        if j_payload is not None and d_payload is not None:
            jac = jac + j_payload @ d_payload
        return jac.reshape(-1, self.n_params)

    def _base_rate_jacobian(self, theta: FloatArray) -> FloatArray:
        """:meth:`base_rate_jacobian` with effects, not counted."""
        return self._effect_jacobians(theta)[0]

    def _remembered(self, kind: str, theta: FloatArray, count: bool, compute: Callable[[FloatArray], FloatArray]) -> FloatArray:
        """``compute(theta)`` (3T, k), or a copy of it when one of the last :data:`REMEMBERED_JACOBIANS` Jacobians of
        this ``kind`` was at the same ``theta`` (k,): a least-squares fit asks for the Jacobian where the fit before it
        ended, and its caller asks again where it ends. Counted as computed either way (k or 2k evaluations, see
        :meth:`jacobian`), so that the budget does not depend on what was remembered."""
        key = (kind, theta.tobytes())
        jac = self._jacobians.pop(key, None)
        if jac is None:
            jac = compute(theta)
        self._jacobians[key] = jac  # the most recent last
        if len(self._jacobians) > REMEMBERED_JACOBIANS:
            del self._jacobians[next(iter(self._jacobians))]
        if count:
            self.n_model_samples += self.n_params * self.n_samples * (1 if self._effects is None else 2)
        return jac.copy()

    def difference_jacobian(self, theta: FloatArray, predict: Callable[..., FloatArray]) -> FloatArray:
        """Central differences (3T, k) of ``predict`` (:meth:`predict` or :meth:`base_rate`) at ``theta`` (k,) with steps
        of :data:`DIFFERENCE_STEP` of each search width, all 2k points through one batched prediction, not counted:
        the reference the analytic Jacobians are tested against."""
        step = DIFFERENCE_STEP * self.parameters.width
        points = np.repeat(theta[None], 2 * self.n_params, axis=0)
        index = np.arange(self.n_params)
        points[2 * index, index] += step
        points[2 * index + 1, index] -= step
        omega = predict(points, count=False)  # (2k, T, 3)
        jac = (omega[0::2] - omega[1::2]) / (2.0 * step[:, None, None])
        return jac.reshape(self.n_params, -1).T

    # ------------------------------------------------------------------ information
    def noise_std(self, theta: FloatArray) -> tuple[float, str]:
        """The gyro noise std (rad/s) for the bound, and whether it was ``given`` or estimated from the ``residual``."""
        if self.model.noise_std_rad_s is not None:
            return float(self.model.noise_std_rad_s), "given"
        residual = self.residuals(theta, count=False)
        dof = max(residual.size - self.n_params, 1)
        return float(np.sqrt(residual @ residual / dof)), "residual"

    def fisher(self, theta: FloatArray, noise_std_rad_s: float | None = None) -> FloatArray:
        """Fisher information (k, k) of the log about ``theta`` for white gyro noise (per-sample std)."""
        sigma = self.noise_std(theta)[0] if noise_std_rad_s is None else noise_std_rad_s
        jac = self.jacobian(theta, count=False)
        return (jac.T @ jac) / (sigma * sigma)

    def _range_scaled_fisher(
        self, theta: FloatArray, noise_std_rad_s: float | None, extra_information: FloatArray | None = None
    ) -> FloatArray:
        """Fisher information (plus ``extra_information`` (k, k), another measurement's, if given) in units of the
        search ranges (k, k): rank decisions compare like with like (kg vs m)."""
        width = self.parameters.width
        fisher = self.fisher(theta, noise_std_rad_s)
        if extra_information is not None:
            fisher = fisher + extra_information
        return fisher * np.outer(width, width)

    def crlb_std(
        self, theta: FloatArray, noise_std_rad_s: float | None = None, extra_information: FloatArray | None = None
    ) -> FloatArray:
        """Cramér-Rao standard deviations (k,) at ``theta``; ``inf`` in directions the log does not inform.

        ``extra_information`` (k, k): the Fisher information of a further measurement of the same log fitted
        together with the gyro (the star tracker's, :meth:`~estimators.attitude_channel.AttitudeChannel.fisher`).
        """
        return cramer_rao_std(self._range_scaled_fisher(theta, noise_std_rad_s, extra_information)) * self.parameters.width

    def crlb_physical_std(self, theta: FloatArray, noise_std_rad_s: float | None = None) -> dict[str, Any]:
        """Cramér-Rao std of the physical quantities (``base_mass_kg``, ...) at ``theta`` (delta method)."""
        scaled = self._range_scaled_fisher(theta, noise_std_rad_s)
        identifiable = np.ones(self.n_params, dtype=bool)
        return _derived_with_std(self.parameters, np.asarray(theta, dtype=float), scaled, self.parameters.width, identifiable)[1]

    # ------------------------------------------------------------------ result
    def make_estimate(
        self,
        theta: FloatArray,
        *,
        estimator: str,
        options: dict[str, Any],
        seed: int | None,
        cost_history: FloatArray | list[float],
        wall_time_s: float,
        extra: dict[str, Any] | None = None,
        extra_information: FloatArray | None = None,
    ) -> Estimate:
        """Wrap ``theta`` as an :class:`Estimate`: bound, identifiability, derived physical quantities.

        ``extra_information`` (k, k): as in :meth:`crlb_std`, for an estimate fitted to more than the gyro.
        """
        theta = np.asarray(theta, dtype=float).copy()
        params = self.parameters
        sigma, source = self.noise_std(theta)
        width = params.width
        scaled = self._range_scaled_fisher(theta, sigma, extra_information)
        std = cramer_rao_std(scaled) * width
        identifiable, messages = identifiability(params.names, std, width, "log")
        physical, physical_std = _derived_with_std(params, theta, scaled, width, identifiable)
        return Estimate.of_problem(
            self,
            theta,
            estimator=estimator,
            options=options,
            seed=seed,
            cost_history=cost_history,
            wall_time_s=wall_time_s,
            extra=extra,
            theta_std=std,
            identifiable=identifiable,
            insufficient_excitation=messages,
            physical=physical,
            physical_std=physical_std,
            noise_std_rad_s=sigma,
            noise_source=source,
        )


def _derived_with_std(
    params: Parameterisation, theta: FloatArray, scaled_fisher: FloatArray, width: FloatArray, identifiable: NDArray[np.bool_]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Physical quantities and their std by the delta method (central differences in range units).

    A quantity that depends on a non-identifiable parameter is reported as ``None`` (value and std). A quantity that
    a step of the differences leaves undefined (a payload's centre of mass where its mass crosses zero) keeps its
    value, with the std ``None``.
    """
    values = params.physical(theta)
    keys = list(values)
    sizes = [np.atleast_1d(np.asarray(values[k], dtype=float)).size for k in keys]
    undefined: set[str] = set()

    def flatten(quantities: dict[str, Any]) -> FloatArray:
        missing = {k for k in keys if k not in quantities}
        undefined.update(missing)
        parts = [
            np.full(n, np.nan) if k in missing else np.atleast_1d(np.asarray(quantities[k], dtype=float)).ravel()
            for k, n in zip(keys, sizes, strict=True)
        ]
        return np.concatenate(parts)

    flat_all = flatten(values)
    flat = np.split(flat_all, np.cumsum(sizes)[:-1])
    step = 1e-6
    columns = []
    for j in range(len(theta)):
        delta = np.zeros_like(theta)
        delta[j] = step * width[j]
        plus = flatten(params.physical(theta + delta))
        minus = flatten(params.physical(theta - delta))
        columns.append((plus - minus) / (2.0 * step))  # per unit of the scaled parameter
    d_scaled = np.column_stack(columns)  # (n_derived, k)
    # the rows of a quantity undefined at some step carry no derivative (their std is None below); a NaN anywhere else
    # is an error of the parameterisation's physical quantities and stays one
    offsets = np.cumsum([0, *sizes])
    for index, key in enumerate(keys):
        if key in undefined:
            d_scaled[offsets[index] : offsets[index + 1]] = 0.0
    # marginal covariance of the identifiable parameters (pseudo-inverse: uninformed directions dropped)
    cov = np.linalg.pinv(scaled_fisher, rcond=1e-9, hermitian=True)[np.ix_(identifiable, identifiable)]
    d_informed = d_scaled[:, identifiable]
    std_flat = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", d_informed, cov, d_informed), 0.0))
    scale = np.abs(d_scaled).max(axis=1, keepdims=True) + 1e-300
    depends_on_unidentified = (np.abs(d_scaled[:, ~identifiable]) > 1e-9 * scale).any(axis=1)
    physical: dict[str, Any] = {}
    physical_std: dict[str, Any] = {}
    offset = 0
    for key, size, value in zip(keys, sizes, flat, strict=True):
        part = slice(offset, offset + size)
        offset += size
        shape = np.shape(values[key])
        if depends_on_unidentified[part].any():
            physical[key], physical_std[key] = None, None
            continue
        physical[key] = float(value[0]) if shape == () else value.reshape(shape)
        if key in undefined:
            physical_std[key] = None
            continue
        physical_std[key] = float(std_flat[part][0]) if shape == () else std_flat[part].reshape(shape)
    return physical, physical_std
