"""Excitation trajectories for fixed-base arms: finite Fourier series, optimised for the base regressor.

Trajectory (Swevers et al.'s periodic excitation), per joint j, with ``w = 2 pi f0``::

    q_j(t)   = q0_j + sum_l [ a_jl sin(l w t) - b_jl cos(l w t) ] / (l w)
    dq_j(t)  =        sum_l [ a_jl cos(l w t) + b_jl sin(l w t) ]
    ddq_j(t) =        sum_l [-a_jl sin(l w t) + b_jl cos(l w t) ] l w

``l = 1..H``; ``a, b`` in rad/s; ``q0`` is the mean angle over a period (not ``q(0)``). The
trajectory is periodic (period ``1 / f0``), band-limited to ``H f0`` and linear in ``(a, b, q0)``,
so joint limits sampled on a time grid are linear constraints.

Optimisation (:func:`optimise_excitation`)
------------------------------------------
Minimise a criterion of the stacked base regressor ``W_b`` (rows: every joint at each of
``n_grid`` times over one period, columns: the r base parameters):

* ``"condition"``: ``log cond(W_b)`` (cond = ratio of the extreme singular values, raw columns as
  in the classical excitation-design literature);
* ``"d-optimal"``: ``-(1/r) log det(W_b^T W_b)`` (independent of the parameters' units up to a
  constant).

subject to ``|q - mid| <= fraction * half range``, ``|dq| <= fraction * rate limit``, ``|ddq| <=
fraction * acceleration limit`` on a time grid (linear inequalities), by
``scipy.optimize.minimize(method="SLSQP")`` from ``n_starts`` seeded random feasible starts. The
gradient is analytic through the chain rule: derivatives of the criterion with respect to ``W_b``
(from the eigen-decomposition of ``W_b^T W_b``), per-sample derivatives of the regressor with
respect to ``(q, dq, ddq)`` (forward differences in q and dq, exact differences in ddq, in which
the regressor is linear) and the closed-form trajectory derivatives. The result is checked on a
dense grid and scaled down if a limit is exceeded between the constraint grid points.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize
from threadpoolctl import threadpool_limits

from spaceid_gym.arm.arm_robot import ArmRobot
from spaceid_gym.arm.regressor import ArmRegressor, BaseParameterSet
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

CRITERIA = ("condition", "d-optimal")
_FD_STEP = 1e-6  # forward-difference step in q (rad) and dq (rad/s)


class FourierTrajectory:
    """A periodic joint trajectory, finite Fourier series per joint (module docstring).

    Args:
        n_joints: n.
        n_harmonics: H.
        base_frequency_hz: ``f0``, Hz (period ``1 / f0``).
        coefficients: shape (n, 2, H): ``[:, 0, :]`` = ``a`` (cosine terms of dq), ``[:, 1, :]`` = ``b`` (sine terms), rad/s.
        q0: mean joint angles, shape (n,), rad.
    """

    def __init__(
        self, n_joints: int, n_harmonics: int, base_frequency_hz: float, coefficients: FloatArray, q0: FloatArray
    ) -> None:
        if n_joints < 1 or n_harmonics < 1:
            raise SpaceIdInputError(f"Fourier trajectory: n_joints and n_harmonics must be >= 1, got {n_joints}, {n_harmonics}")
        if not (np.isfinite(base_frequency_hz) and base_frequency_hz > 0):
            raise SpaceIdInputError(f"Fourier trajectory: base_frequency_hz must be > 0, got {base_frequency_hz!r}")
        c = np.array(coefficients, dtype=float)
        q0_array = np.array(q0, dtype=float).reshape(-1)
        if c.shape != (n_joints, 2, n_harmonics) or not np.isfinite(c).all():
            raise SpaceIdInputError(
                f"Fourier trajectory: coefficients must be finite with shape (n, 2, H) = ({n_joints}, 2, {n_harmonics}), got {c.shape}"
            )
        if q0_array.shape != (n_joints,) or not np.isfinite(q0_array).all():
            raise SpaceIdInputError(f"Fourier trajectory: q0 must be {n_joints} finite angles (rad), got {q0!r}")
        c.flags.writeable = False
        q0_array.flags.writeable = False
        self.n_joints, self.n_harmonics = int(n_joints), int(n_harmonics)
        self.base_frequency_hz = float(base_frequency_hz)
        self.coefficients, self.q0 = c, q0_array
        #: ``l w`` for l = 1..H, rad/s
        self.harmonic_rad_s = 2.0 * math.pi * self.base_frequency_hz * np.arange(1, n_harmonics + 1)

    @property
    def period_s(self) -> float:
        """``1 / f0``, s."""
        return 1.0 / self.base_frequency_hz

    def basis(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Basis of q - q0, dq and ddq at times (T,): each (T, 2H), so that ``q = B_q @ [a_j; b_j] + q0_j``."""
        theta = np.multiply.outer(np.asarray(t_s, dtype=float), self.harmonic_rad_s)
        s, c = np.sin(theta), np.cos(theta)
        lw = self.harmonic_rad_s
        return np.hstack((s / lw, -c / lw)), np.hstack((c, s)), np.hstack((-s * lw, c * lw))

    def state(self, t_s: FloatArray | float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q, dq, ddq)`` at times of shape (T,) -> each (T, n); a scalar time gives shape (n,)."""
        t = np.asarray(t_s, dtype=float)
        flat = self.coefficients.reshape(self.n_joints, -1).T  # (2H, n)
        b_q, b_dq, b_ddq = self.basis(t.reshape(-1))
        q, dq, ddq = b_q @ flat + self.q0, b_dq @ flat, b_ddq @ flat
        if t.ndim == 0:
            return q[0], dq[0], ddq[0]
        return q, dq, ddq

    __call__ = state

    def peak_ratios(self, robot: ArmRobot, n_points: int = 2000) -> dict[str, float]:
        """Largest ``|q - mid| / half range``, ``|dq| / limit``, ``|ddq| / limit`` over one period (``n_points`` times)."""
        q, dq, ddq = self.state(np.linspace(0.0, self.period_s, n_points, endpoint=False))
        mid, half = _mid_half(robot.q_lower_rad, robot.q_upper_rad)
        return {
            "q": float((np.abs(q - mid) / half).max()),
            "dq": float((np.abs(dq) / robot.dq_limit_rad_s).max()),
            "ddq": float((np.abs(ddq) / robot.ddq_limit_rad_s2).max()),
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (``from_dict`` inverts it)."""
        return {
            "kind": "fourier",
            "n_joints": self.n_joints,
            "n_harmonics": self.n_harmonics,
            "base_frequency_hz": self.base_frequency_hz,
            "coefficients_rad_s": self.coefficients.tolist(),
            "q0_rad": self.q0.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FourierTrajectory:
        """The trajectory described by :meth:`to_dict`'s output."""
        try:
            return cls(
                int(data["n_joints"]),
                int(data["n_harmonics"]),
                float(data["base_frequency_hz"]),
                np.asarray(data["coefficients_rad_s"], dtype=float),
                np.asarray(data["q0_rad"], dtype=float),
            )
        except KeyError as exc:
            raise SpaceIdInputError(f"Fourier trajectory: missing key {exc}") from None

    def scaled(self, factor: float) -> FourierTrajectory:
        """The same trajectory with its oscillation (``a``, ``b``) scaled by ``factor`` about ``q0``."""
        return FourierTrajectory(self.n_joints, self.n_harmonics, self.base_frequency_hz, self.coefficients * factor, self.q0)


def _mid_half(lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:
    return 0.5 * (lower + upper), 0.5 * (upper - lower)


@dataclass(frozen=True)
class _Limits:
    """Symmetric limits ``|x - centre| <= bound`` per joint for q, dq and ddq (already times the fraction)."""

    mid: FloatArray
    q_half: FloatArray
    dq: FloatArray
    ddq: FloatArray

    @classmethod
    def of(cls, robot: ArmRobot, fraction: float, q_bounds_rad: tuple[FloatArray, FloatArray] | None) -> _Limits:
        if not (np.isfinite(fraction) and 0 < fraction <= 1):
            raise SpaceIdInputError(f"excitation: limit_fraction must be in (0, 1], got {fraction!r}")
        lower, upper = (robot.q_lower_rad, robot.q_upper_rad) if q_bounds_rad is None else q_bounds_rad
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        n = robot.n_joints
        if lower.shape != (n,) or upper.shape != (n,) or not (lower < upper).all():
            raise SpaceIdInputError(f"excitation: q_bounds_rad must be (lower, upper) of {n} angles each with lower < upper")
        if (lower < robot.q_lower_rad).any() or (upper > robot.q_upper_rad).any():
            raise SpaceIdInputError("excitation: q_bounds_rad must lie within the robot's joint limits")
        mid, half = _mid_half(lower, upper)
        return cls(mid, fraction * half, fraction * robot.dq_limit_rad_s, fraction * robot.ddq_limit_rad_s2)


def random_fourier_trajectory(
    robot: ArmRobot,
    rng: np.random.Generator,
    n_harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    fill: float = 0.8,
    limit_fraction: float = 0.9,
    q_bounds_rad: tuple[FloatArray, FloatArray] | None = None,
) -> FourierTrajectory:
    """A random feasible Fourier trajectory: the typical hand-made excitation and the optimiser's start.

    ``q0`` uniform in the middle half of the (possibly restricted) joint range, coefficients
    ``a, b ~ U(-1, 1) / l`` (a falling spectrum), then the oscillation scaled to ``fill`` times the
    largest amplitude that keeps ``q``, ``dq``, ``ddq`` within ``limit_fraction`` of the limits on a
    dense grid. Draws: ``q0`` (n), then the coefficients (n, 2, H) from ``rng``.
    """
    if not 0 < fill <= 1:
        raise SpaceIdInputError(f"excitation: fill must be in (0, 1], got {fill!r}")
    limits = _Limits.of(robot, limit_fraction, q_bounds_rad)
    n = robot.n_joints
    q0 = limits.mid + rng.uniform(-0.5, 0.5, size=n) * limits.q_half
    coefficients = rng.uniform(-1.0, 1.0, size=(n, 2, n_harmonics)) / np.arange(1, n_harmonics + 1)
    trajectory = FourierTrajectory(n, n_harmonics, base_frequency_hz, coefficients, q0)
    return trajectory.scaled(fill * _largest_feasible_scale(trajectory, limits))


def _largest_feasible_scale(trajectory: FourierTrajectory, limits: _Limits, n_points: int = 2000) -> float:
    """Largest factor of the oscillation that keeps the trajectory within ``limits`` on a dense grid (q0 fixed)."""
    t = np.linspace(0.0, trajectory.period_s, n_points, endpoint=False)
    q, dq, ddq = trajectory.state(t)
    dev = q - trajectory.q0
    upper_room = limits.mid + limits.q_half - trajectory.q0  # room above and below q0 differ
    lower_room = trajectory.q0 - (limits.mid - limits.q_half)
    if (upper_room < 0).any() or (lower_room < 0).any():
        return 0.0
    room = np.where(dev > 0, upper_room, lower_room)
    ratios = [(np.abs(dev), room), (np.abs(dq), limits.dq), (np.abs(ddq), limits.ddq)]  # (excursion, allowed)
    return float(
        min(
            np.divide(allowed, excursion, out=np.full(excursion.shape, np.inf), where=excursion > 0).min()
            for excursion, allowed in ((e, np.broadcast_to(a, e.shape)) for e, a in ratios)
        )
    )


# ---------------------------------------------------------------------- criterion
class _Criterion:
    """The criterion of a trajectory vector ``x = [a, b flattened (n 2H), q0 (n)]`` and its gradient."""

    def __init__(
        self,
        regressor: ArmRegressor,
        base: BaseParameterSet,
        kind: str,
        n_harmonics: int,
        base_frequency_hz: float,
        t_s: FloatArray,
    ) -> None:
        self.regressor, self.base, self.kind = regressor, base, kind
        self.n, self.H, self.f0 = regressor.n_joints, n_harmonics, base_frequency_hz
        self.template = FourierTrajectory(
            self.n, n_harmonics, base_frequency_hz, np.zeros((self.n, 2, n_harmonics)), np.zeros(self.n)
        )
        self.b_q, self.b_dq, self.b_ddq = self.template.basis(t_s)  # each (T, 2H)
        self.evaluations = 0

    def trajectory(self, x: FloatArray) -> FourierTrajectory:
        n, H = self.n, self.H
        return FourierTrajectory(n, H, self.f0, x[: 2 * H * n].reshape(n, 2, H), x[2 * H * n :])

    def states(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        flat = x[: 2 * self.H * self.n].reshape(self.n, -1).T
        return self.b_q @ flat + x[2 * self.H * self.n :], self.b_dq @ flat, self.b_ddq @ flat

    def value(self, x: FloatArray) -> float:
        W = self._base_rows(*self.states(x))
        return self._from_eigen(np.linalg.eigh(W.T @ W)[0])

    def _base_rows(self, q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
        self.evaluations += 1
        return self.base.base_regressor(self.regressor.regressor(q, dq, ddq)).reshape(-1, self.base.rank)

    def _from_eigen(self, eigenvalues: FloatArray) -> float:
        lam = np.maximum(eigenvalues, np.finfo(float).tiny)
        if self.kind == "condition":
            return 0.5 * float(np.log(lam[-1]) - np.log(lam[0]))
        return -float(np.mean(np.log(lam)))

    def value_and_gradient(self, x: FloatArray) -> tuple[float, FloatArray]:
        q, dq, ddq = self.states(x)
        T, n, r = q.shape[0], self.n, self.base.rank
        W = self._base_rows(q, dq, ddq)
        lam, V = np.linalg.eigh(W.T @ W)
        value = self._from_eigen(lam)
        lam = np.maximum(lam, np.finfo(float).tiny)
        if self.kind == "condition":  # d(0.5 log(l_max / l_min)) = (W v)^T dW v / l at both ends
            dW = (W @ V[:, -1:]) @ V[:, -1:].T / lam[-1] - (W @ V[:, :1]) @ V[:, :1].T / lam[0]
        else:  # d(-(1/r) log det G) = -(2/r) tr(G^-1 W^T dW)
            dW = -(2.0 / r) * (W @ (V / lam) @ V.T)
        G_rows = dW.reshape(T, n, r)
        # per-sample derivatives of the base regressor in the 3n state directions
        states = np.concatenate((q, dq, ddq), axis=1)  # (T, 3n)
        steps = np.concatenate((np.full(2 * n, _FD_STEP), np.ones(n)))  # the regressor is linear in ddq: exact with step 1
        perturbed = states[:, None, :] + np.diag(steps)[None, :, :]  # (T, 3n, 3n)
        Yp = self._base_rows(*np.split(perturbed.reshape(-1, 3 * n), 3, axis=1)).reshape(T, 3 * n, n, r)
        Y0 = W.reshape(T, 1, n, r)
        d_state = np.einsum("tkjr,tjr->tk", Yp - Y0, G_rows) / steps  # dJ/d(q, dq, ddq), (T, 3n)
        d_q, d_dq, d_ddq = np.split(d_state, 3, axis=1)
        d_coefficients = (self.b_q.T @ d_q + self.b_dq.T @ d_dq + self.b_ddq.T @ d_ddq).T  # (n, 2H)
        return value, np.concatenate((d_coefficients.ravel(), d_q.sum(axis=0)))


def _limit_constraints(template: FourierTrajectory, t_s: FloatArray, limits: _Limits) -> tuple[FloatArray, FloatArray]:
    """``A x <= c``: the limits at times ``t_s`` for ``x = [a, b flattened (n 2H), q0 (n)]``; A (6 T n, len(x)), c (6 T n,)."""
    n, H = template.n_joints, template.n_harmonics
    blocks, bounds = [], []
    for basis, is_angle, bound in zip(
        template.basis(t_s), (True, False, False), (limits.q_half, limits.dq, limits.ddq), strict=True
    ):
        for j in range(n):
            block = np.zeros((basis.shape[0], 2 * H * n + n))
            block[:, 2 * H * j : 2 * H * (j + 1)] = basis
            offset = 0.0
            if is_angle:  # q_j(t) = basis x_j + q0_j, bounded about the middle of the range
                block[:, 2 * H * n + j] = 1.0
                offset = limits.mid[j]
            for sign in (1.0, -1.0):  # sign (x_j(t) - offset) <= bound
                blocks.append(sign * block)
                bounds.append(np.full(basis.shape[0], bound[j] + sign * offset))
    return np.vstack(blocks), np.concatenate(bounds)


@dataclass(frozen=True, eq=False)
class ExcitationResult:
    """What :func:`optimise_excitation` found.

    Attributes:
        trajectory: the optimised trajectory (feasible on a dense grid).
        start: the random start it came from.
        criterion: ``"condition"`` or ``"d-optimal"``.
        condition_start, condition_optimised: ``cond(W_b)`` of the start and of the result on a dense
            grid of one period (``n_check`` times), the figure to compare.
        log_det_start, log_det_optimised: ``(1/r) log det(W_b^T W_b / T)`` on the same grid (per row-sample, unit-free up to a constant).
        starts: per start: the dense-grid condition before and after, and the optimiser's message.
        peak_ratios: the result's largest ``|q - mid| / half``, ``|dq| / limit``, ``|ddq| / limit``.
        evaluations: regressor stacks evaluated (criterion and gradient samples).
        wall_time_s: time taken, s.
    """

    trajectory: FourierTrajectory
    start: FourierTrajectory
    criterion: str
    condition_start: float
    condition_optimised: float
    log_det_start: float
    log_det_optimised: float
    starts: list[dict[str, Any]] = field(default_factory=list)
    peak_ratios: dict[str, float] = field(default_factory=dict)
    evaluations: int = 0
    wall_time_s: float = 0.0

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures (no trajectory)."""
        return {
            "criterion": self.criterion,
            "condition_start": self.condition_start,
            "condition_optimised": self.condition_optimised,
            "log_det_start": self.log_det_start,
            "log_det_optimised": self.log_det_optimised,
            "starts": self.starts,
            "peak_ratios": self.peak_ratios,
            "evaluations": self.evaluations,
            "wall_time_s": self.wall_time_s,
        }


def regressor_condition(
    trajectory: FourierTrajectory,
    regressor: ArmRegressor,
    base: BaseParameterSet,
    n_points: int = 250,
    duration_s: float | None = None,
) -> tuple[float, float]:
    """``(cond(W_b), (1/r) log det(W_b^T W_b / T))`` of a trajectory at ``n_points`` times over ``duration_s`` (default one period)."""
    duration = trajectory.period_s if duration_s is None else duration_s
    t = np.linspace(0.0, duration, n_points, endpoint=False)
    W = base.base_regressor(regressor.regressor(*trajectory.state(t))).reshape(-1, base.rank)
    lam = np.maximum(np.linalg.eigvalsh(W.T @ W), np.finfo(float).tiny)
    return float(np.sqrt(lam[-1] / lam[0])), float(np.mean(np.log(lam / n_points)))


def optimise_excitation(
    regressor: ArmRegressor,
    base: BaseParameterSet | None = None,
    *,
    rng: np.random.Generator,
    n_harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    duration_s: float | None = None,
    criterion: str = "condition",
    n_starts: int = 2,
    n_grid: int = 40,
    n_constraint_grid: int = 80,
    n_check: int = 250,
    limit_fraction: float = 0.9,
    q_bounds_rad: tuple[FloatArray, FloatArray] | None = None,
    max_iterations: int = 60,
) -> ExcitationResult:
    """An excitation trajectory that minimises the criterion of the base regressor under the joint limits.

    Args:
        regressor: the linear model (robot and friction terms).
        base: its base parameters (default: :meth:`BaseParameterSet.from_regressor` with ``rng``).
        rng: the seeded generator of the random starts (and of ``base`` if not given).
        n_harmonics, base_frequency_hz: the Fourier series (H, f0 in Hz).
        duration_s: time span of the criterion's grid, s (default one period ``1 / f0``).
        criterion: ``"condition"`` or ``"d-optimal"`` (module docstring).
        n_starts: random feasible starts; the best result on the dense grid is returned.
        n_grid: times of the criterion's grid (each gives n rows; the gradient costs 3n + 1 regressor evaluations per time).
        n_constraint_grid: times of the limits' grid over one period.
        n_check: times of the dense grid (reported figures, final feasibility).
        limit_fraction: the fraction of each limit allowed (q about the middle of the range).
        q_bounds_rad: optional tighter joint-angle bounds ``(lower (n,), upper (n,))``, rad.
        max_iterations: SLSQP iterations per start.
    """
    if criterion not in CRITERIA:
        raise SpaceIdInputError(f"excitation: criterion must be one of {list(CRITERIA)}, got {criterion!r}")
    for name, value in (
        ("n_starts", n_starts),
        ("n_grid", n_grid),
        ("n_constraint_grid", n_constraint_grid),
        ("n_harmonics", n_harmonics),
    ):
        if not (isinstance(value, int | np.integer) and value >= 1):
            raise SpaceIdInputError(f"excitation: {name} must be an integer >= 1, got {value!r}")
    start_time = time.perf_counter()
    robot = regressor.robot
    base = BaseParameterSet.from_regressor(regressor, rng) if base is None else base
    if n_grid * robot.n_joints < base.rank:
        raise SpaceIdInputError(
            f"excitation: n_grid = {n_grid} gives {n_grid * robot.n_joints} rows for {base.rank} base parameters"
        )
    limits = _Limits.of(robot, limit_fraction, q_bounds_rad)
    period = 1.0 / base_frequency_hz
    span = period if duration_s is None else float(duration_s)
    if not (np.isfinite(span) and span > 0):
        raise SpaceIdInputError(f"excitation: duration_s must be > 0 s, got {duration_s!r}")
    grid = np.linspace(0.0, span, n_grid, endpoint=False)
    objective = _Criterion(regressor, base, criterion, n_harmonics, base_frequency_hz, grid)
    A, c = _limit_constraints(objective.template, np.linspace(0.0, period, n_constraint_grid, endpoint=False), limits)
    linear = {"type": "ineq", "fun": lambda x: c - A @ x, "jac": lambda x: -A}

    best: tuple[float, FourierTrajectory, FourierTrajectory] | None = None
    starts: list[dict[str, Any]] = []
    with threadpool_limits(limits=1):  # small matrices: threads only add overhead on a shared machine
        for _ in range(n_starts):
            start = random_fourier_trajectory(
                robot, rng, n_harmonics, base_frequency_hz, limit_fraction=limit_fraction, q_bounds_rad=q_bounds_rad
            )
            x0 = np.concatenate((start.coefficients.ravel(), start.q0))
            result = scipy.optimize.minimize(
                objective.value_and_gradient,
                x0,
                jac=True,
                method="SLSQP",
                constraints=[linear],
                options={"maxiter": max_iterations, "ftol": 1e-7},
            )
            candidate = objective.trajectory(result.x if np.isfinite(result.fun) else x0)
            scale = _largest_feasible_scale(candidate, limits)  # limits between the grid points; 0 if q0 left the range
            candidate = candidate.scaled(min(1.0, scale)) if scale > 0 else start
            cond_before = regressor_condition(start, regressor, base, n_check, duration_s)[0]
            cond_after, log_det_after = regressor_condition(candidate, regressor, base, n_check, duration_s)
            score = math.log(cond_after) if criterion == "condition" else -log_det_after
            starts.append({"condition_start": cond_before, "condition_optimised": cond_after, "message": str(result.message)})
            if best is None or score < best[0]:
                best = (score, candidate, start)
    assert best is not None
    _, trajectory, start = best
    cond_start, log_det_start = regressor_condition(start, regressor, base, n_check, duration_s)
    cond_opt, log_det_opt = regressor_condition(trajectory, regressor, base, n_check, duration_s)
    return ExcitationResult(
        trajectory=trajectory,
        start=start,
        criterion=criterion,
        condition_start=cond_start,
        condition_optimised=cond_opt,
        log_det_start=log_det_start,
        log_det_optimised=log_det_opt,
        starts=starts,
        peak_ratios=trajectory.peak_ratios(robot),
        evaluations=objective.evaluations,
        wall_time_s=time.perf_counter() - start_time,
    )
