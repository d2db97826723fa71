"""Fisher information: the incremental kernel used by the reward against the batch routine."""

from __future__ import annotations

import numpy as np
import pytest

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.information import add_information, cramer_rao_std, excitation_measures, fisher_information, log_det


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


def test_excitation_measures_match_closed_form() -> None:
    """A diagonal information ``diag(d)`` in scaled units: log det = sum log d, stds = scale / sqrt(d), cond = max/min."""
    d, scale = np.array([4.0, 25.0, 100.0, 1.0]), np.array([2.0, 0.5, 0.5, 0.5])
    rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(4, 4)))[0]
    measures = excitation_measures(np.diag(d), scale)
    assert measures.d_optimality == pytest.approx(np.log(d).sum(), rel=1e-12)
    assert measures.condition_number == pytest.approx(100.0, rel=1e-12)
    np.testing.assert_allclose(measures.cramer_rao_std, scale / np.sqrt(d), rtol=1e-12)
    assert measures.max_cramer_rao_std == pytest.approx(1.0)  # the scaled std of the last parameter
    rotated = excitation_measures(rotation @ np.diag(d) @ rotation.T)  # log det and cond are rotation invariant
    assert rotated.d_optimality == pytest.approx(measures.d_optimality, rel=1e-10)
    assert rotated.condition_number == pytest.approx(100.0, rel=1e-8)


def test_excitation_measures_of_singular_information_and_bad_input() -> None:
    measures = excitation_measures(np.diag([1.0, 0.0]))
    assert measures.d_optimality == -np.inf and measures.condition_number == np.inf and measures.max_cramer_rao_std == np.inf
    with pytest.raises(SpaceIdInputError, match="information"):
        excitation_measures(np.ones((2, 3)))
    with pytest.raises(SpaceIdInputError, match="scale"):
        excitation_measures(np.eye(2), np.array([1.0, -1.0]))
