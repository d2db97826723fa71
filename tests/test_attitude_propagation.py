"""The encoders' noise propagated into the attitude channel's residual (estimators/attitude_propagation.py): against
the channel itself moved by one encoder sample, and against the simulator's own noise on a noise-free attitude."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import cholesky

from estimators.attitude_channel import AttitudeChannel, noise_from_dict
from estimators.attitude_noise import fit_attitude_noise
from estimators.attitude_propagation import (
    EncoderPropagation,
    PropagatedNoise,
    encoder_propagation,
    fit_propagated_noise,
    propagated_log_likelihood,
    whiten_block_banded,
    whiten_propagated,
)
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
    propagation = encoder_propagation(model, log, theta)
    whitened, _ = whiten_propagated(d, propagation, PropagatedNoise(encoder_std))
    n = whitened.size
    chi2_per_value = float(np.sum(whitened**2)) / n
    # unit variance within 4 sampling std (sqrt(2 / n) = 0.041), each axis too, and no correlation between steps
    assert abs(chi2_per_value - 1.0) < 4.0 * np.sqrt(2.0 / n)
    for axis in range(3):
        assert abs(float(np.mean(whitened[:, axis] ** 2)) - 1.0) < 4.0 * np.sqrt(2.0 / len(whitened))
        lag1 = float(np.corrcoef(whitened[1:, axis], whitened[:-1, axis])[0, 1])
        assert abs(lag1) < 4.0 / np.sqrt(len(whitened))
    # a stationary white model of the same total variance per axis misdescribes it: the covariance is nearly flat at
    # each sample (the momentum map carries the joints' noise into two directions of rotation far more than the third)
    eigenvalues = np.linalg.eigvalsh(propagation.unit_diagonal)
    assert np.median(eigenvalues[:, 0] / eigenvalues[:, 2]) < 0.05


def test_the_banded_whitening_matches_a_dense_cholesky_and_its_log_determinant() -> None:
    rng = np.random.default_rng(7)
    m = 12
    # a covariance of block bandwidth 2: M M^T with M's 3x3 blocks on the diagonal and the two below it
    mixing = np.zeros((3 * m, 3 * m))
    for k in range(m):
        for lag in range(3):
            if k - lag >= 0:
                mixing[3 * k : 3 * k + 3, 3 * (k - lag) : 3 * (k - lag) + 3] = rng.normal(size=(3, 3))
    dense = mixing @ mixing.T + 0.1 * np.eye(3 * m)
    blocks = tuple(
        np.array([dense[3 * k : 3 * k + 3, 3 * (k - lag) : 3 * (k - lag) + 3] for k in range(lag, m)]) for lag in range(3)
    )
    values = rng.normal(size=(m, 3, 2))
    whitened, log_det = whiten_block_banded(values, blocks)
    factor = cholesky(dense, lower=True)
    np.testing.assert_allclose(whitened.reshape(3 * m, 2), np.linalg.solve(factor, values.reshape(3 * m, 2)), rtol=1e-10)
    assert log_det == pytest.approx(np.linalg.slogdet(dense)[1], rel=1e-12)
    with pytest.raises(SpaceIdInputError, match="not positive definite"):
        whiten_block_banded(values, tuple(-b for b in blocks))


def test_the_filtered_covariance_is_that_of_the_filtered_steps() -> None:
    """The covariance of ``u_k = d_k - phi d_{k-1}`` from the blocks, against the dense covariance of the steps built
    from P, C, the white error and the wander's steps (an AR(1) with correlation phi) and filtered explicitly."""
    rng = np.random.default_rng(3)
    m, n, phi = 9, 2, 0.6
    propagation = EncoderPropagation(rng.normal(size=(m, 3, n)), rng.normal(size=(m, 3, n)))
    noise = PropagatedNoise(0.7, 0.3, 0.2, phi)
    # steps d (3m) = E n (n_samples = m + 1 encoder samples) + white differences + wander steps
    encoder = np.zeros((3 * m, n * (m + 1)))
    white = np.zeros((3 * m, 3 * (m + 1)))
    for k in range(m):
        encoder[3 * k : 3 * k + 3, n * k : n * k + n] = propagation.previous[k]
        encoder[3 * k : 3 * k + 3, n * (k + 1) : n * (k + 1) + n] = propagation.current[k]
        white[3 * k : 3 * k + 3, 3 * (k + 1) : 3 * (k + 1) + 3] = np.eye(3)
        white[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = -np.eye(3)
    steps = np.array([[phi ** abs(i - j) for j in range(m)] for i in range(m)]) * noise.walk_std_rad**2 / (1 - phi * phi)
    cov_d = 0.49 * encoder @ encoder.T + 0.09 * white @ white.T + np.kron(steps, np.eye(3))
    filter_ = np.zeros((3 * (m - 1), 3 * m))
    for k in range(1, m):
        filter_[3 * (k - 1) : 3 * k, 3 * k : 3 * k + 3] = np.eye(3)
        filter_[3 * (k - 1) : 3 * k, 3 * (k - 1) : 3 * k] = -phi * np.eye(3)
    dense = filter_ @ cov_d @ filter_.T
    lag0, lag1, lag2 = propagation.covariance(noise)
    for lag, blocks in enumerate((lag0, lag1, lag2)):
        for k in range(lag, m - 1):
            np.testing.assert_allclose(blocks[k - lag], dense[3 * k : 3 * k + 3, 3 * (k - lag) : 3 * (k - lag) + 3], atol=1e-12)
    assert np.max(np.abs(dense[9:, :3])) < 1e-12  # nothing beyond two blocks but the wander's own correlation, filtered out


def test_a_model_with_a_state_in_time_is_refused(exact_log: tuple) -> None:
    model, log, theta, _ = exact_log
    slosh = candidate_model(model, "slosh")
    term = slosh.parameters.terms[-1]
    start = np.concatenate((theta, term.nominal + term.scale))  # a slosh mass on: the liquid moves in time
    with pytest.raises(SpaceIdInputError, match="carries a state in time"):
        encoder_propagation(slosh, log, start)


def test_the_fitted_error_model_finds_the_simulated_encoder_noise_and_a_star_trackers_white_error(exact_log: tuple) -> None:
    model, log, theta, encoder_std = exact_log
    channel = AttitudeChannel.of(model, log, reference=theta)
    assert channel is not None
    propagation = encoder_propagation(model, log, theta)
    d = channel.differences(theta)
    exact = fit_propagated_noise(d, propagation)
    # 1197 values: the variance's sampling std is 4 %, its std's 2 %
    assert exact.encoder_std_rad == pytest.approx(encoder_std, rel=0.08)
    assert exact.white_std_rad < 0.05 * encoder_std
    # the same steps with a star tracker's white error added (its differences), as large as the encoders' part on
    # average: both found
    white = encoder_std * float(np.sqrt(np.trace(propagation.unit_diagonal.mean(axis=0)) / 6.0))
    errors = np.random.default_rng(11).normal(0.0, white, size=(len(d) + 1, 3))
    tracker = fit_propagated_noise(d + np.diff(errors, axis=0), propagation)
    assert tracker.white_std_rad == pytest.approx(white, rel=0.1)
    assert tracker.encoder_std_rad == pytest.approx(encoder_std, rel=0.1)
    # the maximum: no nearby error model is more likely by more than 0.1 unit (each number moved alone; the white error
    # and the wander sit at the explored range's end, 1e-6 of the encoders' std, below which -2 log L falls by 0.06)
    best = propagated_log_likelihood(d, propagation, exact)
    fields = ("encoder_std_rad", "white_std_rad", "walk_std_rad")
    for label in fields:
        for factor in (0.5, 2.0):
            moved = dataclasses.replace(exact, **{label: getattr(exact, label) * factor})
            assert propagated_log_likelihood(d, propagation, moved) >= best - 0.1
    for phi in (0.3, 0.9):
        assert propagated_log_likelihood(d, propagation, dataclasses.replace(exact, walk_correlation=phi)) >= best - 0.1
    # a white error that carries a quarter of the encoders' variance per axis is far less likely than the fit
    quarter = exact.encoder_std_rad * float(np.sqrt(np.trace(propagation.unit_diagonal.mean(axis=0)) / 12.0))
    assert propagated_log_likelihood(d, propagation, dataclasses.replace(exact, white_std_rad=quarter)) > best + 10.0
    # a refit from a start: the start's own kind and at least as likely
    again = fit_propagated_noise(d, propagation, start=dataclasses.replace(exact, encoder_std_rad=1.3 * encoder_std))
    assert propagated_log_likelihood(d, propagation, again) <= propagated_log_likelihood(
        d, propagation, dataclasses.replace(exact, encoder_std_rad=1.3 * encoder_std)
    )
    assert again.encoder_std_rad == pytest.approx(exact.encoder_std_rad, rel=1e-6)  # the scale is profiled exactly
    # the written form reads back, and noise_from_dict tells the two kinds apart
    assert PropagatedNoise.from_dict(exact.to_dict()) == exact and noise_from_dict(exact.to_dict()) == exact
    with pytest.raises(SpaceIdInputError, match="walk_correlation"):
        PropagatedNoise(1e-6, walk_correlation=1.0)


def test_the_channel_chooses_the_propagated_error_model_on_an_exact_attitude_and_whitens_with_it(exact_log: tuple) -> None:
    model, log, theta, encoder_std = exact_log
    channel = AttitudeChannel.of(model, log, reference=theta)
    assert channel is not None
    noise = channel.estimate_noise(theta)
    assert isinstance(noise, PropagatedNoise)
    assert noise.encoder_std_rad == pytest.approx(encoder_std, rel=0.08)
    r = channel.residuals(theta, noise)
    assert r.shape == (channel.n_values,)
    assert abs(float(r @ r) / r.size - 1.0) < 4.0 * np.sqrt(2.0 / r.size)
    # the stationary model it beat: -2 log L thousands of units higher on the same values
    stationary = fit_attitude_noise(channel.differences(theta) @ channel.axes)
    assert channel.profile_chi2(theta, stationary, noise) - channel.profile_chi2(theta, noise, noise) > 1000.0
    # rows for many unknowns at once, and the Jacobian, under the same whitening
    thetas = np.stack([theta, theta * (1.0 + 1e-4)])
    rows = channel.residual_rows(thetas, noise)
    np.testing.assert_allclose(rows[0], r, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(rows[1], channel.residuals(thetas[1], noise), rtol=1e-10, atol=1e-12)
    jac = channel.jacobian(theta, noise)
    step = 1e-6 * np.maximum(np.abs(theta), 1e-3)
    for j in range(len(theta)):
        moved = theta.copy()
        moved[j] += step[j]
        numeric = (channel.residuals(moved, noise) - r) / step[j]
        np.testing.assert_allclose(jac[:, j], numeric, rtol=1e-3, atol=1e-4 * float(np.max(np.abs(numeric))))
    # the profile chi-square between the two kinds is the difference of their -2 log L on the same values
    assert channel.profile_chi2(theta, stationary, noise) - channel.profile_chi2(theta, noise, noise) == pytest.approx(
        fit_and_score(channel, theta, stationary)
        - propagated_log_likelihood(
            channel.differences(theta) @ channel.axes, encoder_propagation(model, log, theta).in_axes(channel.axes), noise
        ),
        rel=1e-9,
    )


def fit_and_score(channel: AttitudeChannel, theta: np.ndarray, noise: object) -> float:
    """``-2 log L`` of the channel's residual at ``theta`` under a stationary ``noise``: chi-square plus log-determinant."""
    d = channel.differences(theta) @ channel.axes
    whitened = noise.whiten(d)  # type: ignore[attr-defined]
    return float(np.sum(whitened**2)) + noise.log_det(len(d))  # type: ignore[attr-defined]
