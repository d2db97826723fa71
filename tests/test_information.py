"""Fisher information: the incremental kernel used by the reward against the batch routine."""

from __future__ import annotations

import numpy as np
import pytest

from spaceid_gym.information import add_information, cramer_rao_std, fisher_information, log_det


def test_incremental_information_matches_batch() -> None:
    rng = np.random.default_rng(0)
    jacobians = rng.normal(size=(50, 3, 4))
    sigma = 0.3
    information, value = np.eye(4), 0.0
    for jac in jacobians:
        information, value = add_information(information, jac, 1.0 / sigma**2)
    expected = np.eye(4) + fisher_information(jacobians, sigma)
    np.testing.assert_allclose(information, expected, rtol=1e-12)
    assert value == pytest.approx(np.linalg.slogdet(expected)[1], rel=1e-12)
    assert value == pytest.approx(log_det(expected), rel=1e-12)
    np.testing.assert_allclose(cramer_rao_std(expected), np.sqrt(np.diag(np.linalg.inv(expected))), rtol=1e-12)


def test_non_positive_definite_information_has_minus_infinite_log_det() -> None:
    _, value = add_information(np.zeros((2, 2)), np.array([[1.0, 1.0]]), 1.0)
    assert value == -np.inf
