"""Excitation design for the free-floating robot: the paper's one-joint-at-a-time motion and an optimised Fourier series.

Both drive ``FreeFloatingID-v0`` as normalised joint-rate commands (time, s -> action in [-1, 1]), like
:class:`spaceid_gym.excitation.FourierExcitation` (the random multi-sine).

**One joint at a time** (:class:`OneJointExcitation`): the source paper's eq. 13 reads column i of the generalized
inertia map off the base rate while only joint i moves. The window is split into n equal slots; in slot i joint i
runs ``u(t) = amplitude sin(2 pi c t / slot)`` (``c`` whole cycles: it starts and ends the slot at rest, back where it
started), every other joint rests.

**Optimised Fourier series** (:func:`optimise_fourier_excitation`, Swevers et al. 1997): per joint the normalised
rate is a finite Fourier series over the window, ``u_j(t) = sum_l a_jl cos(l w t) + b_jl sin(l w t)``, ``l = 1..H``,
``w = 2 pi / duration`` (base frequency ``1 / duration``: one period per window; default ``H = 10`` harmonics, up
to ``10 / duration``: 0.167 Hz for 60 s). It maximises the D-optimality ``log det F_s`` of the gyro data about the
fuel parameters (:class:`FuelInformation`, in prior-range units) subject to, on a time grid,

* rest at both ends: ``u_j(0) = 0`` and ``du_j/dt(0) = 0`` (linear equalities; periodicity gives the same at the end);
* rate: ``|u_j| <= limit_fraction`` (of the rate limit);
* acceleration: ``rate_limit_j |du_j/dt| <= limit_fraction * a_max_j`` (the servo's acceleration limit);
* position: ``|q_j(t) - q_j(0)| <= limit_fraction * half range_j - 0.3 rad`` (the env starts within 0.3 rad of the
  middle of each range).

Torque limits are not constraints here: any motion within the servo's rate and acceleration limits keeps the joint
torques of the shipped robots inside their URDF efforts (``tests/test_simulator.py`` checks the worst case, a new
full-scale bang-bang rate command every step).

The criterion is evaluated at the design point ``theta_0`` (half the usable fuel consumed, tank at the full-tank CoM
unless given) with joint rates equal to the commands (the servo's 0.1 s lag neglected), on a grid of ``n_grid`` times
weighted to the env's sample rate. Its gradient is analytic in the rates (the base rate is linear in them) and uses
forward differences of the composite inertia in the joint angles; ``scipy.optimize.minimize(method="SLSQP")`` runs
from ``n_starts`` seeded random starts (random multi-sines scaled into the limits) and the best result, checked on a
dense grid and scaled into the limits if needed, is kept.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import scipy.optimize
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from spaceid_gym.arm.excitation_design import FourierTrajectory
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import ExcitationMeasures, excitation_measures
from spaceid_gym.mission import FuelSchedule
from spaceid_gym.physics.fuel import base_after_fuel, base_params10_fuel_jacobian
from spaceid_gym.physics.momentum import base_parameter_directions
from spaceid_gym.robots import Robot
from spaceid_gym.sim.sensors import SensorModel
from spaceid_gym.sim.servo import default_servo

#: the env's initial joint angles lie within this of the middle of each range, rad
START_SPREAD_RAD = 0.3
_FD_STEP_RAD = 1e-6


class OneJointExcitation:
    """The source paper's identification motion (eq. 13): one joint moves at a time (module docstring).

    Args:
        n_joints: n.
        duration_s: the window, split into n equal slots, s (> 0).
        amplitude: peak normalised rate, in (0, 1] (default 0.9).
        cycles: whole sine cycles per slot (>= 1, default 1).
    """

    def __init__(self, n_joints: int, duration_s: float, amplitude: float = 0.9, cycles: int = 1) -> None:
        if n_joints < 1 or cycles < 1:
            raise SpaceIdInputError(f"excitation: n_joints and cycles must be >= 1, got {n_joints}, {cycles}")
        if not (math.isfinite(duration_s) and duration_s > 0.0) or not 0.0 < amplitude <= 1.0:
            raise SpaceIdInputError(f"excitation: expected duration_s > 0 and 0 < amplitude <= 1, got {duration_s}, {amplitude}")
        self.n_joints, self.amplitude, self.cycles = n_joints, float(amplitude), int(cycles)
        self.slot_s = float(duration_s) / n_joints

    def __call__(self, t_s: float) -> NDArray[np.float32]:
        """Normalised joint-rate command at ``t_s``, shape (n,): only the slot's joint moves; zero outside the window."""
        action = np.zeros(self.n_joints, dtype=np.float32)
        slot = math.floor(t_s / self.slot_s) if t_s >= 0.0 else -1
        if 0 <= slot < self.n_joints:
            action[slot] = self.amplitude * math.sin(2.0 * math.pi * self.cycles * (t_s - slot * self.slot_s) / self.slot_s)
        return action


