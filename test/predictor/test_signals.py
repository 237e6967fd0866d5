"""The predictor's signal helpers: causal acceleration, the replay's reference, rolling stats."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from id_learning.dataset.inputs import InputDefinition
from id_learning.errors import DatasetError
from id_learning.predictor import (
    CausalAccelerationEstimator,
    RollingStats,
    causal_acceleration,
    reference_from_states,
)

PERIOD_NS = 8_000_000


def test_backward_difference_recovers_a_constant_acceleration_exactly():
    stamps = np.arange(20) * PERIOD_NS + 123
    a_true = np.array([0.5, -2.0, 3.0])
    v = 0.1 + (stamps[:, None] * 1e-9) * a_true
    a = causal_acceleration(stamps, v)
    np.testing.assert_array_equal(a[0], 0.0)  # no history yet
    np.testing.assert_allclose(a[1:], np.broadcast_to(a_true, (19, 3)), rtol=1e-9)


def test_the_low_pass_estimate_converges_to_a_constant_acceleration():
    stamps = np.arange(400) * PERIOD_NS
    v = (stamps[:, None] * 1e-9) * np.array([2.0])
    a = causal_acceleration(stamps, v, cutoff_hz=5.0)
    # First-order lag: after 3.2 s (100 time constants) the estimate has settled.
    assert a[-1, 0] == pytest.approx(2.0, rel=1e-6)
    # and it rises monotonically without overshoot, as a first-order filter must.
    assert np.all(np.diff(a[1:, 0]) >= -1e-12)
    assert a[1:, 0].max() <= 2.0 + 1e-9


@given(
    steps=arrays(np.int64, st.integers(2, 30), elements=st.integers(1_000_000, 20_000_000)),
    cutoff=st.sampled_from([0.0, 1.0, 30.0]),
)
def test_the_online_estimator_equals_the_batch_function(steps, cutoff):
    stamps = np.cumsum(steps)
    rng = np.random.default_rng(len(steps))
    v = rng.normal(size=(len(stamps), 2))
    estimator = CausalAccelerationEstimator(cutoff)
    online = np.array([estimator.update(int(t), row) for t, row in zip(stamps, v, strict=True)])
    np.testing.assert_array_equal(online, causal_acceleration(stamps, v, cutoff))


def test_reset_starts_the_estimate_from_zero_again():
    estimator = CausalAccelerationEstimator()
    estimator.update(0, np.array([0.0]))
    assert estimator.update(PERIOD_NS, np.array([1.0]))[0] == pytest.approx(125.0)
    estimator.reset()
    assert estimator.update(2 * PERIOD_NS, np.array([5.0]))[0] == 0.0


def test_reference_accelerations_are_exact_for_a_quadratic_trajectory():
    # Non-uniform stamps: central differences of a linear v over the stamps are exact.
    stamps = np.cumsum(np.r_[0, np.full(30, PERIOD_NS) + np.arange(30) * 1000]) + 10**18
    t = (stamps - stamps[0]) * 1e-9
    q = np.stack([0.5 * 1.5 * t**2, -t], axis=1)
    v = np.stack([1.5 * t, -np.ones_like(t)], axis=1)
    reference = reference_from_states(('a', 'b'), stamps, q, v, period_s=0.008)
    np.testing.assert_allclose(reference.a[:, 0], 1.5, rtol=1e-9)
    np.testing.assert_allclose(reference.a[:, 1], 0.0, atol=1e-9)
    np.testing.assert_array_equal(reference.q, q)  # no filter asked for
    assert reference.joints == ('a', 'b')


def test_the_reference_low_pass_removes_noise_but_keeps_a_slow_motion():
    stamps = np.arange(2000) * PERIOD_NS
    t = stamps * 1e-9
    rng = np.random.default_rng(0)
    v_true = np.sin(2 * np.pi * 0.1 * t)[:, None]
    v = v_true + rng.normal(scale=0.01, size=v_true.shape)
    q = np.zeros_like(v)
    raw = reference_from_states(('j',), stamps, q, v, period_s=0.008)
    smooth = reference_from_states(
        ('j',), stamps, q, v, period_s=0.008, inputs=InputDefinition.study(np.array([1.0]))
    )
    a_true = 2 * np.pi * 0.1 * np.cos(2 * np.pi * 0.1 * t)
    inner = slice(200, -200)
    error_raw = np.std(raw.a[inner, 0] - a_true[inner])
    error_smooth = np.std(smooth.a[inner, 0] - a_true[inner])
    assert error_smooth < 0.05 * error_raw


def test_a_controller_reference_keeps_recorded_positions_and_smooths_velocities_only():
    stamps = np.arange(2000) * PERIOD_NS
    t = stamps * 1e-9
    rng = np.random.default_rng(1)
    v_true = np.sin(2 * np.pi * 0.1 * t)[:, None]
    v = v_true + rng.normal(scale=0.01, size=v_true.shape)
    q = rng.normal(size=v.shape)  # any positions: they must come through untouched
    inputs = InputDefinition.controller(np.array([10.0]))
    reference = reference_from_states(('j',), stamps, q, v, period_s=0.008, inputs=inputs)
    motion = inputs.motion(q, v, 0.008)

    np.testing.assert_array_equal(reference.q, q)
    np.testing.assert_allclose(reference.v, motion.v, rtol=0, atol=1e-15)
    np.testing.assert_allclose(reference.a, motion.a, rtol=1e-9, atol=1e-9)
    # 10 Hz keeps the 0.1 Hz motion (a low-pass at the labels' 0.3 Hz would not)
    inner = slice(200, -200)
    assert np.max(np.abs(reference.v[inner] - v_true[inner])) < 0.02


def test_reference_refuses_too_few_or_unordered_samples():
    with pytest.raises(DatasetError, match='at least 3'):
        reference_from_states(
            ('j',), np.arange(2), np.zeros((2, 1)), np.zeros((2, 1)), period_s=0.008
        )
    with pytest.raises(DatasetError, match='increase'):
        reference_from_states(
            ('j',), np.array([0, 2, 1]), np.zeros((3, 1)), np.zeros((3, 1)), period_s=0.008
        )


def test_rolling_stats_keep_the_last_values_and_count_all():
    stats = RollingStats(capacity=4)
    assert stats.summary().count == 0
    for value in [100.0, 1.0, 2.0, 3.0, 4.0]:
        stats.add(value)
    np.testing.assert_array_equal(stats.values(), [1.0, 2.0, 3.0, 4.0])
    summary = stats.summary()
    assert stats.total == 5
    assert summary.count == 4
    assert summary.median == 2.5
    assert summary.max == 4.0
    assert summary.p99 == pytest.approx(3.97)
    with pytest.raises(ValueError, match='capacity'):
        RollingStats(0)
