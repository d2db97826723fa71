"""A synthetic fixed-base arm identification problem on pinocchio's sample manipulator (tests and benchmarks).

A stand-in for the UR5 model (``spaceid_gym.arm``) with everything the linear estimators need and a
known truth:

* robot: :func:`pinocchio.buildSampleModelManipulator` (6 revolute joints; its link inertias are the
  truth), plus per-joint friction ``tau_f = fc sign(dq) + fv dq`` with the documented ``FRICTION_TRUE``;
* full parameters in the source's ``p_dyn`` layout: per joint its link's params10 (pinocchio order, about
  the joint frame origin) then ``fc`` (N m), ``fv`` (N m s/rad): 12 per joint, 72 in all;
* regressor: :func:`pinocchio.computeJointTorqueRegressor` (n, 10 n) with the friction columns added,
  rows sample-major (sample t, joint j is row ``n t + j``);
* excitation: a finite Fourier series per joint (Swevers et al. 1997), ``dq_j(t) = sum_h a_jh cos(w_h t)
  + b_jh sin(w_h t)`` with ``w_h = 2 pi h f0``; ``q`` and ``ddq`` its exact integral and derivative;
* base parameters: :class:`~spaceid_gym.arm.regressor.BaseParameterSet` of the regressor stacked over
  random states (the UR5's QR: rank by pivoted QR, independent columns in the natural parameter order)
  gives the independent columns and ``K`` with ``Y theta_full = Y[:, independent] (K theta_full)``
  (Gautier 1990's numerical method); 50 base parameters for this arm;
* noise: white Gaussian per joint, ``NOISE_STD`` (about 2 % of each joint's torque RMS on the default
  excitation);
* search box: per link mass ``[0, 2]`` kg, first moments ``+-2`` kg m, diagonal inertia ``[0, 4]`` kg m^2,
  off-diagonal ``+-2`` kg m^2 (a 2 kg, 1 m body at most; the truth has 0.1-1 kg links, CoM 0-0.5 m from the
  joint), ``fc`` in ``[0, 2]`` N m, ``fv`` in ``[0, 1]`` N m s/rad; the base-parameter box is its image
  under ``K`` (interval arithmetic), so it holds every base vector of a body in the full box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from estimators.arm.consistency import PhysicalConsistency
from estimators.arm.linear_problem import LinearIdentificationProblem, image_box
from estimators.parameters import PARAMS10_NAMES
from spaceid_gym.arm.excitation_design import FourierTrajectory
from spaceid_gym.arm.regressor import BaseParameterSet
from spaceid_gym.arrays import FloatArray

IntArray = NDArray[np.intp]

N_JOINTS = 6
#: true friction per joint: Coulomb (N m), viscous (N m s/rad)
FRICTION_TRUE = np.array([[0.8, 0.4], [0.9, 0.3], [0.5, 0.2], [0.4, 0.2], [0.2, 0.1], [0.15, 0.05]])
#: torque noise std per joint (N m)
NOISE_STD = np.array([0.4, 0.5, 0.25, 0.2, 0.08, 0.06])
#: search box of one link (params10) and one joint's friction (fc, fv)
LINK_LOWER = np.array([0.0, -2.0, -2.0, -2.0, 0.0, -2.0, 0.0, -2.0, -2.0, 0.0])
LINK_UPPER = np.array([2.0, 2.0, 2.0, 2.0, 4.0, 2.0, 4.0, 2.0, 2.0, 4.0])
FRICTION_UPPER = np.array([2.0, 1.0])
#: mass range and size of the consistent search box (PhysicalConsistency)
CONSISTENT_MASS_RANGE_KG = (0.01, 2.0)
CONSISTENT_SIZE_M = 1.0

FULL_NAMES = tuple(
    name
    for j in range(1, N_JOINTS + 1)
    for name in (*(f"link{j}_{n}" for n in PARAMS10_NAMES), f"joint{j}_fc_nm", f"joint{j}_fv_nms_rad")
)


def sample_model() -> pin.Model:
    """pinocchio's sample manipulator (6 revolute joints)."""
    return pin.buildSampleModelManipulator()


def true_full_parameters(model: pin.Model) -> FloatArray:
    """The truth (72,): the sample model's link params10 and ``FRICTION_TRUE``, per joint."""
    return np.concatenate(
        [np.concatenate((model.inertias[j + 1].toDynamicParameters(), FRICTION_TRUE[j])) for j in range(N_JOINTS)]
    )


