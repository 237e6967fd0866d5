"""Error metrics against values computed by hand, and their identities for any data."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from id_learning.evaluation.metrics import (
    absolute_errors,
    error_metrics,
    mse,
    nmse,
    normalised_mse,
    normalised_rmse,
    rmse,
)

# Two samples, two joints. Errors [[1, 0], [2, 3]]; target columns [0, 1] and [2, 1].
PREDICTION = np.array([[1.0, 2.0], [3.0, 4.0]])
TARGET = np.array([[0.0, 2.0], [1.0, 1.0]])
SCALE = np.array([2.0, 3.0])


def test_absolute_errors_and_mse_match_hand_computed_values():
    np.testing.assert_array_equal(absolute_errors(PREDICTION, TARGET), [[1, 0], [2, 3]])
    # (1 + 4) / 2 and (0 + 9) / 2
    np.testing.assert_array_equal(mse(PREDICTION, TARGET), [2.5, 4.5])
    np.testing.assert_allclose(rmse(PREDICTION, TARGET), [np.sqrt(2.5), np.sqrt(4.5)], rtol=1e-15)


def test_normalised_errors_divide_by_the_half_range_per_joint():
    np.testing.assert_allclose(
        normalised_rmse(PREDICTION, TARGET, SCALE), [np.sqrt(2.5) / 2, np.sqrt(4.5) / 3]
    )
    # 2.5 / 2**2 and 4.5 / 3**2
    np.testing.assert_allclose(normalised_mse(PREDICTION, TARGET, SCALE), [0.625, 0.5])


def test_nmse_divides_by_the_target_variance():
    # Both target columns have variance 0.25: 2.5 / 0.25 and 4.5 / 0.25.
    np.testing.assert_allclose(nmse(PREDICTION, TARGET), [10.0, 18.0])


def test_nmse_of_a_constant_target_is_zero_when_met_and_infinite_when_missed():
    target = np.array([[1.0, 2.0], [1.0, 2.0]])
    prediction = np.array([[1.0, 2.5], [1.0, 2.5]])
    np.testing.assert_array_equal(nmse(prediction, target), [0.0, np.inf])


def test_error_metrics_collects_every_metric_and_the_means():
    metrics = error_metrics(PREDICTION, TARGET, SCALE).to_dict()
    assert metrics['n_samples'] == 2
    np.testing.assert_array_equal(metrics['max_abs_nm'], [2.0, 3.0])
    np.testing.assert_allclose(metrics['mse_normalised'], [0.625, 0.5])
    assert metrics['mean_mse_normalised'] == pytest.approx(0.5625)
    assert metrics['mean_nmse'] == pytest.approx(14.0)
    assert metrics['mean_rmse_normalised'] == pytest.approx((np.sqrt(2.5) / 2 + 1 / 2**0.5) / 2)


def test_metrics_refuse_mismatched_shapes_empty_data_and_non_positive_scales():
    with pytest.raises(ValueError, match=r'must both be \(N, n\)'):
        rmse(PREDICTION, TARGET[:, :1])
    with pytest.raises(ValueError, match='no samples'):
        rmse(np.empty((0, 2)), np.empty((0, 2)))
    with pytest.raises(ValueError, match='scale must be > 0'):
        normalised_rmse(PREDICTION, TARGET, np.array([1.0, 0.0]))


finite = st.floats(-1e3, 1e3, allow_nan=False)


@given(
    target=arrays(np.float64, (7, 3), elements=finite),
    offset=arrays(np.float64, (3,), elements=finite),
)
def test_a_constant_offset_gives_its_magnitude_as_rmse(target, offset):
    np.testing.assert_allclose(rmse(target + offset, target), np.abs(offset), atol=1e-9)


@given(
    prediction=arrays(np.float64, (5, 2), elements=finite),
    target=arrays(np.float64, (5, 2), elements=finite),
    scale=arrays(np.float64, (2,), elements=st.floats(1e-3, 1e3)),
)
def test_normalised_and_physical_errors_agree_through_the_scale(prediction, target, scale):
    np.testing.assert_allclose(
        normalised_rmse(prediction, target, scale) * scale, rmse(prediction, target), rtol=1e-12
    )
    np.testing.assert_allclose(
        normalised_mse(prediction, target, scale), normalised_rmse(prediction, target, scale) ** 2
    )
