"""The Dahl presliding state (spaceid_gym.arm.presliding): exact per step against a fine-step ODE reference, the
sign of the rate as the presliding length goes to zero, and clear errors on bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from spaceid_gym.arm.presliding import presliding_state
from spaceid_gym.errors import SpaceIdInputError


def _positions(seed: int, n_samples: int = 400, n_joints: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Times (T,) s and positions (T, n) rad at 125 Hz: slow sines with reversals, small ripples and rests."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * 0.008
    q = 0.3 * np.sin(2 * np.pi * rng.uniform(0.2, 0.6, n_joints) * t[:, None] + rng.uniform(0, 2 * np.pi, n_joints))
    q += 2e-3 * np.sin(2 * np.pi * 7.0 * t[:, None])  # presliding-sized ripples: reversals every few samples
    q[100:140] = q[100]  # a rest
    return t, q


def _ode_reference(t: np.ndarray, q: np.ndarray, delta: float, initial: float) -> np.ndarray:
    """``h`` (T,) of one joint by RK45 at a tight tolerance through ``dh/dt = (v - |v| h) / delta``, with the rate
    ``v`` constant over each step (positions linear between samples)."""
    h = np.empty(len(t))
    h[0] = initial
    for k in range(len(t) - 1):
        v = (q[k + 1] - q[k]) / (t[k + 1] - t[k])
        solution = solve_ivp(
            lambda _, y, v=v: (v - abs(v) * y) / delta, (t[k], t[k + 1]), [h[k]], method="RK45", rtol=1e-11, atol=1e-13
        )
        h[k + 1] = solution.y[0, -1]
    return h


@pytest.mark.parametrize("seed", [0, 1])
def test_exact_step_matches_a_fine_step_ode_reference(seed: int) -> None:
    t, q = _positions(seed)
    deltas = np.array([1e-4, 2e-3, 5e-2])
    h = presliding_state(q, np.tile(deltas, (q.shape[1], 1)), initial=0.3)  # (T, n, G)
    assert h.shape == (*q.shape, len(deltas))
    for j in range(q.shape[1]):
        for g, delta in enumerate(deltas):
            reference = _ode_reference(t, q[:, j], delta, 0.3)
            np.testing.assert_allclose(h[:, j, g], reference, atol=1e-8, rtol=0)
    assert np.all(np.abs(h) <= 1.0)
    np.testing.assert_array_equal(h[101:140], np.broadcast_to(h[100], h[101:140].shape))  # held at rest


def test_one_length_per_joint_matches_the_grid_form() -> None:
    _, q = _positions(2)
    deltas = np.array([1e-3, 1e-2, 3e-2])
    per_joint = presliding_state(q, deltas)
    grid = presliding_state(q, np.tile(deltas, (3, 1)))
    np.testing.assert_array_equal(per_joint, grid[:, np.arange(3), np.arange(3)])


def test_vanishing_presliding_length_gives_the_sign_of_the_last_motion() -> None:
    _, q = _positions(3)
    h = presliding_state(q, np.full(q.shape[1], 1e-12))
    step_sign = np.sign(np.diff(q, axis=0))
    moving = step_sign != 0
    np.testing.assert_array_equal(h[1:][moving], step_sign[moving])
    # at rest the state keeps the sign of the motion before
    np.testing.assert_array_equal(h[101:140], np.broadcast_to(h[100], h[101:140].shape))


def test_long_motion_in_one_direction_saturates_after_a_few_lengths() -> None:
    q = np.linspace(0.0, 0.05, 501)[:, None]  # 1e-4 rad per step
    h = presliding_state(q, np.array([1e-2]), initial=-1.0)
    # exactly -1 + 2 (1 - exp(-x / delta)) after a displacement x from -1
    np.testing.assert_allclose(h[:, 0], 1.0 - 2.0 * np.exp(-(q[:, 0] - q[0, 0]) / 1e-2), atol=1e-12)


@pytest.mark.parametrize(
    ("q", "delta", "initial", "message"),
    [
        (np.zeros((5, 2)), np.array([1e-3]), 0.0, "shape"),
        (np.zeros((5, 2)), np.array([1e-3, 0.0]), 0.0, "> 0"),
        (np.zeros((5, 2)), np.array([1e-3, 1e-3]), 1.5, "initial"),
        (np.full((5, 2), np.nan), np.array([1e-3, 1e-3]), 0.0, "non-finite"),
        (np.zeros(5), np.array([1e-3]), 0.0, "q_rad"),
    ],
)
def test_bad_input_is_named(q: np.ndarray, delta: np.ndarray, initial: float, message: str) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        presliding_state(q, delta, initial)