def fourier_trajectory(
    rng: np.random.Generator,
    n_samples: int,
    dt_s: float = 0.05,
    n_harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    rate_amplitude_rad_s: float = 1.0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Joint angles (rad), rates (rad/s) and accelerations (rad/s^2), each (n_samples, 6), of a random
    :class:`~spaceid_gym.arm.excitation_design.FourierTrajectory` sampled from t = 0 every ``dt_s``.

    Coefficients ``a, b ~ N(0, (rate_amplitude / n_harmonics)^2)`` per joint and harmonic; mean angles ``q0 ~ U(-1, 1)`` rad.
    """
    a, b = rng.normal(scale=rate_amplitude_rad_s / n_harmonics, size=(2, N_JOINTS, n_harmonics))
    q0 = rng.uniform(-1.0, 1.0, N_JOINTS)
    trajectory = FourierTrajectory(N_JOINTS, n_harmonics, base_frequency_hz, np.stack((a, b), axis=1), q0)
    return trajectory.state(np.arange(n_samples) * dt_s)


def arm_regressor(model: pin.Model, q: FloatArray, dq: FloatArray, ddq: FloatArray) -> FloatArray:
    """Regressor (T, 6, 72) with friction columns, full-parameter layout of the module docstring."""
    data = model.createData()
    n_samples = len(q)
    out = np.zeros((n_samples, N_JOINTS, 12, N_JOINTS))  # (t, row joint, column within joint block, column joint)
    joints = np.arange(N_JOINTS)
    for t in range(n_samples):
        inertial = pin.computeJointTorqueRegressor(model, data, q[t], dq[t], ddq[t])  # (6, 60)
        out[t, :, :10, :] = inertial.reshape(N_JOINTS, N_JOINTS, 10).transpose(0, 2, 1)
    out[:, joints, 10, joints] = np.sign(dq)
    out[:, joints, 11, joints] = dq
    return out.transpose(0, 1, 3, 2).reshape(n_samples, N_JOINTS, 12 * N_JOINTS)


def arm_base_parameters(model: pin.Model, n_states: int = 300, seed: int = 12345) -> BaseParameterSet:
    """The base parameters of the arm's regressor (:data:`FULL_NAMES`) at ``n_states`` random states.

    Angles ``U(-pi, pi)`` rad, rates ``N(0, 2^2)`` rad/s, accelerations ``N(0, 5^2)`` rad/s^2, from ``seed``.
    """
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (n_states, N_JOINTS))
    dq = rng.normal(scale=2.0, size=(n_states, N_JOINTS))
    ddq = rng.normal(scale=5.0, size=(n_states, N_JOINTS))
    return BaseParameterSet.from_matrix(arm_regressor(model, q, dq, ddq).reshape(-1, 12 * N_JOINTS), FULL_NAMES)


def full_box() -> tuple[FloatArray, FloatArray]:
    """The full-parameter search box (72,) x 2 (module docstring)."""
    lower = np.tile(np.concatenate((LINK_LOWER, [0.0, 0.0])), N_JOINTS)
    upper = np.tile(np.concatenate((LINK_UPPER, FRICTION_UPPER)), N_JOINTS)
    return lower, upper


@dataclass
class ArmData:
    """One simulated experiment: regressor (N, 72), noisy torques (N,), joint of each row (N,), noise std per row (N,)."""

    Y_full: FloatArray
    tau: FloatArray
    row_group: IntArray
    row_std: FloatArray


def simulate(
    model: pin.Model,
    theta_full: FloatArray,
    rng: np.random.Generator,
    n_samples: int,
    n_segments: int = 1,
    noise_scale: float = 1.0,
) -> ArmData:
    """Torques of ``theta_full`` (72,) with noise ``noise_scale x NOISE_STD`` along ``n_segments`` independent
    :func:`fourier_trajectory` segments of ``n_samples // n_segments`` samples each (more segments: more of the
    joint space visited)."""
    segments = [fourier_trajectory(rng, n_samples // n_segments) for _ in range(n_segments)]
    q, dq, ddq = (np.concatenate(part) for part in zip(*segments, strict=True))
    regressor = arm_regressor(model, q, dq, ddq).reshape(-1, 12 * N_JOINTS)
    std = np.tile(noise_scale * NOISE_STD, len(q))
    tau = regressor @ theta_full + rng.normal(size=std.size) * std
    return ArmData(regressor, tau, np.tile(np.arange(N_JOINTS), len(q)), std)


@dataclass
class ArmBenchmark:
    """The base-parameter problem of one experiment, its truth and a held-out experiment.

    Attributes:
        problem: :class:`~estimators.arm.linear_problem.LinearIdentificationProblem` in base parameters (r = 50), with a
            :class:`~estimators.arm.consistency.PhysicalConsistency` (``base_map`` = K); noise unknown to it unless
            ``known_noise``.
        theta_true: (r,) true base parameters; full_true: (72,) true full parameters; base_map: K (r, 72);
        independent: (r,) the full-parameter columns of the base regressor; row_std: (N,) the true noise std per row.
        holdout: another trajectory with fresh noise (:class:`ArmData`).
    """

    problem: LinearIdentificationProblem
    theta_true: FloatArray
    full_true: FloatArray
    base_map: FloatArray
    independent: IntArray
    row_std: FloatArray
    holdout: ArmData

    def crlb(self) -> FloatArray:
        """Cramér-Rao std (r,) of the base parameters for the true noise (``row_std``), at the truth."""
        return self.problem.crlb_std(self.theta_true, self.row_std)

    def parameter_error(self, theta: FloatArray) -> float:
        """RMS over the base parameters of ``(theta - truth) / Cramér-Rao std``: about 1 for an efficient estimate
        (``nan`` if the data leave a parameter's bound unbounded)."""
        bound = self.crlb()
        if not np.all(np.isfinite(bound)):
            return float("nan")
        return float(np.sqrt(np.mean(((np.asarray(theta) - self.theta_true) / bound) ** 2)))

    def holdout_error(self, theta: FloatArray) -> float:
        """Held-out torque residual RMS in noise units, ``sqrt(mean(((Y_b theta - tau) / s)^2))``: ~1 at the truth."""
        predicted = self.holdout.Y_full[:, self.independent] @ np.asarray(theta)
        return float(np.sqrt(np.mean(((predicted - self.holdout.tau) / self.holdout.row_std) ** 2)))


def arm_benchmark(
    seed: int, n_samples: int = 400, n_segments: int = 4, known_noise: bool = False, noise_scale: float = 1.0
) -> ArmBenchmark:
    """The documented base-parameter problem (module docstring) from ``seed``.

    Identification data: ``n_samples`` samples at 20 Hz in ``n_segments`` independent Fourier segments (default
    4 x 5 s, 2400 rows); held out: one 200-sample (10 s) segment with its own trajectory and noise.
    ``known_noise`` gives the problem the true ``row_std`` (else it estimates the noise per joint).
    """
    model = sample_model()
    base = arm_base_parameters(model)
    k_map, independent = base.K, base.independent
    full_true = true_full_parameters(model)
    fit_rng, holdout_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    data = simulate(model, full_true, fit_rng, n_samples, n_segments, noise_scale)
    holdout = simulate(model, full_true, holdout_rng, 200, 1, noise_scale)
    lower, upper = image_box(k_map, *full_box())
    consistency = PhysicalConsistency.per_joint(
        N_JOINTS,
        mass_range_kg=CONSISTENT_MASS_RANGE_KG,
        size_m=CONSISTENT_SIZE_M,
        friction_upper=FRICTION_UPPER,
        base_map=k_map,
    )
    problem = LinearIdentificationProblem(
        data.Y_full[:, independent],
        data.tau,
        base.names,
        lower,
        upper,
        row_std=data.row_std if known_noise else None,
        row_group=data.row_group,
        consistency=consistency,
        name="base",
    )
    return ArmBenchmark(problem, k_map @ full_true, full_true, k_map, independent, data.row_std, holdout)


#: the last link replaced by a thin rod for :func:`last_link_problem`: 1 kg, 0.5 m long along z, CoM 0.25 m out,
#: inertia about the CoM diag(m L^2 / 12, m L^2 / 12, 1e-4) kg m^2: consistent, close to the boundary (a thin body)
ROD_MASS_KG, ROD_LENGTH_M = 1.0, 0.5


def rod_params10() -> FloatArray:
    """params10 (10,) of the thin rod (``ROD_MASS_KG``, ``ROD_LENGTH_M``), about the last joint's origin."""
    inertia_com = np.diag([ROD_MASS_KG * ROD_LENGTH_M**2 / 12.0] * 2 + [1e-4])
    return pin.Inertia(ROD_MASS_KG, np.array([0.0, 0.0, ROD_LENGTH_M / 2.0]), inertia_com).toDynamicParameters()


def last_link_problem(seed: int, n_samples: int = 20, noise_scale: float = 1.0) -> tuple[LinearIdentificationProblem, FloatArray]:
    """Identify only the last link's params10 (a thin rod, :func:`rod_params10`), the rest of the arm known.

    The torques of the known links and friction are subtracted, leaving ``tau - Y_known theta_known = Y_6 p_6``: 10
    unknowns, full rank (the six joint torques carry the whole wrench of the last link). With a short excitation
    (default 20 samples, 1 s) and noise the least-squares estimate of such a thin body often is not physically
    consistent. Returns the problem (with a one-link :class:`PhysicalConsistency`) and the true params10.
    """
    model = sample_model()
    model.inertias[N_JOINTS] = pin.Inertia.FromDynamicParameters(rod_params10())
    full_true = true_full_parameters(model)
    data = simulate(model, full_true, np.random.default_rng(seed), n_samples, 1, noise_scale)
    link = 12 * (N_JOINTS - 1) + np.arange(10)
    known = np.setdiff1d(np.arange(12 * N_JOINTS), link)
    consistency = PhysicalConsistency(
        link_columns=np.arange(10)[None, :],
        friction_columns=np.zeros(0, dtype=np.intp),
        mass_range_kg=[CONSISTENT_MASS_RANGE_KG],
        size_m=[CONSISTENT_SIZE_M],
        friction_upper=np.zeros(0),
    )
    problem = LinearIdentificationProblem(
        data.Y_full[:, link],
        data.tau - data.Y_full[:, known] @ full_true[known],
        [FULL_NAMES[i] for i in link],
        LINK_LOWER,
        LINK_UPPER,
        row_group=data.row_group,
        consistency=consistency,
    )
    return problem, full_true[link]
