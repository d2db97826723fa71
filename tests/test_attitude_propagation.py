"""The encoders' noise propagated into the attitude channel's residual (estimators/attitude_propagation.py): against
the channel itself moved by one encoder sample, and against the simulator's own noise on a noise-free attitude."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import cholesky

from estimators.attitude_channel import AttitudeChannel
from estimators.attitude_propagation import encoder_propagation, whiten_block_tridiagonal
from estimators.diagnostics.diagnose import candidate_model
from estimators.diagnostics.workflow import true_parameters
from estimators.problem import IdentificationModel
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.variations import draw_variation, simulate_variation, truth_of


@pytest.fixture(scope="module")
def exact_log() -> tuple[IdentificationModel, object, np.ndarray, float]:
    """A clean 8 s log of quick3 at 50 Hz with a noise-free attitude, its model, true unknowns and encoder noise std."""
    fixed = {"robot": "quick3", "rate_hz": 50, "attitude": "exact", "noise_scale": 1.0, "excitation": "evaluation"}
    env = simulate_variation(draw_variation("none", 4242, fixed), 8.0)
    model = IdentificationModel(env.robot, "fuel")
    theta = true_parameters(model, truth_of(env))
    assert theta is not None
    return model, env.measurement_log(), theta, env.sensors.joint_angle_std_rad()


def test_one_encoder_sample_moves_the_channels_two_steps_as_propagated(exact_log: tuple) -> None:
    model, log, theta, _ = exact_log
    propagation = encoder_propagation(model, log, theta)
    channel = AttitudeChannel.of(model, log, reference=theta)
    assert channel is not None
    before = channel.differences(theta)
    sample, eps = 200, 1e-7
    for joint in range(log.q_rad.shape[1]):
        q = np.array(log.q_rad)
        q[sample, joint] += eps
        moved = AttitudeChannel.of(model, dataclasses.replace(log, q_rad=q), reference=theta)
        assert moved is not None
        change = (moved.differences(theta) - before) / eps  # row k - 1 is step k
        predicted = np.zeros_like(change)
        predicted[sample - 1] = propagation.current[sample - 1, :, joint]  # step `sample` ends at the sample
        predicted[sample] = propagation.previous[sample, :, joint]  # step `sample + 1` starts at it
        scale = np.max(np.abs(predicted))
        assert scale > 0.0
        # the channel's integration-error correction, recomputed from the moved encoders, adds its own sensitivity
        # over the neighbouring steps: 1e-4 of the midpoint prediction's (3.5e-4 at most on quick3, 50 Hz; orbit7 at
        # 20 Hz 4.3e-4, paper6 at 100 Hz 0.9e-4)
        np.testing.assert_allclose(change, predicted, atol=2e-3 * scale)


def test_the_simulators_encoder_noise_whitens_to_unit_variance_under_the_propagated_covariance(exact_log: tuple) -> None:
    model, log, theta, encoder_std = exact_log
    channel = AttitudeChannel.of(model, log, reference=theta)
    assert channel is not None
    d = channel.differences(theta)
    diagonal, below = encoder_propagation(model, log, theta).covariance(encoder_std)
    whitened, _ = whiten_block_tridiagonal(d, diagonal, below)
    n = whitened.size
    chi2_per_value = float(np.sum(whitened**2)) / n
    # unit variance within 4 sampling std (sqrt(2 / n) = 0.027), each axis too, and no correlation between steps
    assert abs(chi2_per_value - 1.0) < 4.0 * np.sqrt(2.0 / n)
    for axis in range(3):
        assert abs(float(np.mean(whitened[:, axis] ** 2)) - 1.0) < 4.0 * np.sqrt(2.0 / len(whitened))
        lag1 = float(np.corrcoef(whitened[1:, axis], whitened[:-1, axis])[0, 1])
        assert abs(lag1) < 4.0 / np.sqrt(len(whitened))
    # a stationary white model of the same total variance per axis misdescribes it: the covariance is nearly flat at
    # each sample (the momentum map carries the joints' noise into two directions of rotation far more than the third)
    eigenvalues = np.linalg.eigvalsh(diagonal)
    assert np.median(eigenvalues[:, 0] / eigenvalues[:, 2]) < 0.05


def test_the_banded_whitening_matches_a_dense_cholesky_and_its_log_determinant() -> None:
    rng = np.random.default_rng(7)
    m = 12
    p, c = rng.normal(size=(m, 3, 4)), rng.normal(size=(m, 3, 4))
    diagonal = np.einsum("kin,kjn->kij", p, p) + np.einsum("kin,kjn->kij", c, c) + 0.1 * np.eye(3)
    below = np.einsum("kin,kjn->kij", p[1:], c[:-1])
    dense = np.zeros((3 * m, 3 * m))
    for k in range(m):
        dense[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = diagonal[k]
        if k:
            dense[3 * k : 3 * k + 3, 3 * k - 3 : 3 * k] = below[k - 1]
            dense[3 * k - 3 : 3 * k, 3 * k : 3 * k + 3] = below[k - 1].T
    values = rng.normal(size=(m, 3, 2))
    whitened, log_det = whiten_block_tridiagonal(values, diagonal, below)
    factor = cholesky(dense, lower=True)
    np.testing.assert_allclose(whitened.reshape(3 * m, 2), np.linalg.solve(factor, values.reshape(3 * m, 2)), rtol=1e-10)
    assert log_det == pytest.approx(np.linalg.slogdet(dense)[1], rel=1e-12)
    with pytest.raises(SpaceIdInputError, match="not positive definite"):
        whiten_block_tridiagonal(values, -diagonal, below)


def test_a_model_with_a_state_in_time_is_refused(exact_log: tuple) -> None:
    model, log, theta, _ = exact_log
    slosh = candidate_model(model, "slosh")
    term = slosh.parameters.terms[-1]
    start = np.concatenate((theta, term.nominal + term.scale))  # a slosh mass on: the liquid moves in time
    with pytest.raises(SpaceIdInputError, match="carries a state in time"):
        encoder_propagation(slosh, log, start)