class FourierRateExcitation:
    """Normalised joint-rate commands from a finite Fourier series over one window (module docstring).

    Args:
        coefficients: shape (n, 2, H): ``[:, 0]`` the cosine terms ``a``, ``[:, 1]`` the sine terms ``b`` of the
            normalised rate.
        duration_s: the window = the series' period, s (> 0); the command is zero outside ``[0, duration_s]``.
    """

    def __init__(self, coefficients: FloatArray, duration_s: float) -> None:
        c = np.array(coefficients, dtype=float)
        if c.ndim != 3 or c.shape[1] != 2 or c.shape[0] < 1 or c.shape[2] < 1 or not np.isfinite(c).all():
            raise SpaceIdInputError(f"Fourier excitation: coefficients must be finite with shape (n, 2, H), got {c.shape}")
        if not (math.isfinite(duration_s) and duration_s > 0.0):
            raise SpaceIdInputError(f"Fourier excitation: duration_s must be > 0 s, got {duration_s!r}")
        self.coefficients, self.duration_s = c, float(duration_s)
        n, _, harmonics = c.shape
        #: the basis of the series (the arm's Fourier trajectory, whose rates are these normalised rates)
        self.template = FourierTrajectory(n, harmonics, 1.0 / self.duration_s, c, np.zeros(n))

    @property
    def n_joints(self) -> int:
        return int(self.coefficients.shape[0])

    @property
    def n_harmonics(self) -> int:
        return int(self.coefficients.shape[2])

    def rates(self, t_s: FloatArray) -> FloatArray:
        """Normalised rates at times (T,), shape (T, n) (not clipped, not zeroed outside the window)."""
        return self.template.state(np.asarray(t_s, dtype=float).reshape(-1))[1]

    def __call__(self, t_s: float) -> NDArray[np.float32]:
        """Normalised joint-rate command at ``t_s``, shape (n,), clipped to [-1, 1]; zero outside the window."""
        if not 0.0 <= t_s <= self.duration_s:
            return np.zeros(self.n_joints, dtype=np.float32)
        return np.clip(self.rates(np.array([t_s]))[0], -1.0, 1.0).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (:meth:`from_dict` inverts it)."""
        return {
            "kind": "fourier_rate",
            "duration_s": self.duration_s,
            "base_frequency_hz": 1.0 / self.duration_s,
            "n_harmonics": self.n_harmonics,
            "coefficients": self.coefficients.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "excitation") -> FourierRateExcitation:
        """The excitation :meth:`to_dict` described; ``source`` names the file in errors."""
        if not isinstance(data, dict) or data.get("kind") != "fourier_rate":
            raise SpaceIdInputError(f"{source}: expected a 'fourier_rate' excitation (written by 'spaceid excite fourier')")
        try:
            return cls(np.asarray(data["coefficients"], dtype=float), float(data["duration_s"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise SpaceIdInputError(f"{source}: missing or malformed field ({exc})") from None


class FuelInformation:
    """Fisher information of the gyro about the fuel parameters for a joint trajectory, in prior-range units.

    With zero system momentum the base twist is ``v = -M(q)^{-1} C(q) dq`` (``M`` the composite inertia, ``C`` the
    arm's coupling, pinocchio CRBA at ``theta_0``), so its sensitivity to the scaled fuel parameters is linear in the
    rates: ``d omega / d theta_s = sum_j dq_j G_j(q)`` with ``G_j = [M^{-1} D_k M^{-1} C_j]_{omega rows}`` and ``D_k``
    the derivative of the base's spatial inertia along parameter k. The same information as ``FreeFloatingID-v0``'s
    reward accumulates (the env evaluates it at the true parameters of the episode).

    Args:
        robot: the free-floating robot.
        theta0: design point ``(mdf kg, bf m (3))``; default half the usable fuel, tank at the full-tank CoM.
        schedule: the prior ranges (the env's default :class:`FuelSchedule`).
        control_period_s: the sample period whose gyro noise the information is for, s (default 0.02).
    """

    def __init__(
        self,
        robot: Robot,
        theta0: FloatArray | None = None,
        schedule: FuelSchedule | None = None,
        control_period_s: float = 0.02,
    ) -> None:
        schedule = schedule or FuelSchedule()
        full = robot.base_full
        usable = schedule.usable_fraction * full.mass_kg
        theta = np.array([0.5 * usable, 0.0, 0.0, 0.0]) if theta0 is None else np.asarray(theta0, dtype=float)
        self.robot, self.theta0 = robot, theta
        self.scale = np.array([usable] + [schedule.tank_half_width_m(full)] * 3)
        self.model = robot.model_with_base(base_after_fuel(full, float(theta[0]), theta[1:]))
        self.data = self.model.createData()
        self.directions = base_parameter_directions(base_params10_fuel_jacobian(full.com_m, theta) * self.scale)
        self.control_period_s = float(control_period_s)
        self.inverse_variance = 1.0 / SensorModel().gyro_std_rad_s(self.control_period_s) ** 2

    def rate_maps(self, q_rad: FloatArray) -> FloatArray:
        """``G_j(q)`` at joint angles (T, n): shape (T, n, 3, k), rad/s of base rate per rad/s of joint j per unit."""
        q_full = pin.neutral(self.model)
        n = self.robot.n_joints
        mass = np.empty((len(q_rad), 6, 6))
        coupling = np.empty((len(q_rad), 6, n))
        for i, q in enumerate(q_rad):
            q_full[7:] = q
            h = pin.crba(self.model, self.data, q_full)
            mass[i] = np.triu(h[:6, :6]) + np.triu(h[:6, :6], 1).T  # CRBA fills the upper triangle
            coupling[i] = h[:6, 6:]
        inverse = np.linalg.inv(mass)
        twist_per_rate = inverse @ coupling  # (T, 6, n)
        moved = np.einsum("kab,tbn->tkan", self.directions, twist_per_rate)
        return np.einsum("tab,tkbn->tnak", inverse[:, 3:, :], moved)

    def information(self, q_rad: FloatArray, dq_rad_s: FloatArray, samples_per_point: float = 1.0) -> FloatArray:
        """Scaled Fisher information (k, k) of samples at ``(q, dq)`` (T, n) each, each standing for
        ``samples_per_point`` samples of the control period."""
        jac = np.einsum("tj,tjak->tak", dq_rad_s, self.rate_maps(q_rad))
        return np.einsum("tak,tal->kl", jac, jac) * (self.inverse_variance * samples_per_point)

    def measures(self, q_rad: FloatArray, dq_rad_s: FloatArray, samples_per_point: float = 1.0) -> ExcitationMeasures:
        """:func:`~spaceid_gym.information.excitation_measures` of :meth:`information` (stds in kg and m)."""
        return excitation_measures(self.information(q_rad, dq_rad_s, samples_per_point), self.scale)


@dataclass(frozen=True, eq=False)
class FourierDesign:
    """What :func:`optimise_fourier_excitation` found.

    Attributes:
        excitation: the optimised excitation (within the limits on a dense grid).
        start: the random start it came from.
        measures_start, measures_optimised: the excitation measures of both at the design point on the dense grid.
        starts: per start, the D-optimality before and after and the optimiser's message.
        peak_ratios: the result's largest ``|u|`` (of the rate limit), ``|ddq| / a_max`` and ``|q - q(0)|`` / allowed.
        wall_time_s: time taken, s.
    """

    excitation: FourierRateExcitation
    start: FourierRateExcitation
    measures_start: ExcitationMeasures
    measures_optimised: ExcitationMeasures
    starts: list[dict[str, Any]] = field(default_factory=list)
    peak_ratios: dict[str, float] = field(default_factory=dict)
    wall_time_s: float = 0.0


class _Design:
    """The criterion ``-log det F_s`` of coefficients ``x`` (n 2H,), its gradient and the limits' linear constraints."""

    def __init__(
        self, information: FuelInformation, n_harmonics: int, duration_s: float, n_grid: int, limit_fraction: float
    ) -> None:
        robot = information.robot
        self.info, self.n, self.H = information, robot.n_joints, n_harmonics
        self.duration_s = duration_s
        self.template = FourierTrajectory(
            self.n, n_harmonics, 1.0 / duration_s, np.zeros((self.n, 2, n_harmonics)), np.zeros(self.n)
        )
        self.t = np.linspace(0.0, duration_s, n_grid, endpoint=False)
        self.weight = (duration_s / n_grid) / information.control_period_s  # env samples per grid point
        b_q, self.b_dq, self.b_ddq = self.template.basis(self.t)
        self.b_dq_q = b_q - self.template.basis(np.zeros(1))[0]  # q(t) - q(0) per unit rate
        self.rate = robot.rate_limit_rad_s
        self.accel = default_servo(robot.rate_limit_rad_s).accel_limit_rad_s2
        mid, half = 0.5 * (robot.q_lower_rad + robot.q_upper_rad), 0.5 * (robot.q_upper_rad - robot.q_lower_rad)
        self.q_start = mid
        self.room_rad = limit_fraction * half - START_SPREAD_RAD
        if (self.room_rad <= 0).any():
            raise SpaceIdInputError(f"excitation: the joint ranges of {robot.name} leave no room to move after the start spread")
        self.fraction = limit_fraction

    def states(self, x: FloatArray, t_s: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
        """Joint angles and rates (T, n) of coefficients ``x`` on the criterion's grid or at times ``t_s``."""
        b_q, b_dq = self.b_dq_q, self.b_dq
        if t_s is not None:
            b_q, b_dq, _ = self.template.basis(t_s)
            b_q = b_q - self.template.basis(np.zeros(1))[0]
        flat = x.reshape(self.n, -1).T  # (2H, n)
        return self.q_start + (b_q @ flat) * self.rate, (b_dq @ flat) * self.rate

    def value_and_gradient(self, x: FloatArray) -> tuple[float, FloatArray]:
        q, dq = self.states(x)
        maps = self.info.rate_maps(q)  # (T, n, 3, k)
        jac = np.einsum("tj,tjak->tak", dq, maps)
        scale = self.info.inverse_variance * self.weight
        fisher = np.einsum("tak,tal->kl", jac, jac) * scale
        sign, log_det = np.linalg.slogdet(fisher)
        if sign <= 0:
            return 1e6, np.zeros_like(x)
        d_jac = -2.0 * scale * jac @ np.linalg.inv(fisher)  # d(-log det F) / d J_t, (T, 3, k)
        d_dq = np.einsum("tak,tjak->tj", d_jac, maps)
        d_q = np.empty_like(q)
        for i in range(self.n):  # the maps' dependence on joint i's angle, forward differences
            shifted = q.copy()
            shifted[:, i] += _FD_STEP_RAD
            jac_i = np.einsum("tj,tjak->tak", dq, self.info.rate_maps(shifted))
            d_q[:, i] = np.einsum("tak,tak->t", d_jac, jac_i - jac) / _FD_STEP_RAD
        gradient = (self.b_dq.T @ (d_dq * self.rate) + self.b_dq_q.T @ (d_q * self.rate)).T  # (n, 2H)
        return -float(log_det), gradient.ravel()

    def constraints(self, n_constraint_grid: int) -> list[dict[str, Any]]:
        """Rest at t = 0 (equalities) and the limits on a grid (inequalities ``c - A x >= 0``)."""
        n, width = self.n, 2 * self.H
        zero = self.template.basis(np.zeros(1))
        rest = np.zeros((2 * n, n * width))
        for j in range(n):
            rest[2 * j, j * width : (j + 1) * width] = zero[1][0]
            rest[2 * j + 1, j * width : (j + 1) * width] = zero[2][0]
        t = np.linspace(0.0, self.duration_s, n_constraint_grid, endpoint=False)
        b_q, b_dq, b_ddq = self.template.basis(t)
        b_q = b_q - zero[0]
        blocks, bounds = [], []
        for j in range(n):
            for basis, bound in (
                (b_dq, self.fraction),
                (b_ddq * self.rate[j], self.fraction * self.accel[j]),
                (b_q * self.rate[j], self.room_rad[j]),
            ):
                block = np.zeros((len(t), n * width))
                block[:, j * width : (j + 1) * width] = basis
                blocks += [block, -block]
                bounds += [np.full(len(t), bound)] * 2
        a, c = np.vstack(blocks), np.concatenate(bounds)
        return [
            {"type": "eq", "fun": lambda x: rest @ x, "jac": lambda x: rest},
            {"type": "ineq", "fun": lambda x: c - a @ x, "jac": lambda x: -a},
        ]

    def peak_ratios(self, x: FloatArray, n_points: int = 3000) -> dict[str, float]:
        """Largest fraction of each limit used on a dense grid (1 = at the limit)."""
        t = np.linspace(0.0, self.duration_s, n_points, endpoint=False)
        b_q, b_dq, b_ddq = self.template.basis(t)
        flat = x.reshape(self.n, -1).T
        excursion = np.abs((b_q - self.template.basis(np.zeros(1))[0]) @ flat) * self.rate
        return {
            "rate": float((np.abs(b_dq @ flat) / self.fraction).max()),
            "acceleration": float((np.abs(b_ddq @ flat) * self.rate / (self.fraction * self.accel)).max()),
            "position": float((excursion / self.room_rad).max()),
        }

    def random_start(self, rng: np.random.Generator) -> FloatArray:
        """A random series with a falling spectrum, made to rest at t = 0 and scaled to 80 % of the tightest limit."""
        x = rng.uniform(-1.0, 1.0, size=(self.n, 2, self.H)) / np.arange(1, self.H + 1)
        harmonics = np.arange(1, self.H + 1)
        x[:, 0, :] -= x[:, 0, :].sum(axis=1, keepdims=True) / self.H  # sum_l a_l = 0: u(0) = 0
        x[:, 1, :] -= np.outer((x[:, 1, :] @ harmonics), harmonics) / (harmonics @ harmonics)  # sum_l l b_l = 0
        flat = x.ravel()
        return 0.8 * flat / max(self.peak_ratios(flat).values())


def optimise_fourier_excitation(
    robot: Robot,
    duration_s: float = 60.0,
    *,
    seed: int = 0,
    n_harmonics: int = 10,
    n_starts: int = 4,
    n_grid: int = 200,
    n_constraint_grid: int = 240,
    limit_fraction: float = 0.9,
    max_iterations: int = 60,
    theta0: FloatArray | None = None,
    control_period_s: float = 0.02,
) -> FourierDesign:
    """The optimised Fourier excitation of the fuel parameters (module docstring).

    Args:
        robot: the free-floating robot.
        duration_s: the window, s (the series' period).
        seed: seed of the random starts (``numpy.random.default_rng(seed)``).
        n_harmonics: H (base frequency ``1 / duration_s``).
        n_starts: seeded random starts; the best result is kept.
        n_grid: times of the criterion's grid (the gradient costs n + 1 CRBA sweeps of it).
        n_constraint_grid: times of the limits' grid.
        limit_fraction: fraction of each limit allowed.
        max_iterations: SLSQP iterations per start.
        theta0: the design point (see :class:`FuelInformation`).
        control_period_s: the env's sample period the information is for, s.
    """
    for name, value in (
        ("n_harmonics", n_harmonics),
        ("n_starts", n_starts),
        ("n_grid", n_grid),
        ("n_constraint_grid", n_constraint_grid),
    ):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise SpaceIdInputError(f"excitation: {name} must be an integer >= 1, got {value!r}")
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise SpaceIdInputError(f"excitation: duration must be a positive number of seconds, got {duration_s!r}")
    if not 0.0 < limit_fraction <= 1.0:
        raise SpaceIdInputError(f"excitation: limit_fraction must be in (0, 1], got {limit_fraction!r}")
    started = time.perf_counter()
    information = FuelInformation(robot, theta0, control_period_s=control_period_s)
    design = _Design(information, n_harmonics, float(duration_s), n_grid, limit_fraction)
    constraints = design.constraints(n_constraint_grid)
    rng = np.random.default_rng(seed)
    dense = np.linspace(0.0, duration_s, 3000, endpoint=False)

    def measured(x: FloatArray) -> ExcitationMeasures:  # on the dense grid, weighted to the env's sample rate
        return information.measures(*design.states(x, dense), samples_per_point=(duration_s / len(dense)) / control_period_s)

    best: tuple[float, FloatArray, FloatArray] | None = None
    starts: list[dict[str, Any]] = []
    with threadpool_limits(limits=1):  # small matrices: threads only add overhead on a shared machine
        for _ in range(n_starts):
            x0 = design.random_start(rng)
            result = scipy.optimize.minimize(
                design.value_and_gradient,
                x0,
                jac=True,
                method="SLSQP",
                constraints=constraints,
                options={"maxiter": max_iterations, "ftol": 1e-9},
            )
            x = result.x if np.isfinite(result.fun) else x0
            x = x / max(1.0, max(design.peak_ratios(x).values()))  # limits between the grid points
            before, after = measured(x0).d_optimality, measured(x).d_optimality
            starts.append({"d_optimality_start": before, "d_optimality_optimised": after, "message": str(result.message)})
            if best is None or after > best[0]:
                best = (after, x, x0)
    assert best is not None
    _, x, x0 = best
    shape = (robot.n_joints, 2, n_harmonics)
    return FourierDesign(
        excitation=FourierRateExcitation(x.reshape(shape), duration_s),
        start=FourierRateExcitation(x0.reshape(shape), duration_s),
        measures_start=measured(x0),
        measures_optimised=measured(x),
        starts=starts,
        peak_ratios=design.peak_ratios(x),
        wall_time_s=time.perf_counter() - started,
    )


def write_fourier_design(path: str | Path, design: FourierDesign, robot: Robot, params: str = "fuel") -> Path:
    """Write the design as JSON: the excitation, the robot and parameterisation it was optimised for, its measures."""
    doc = {
        **design.excitation.to_dict(),
        "robot": robot.name,
        "params": params,
        "criterion": "d-optimality of the fuel parameters (log det of the gyro's Fisher information, prior-range units)",
        "measures_start": design.measures_start.to_dict(),
        "measures_optimised": design.measures_optimised.to_dict(),
        "starts": design.starts,
        "peak_ratios": design.peak_ratios,
        "wall_time_s": design.wall_time_s,
    }
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=2))
    return out


def load_fourier_excitation(path: str | Path, robot: Robot, params: str = "fuel") -> FourierRateExcitation:
    """The excitation of a file :func:`write_fourier_design` wrote, checked against ``robot`` and ``params``.

    Raises:
        SpaceIdInputError: naming the file when it is unreadable, not such a file, or for another robot/parameterisation.
    """
    source = str(path)
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise SpaceIdInputError(f"{source}: cannot read the excitation file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise SpaceIdInputError(f"{source}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(doc, dict):
        raise SpaceIdInputError(f"{source}: expected a JSON object written by 'spaceid excite fourier'")
    if doc.get("robot") != robot.name:
        raise SpaceIdInputError(f"{source}: optimised for robot {doc.get('robot')!r}, not {robot.name!r}")
    if doc.get("params") != params:
        raise SpaceIdInputError(f"{source}: optimised for parameterisation {doc.get('params')!r}, not {params!r}")
    excitation = FourierRateExcitation.from_dict(doc, source)
    if excitation.n_joints != robot.n_joints:
        raise SpaceIdInputError(f"{source}: has {excitation.n_joints} joints, robot {robot.name!r} has {robot.n_joints}")
    return excitation
