"""The study's preprocessing against analytic derivatives of a Fourier excitation, known cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from support import sine_recording

from id_learning.dataset.preprocess import (
    MinMaxScaler,
    PreprocessConfig,
    differentiate,
    lowpass,
    prepare_dataset,
    regularise,
)
from id_learning.dataset.recording import Recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.record.excitation import ExcitationConfig, design_excitation


@pytest.fixture(scope='module')
def fourier(mabi):
    """Four periods of one Fourier segment: smooth and periodic, with exact derivatives."""
    trajectory = design_excitation(
        ExcitationConfig(duration_s=30.0),
        mabi.limits,
        mabi.ipo_period_s,
        np.random.default_rng(11),
    )
    segment = trajectory.segments[0]
    t = np.arange(0.0, 4 * trajectory.period_s, mabi.ipo_period_s)
    return segment.evaluate(t)


def interior(x: np.ndarray) -> np.ndarray:
    """Drop the first and last quarter, where the filter's edge padding acts."""
    quarter = len(x) // 4
    return x[quarter:-quarter]


def test_filtering_keeps_the_excitation_and_differentiation_matches_analytic_derivatives(
    mabi, fourier
):
    q, v, a = fourier
    period = mabi.ipo_period_s
    v_filtered = lowpass(v, mabi.lowpass_cutoff_hz, period)
    # Harmonics up to 0.12 Hz lie well below the lowest 0.3 Hz cut-off: the gain there is
    # 1 / (1 + (0.12 / 0.3)^8) for a 4th-order Butterworth run forward and backward.
    assert np.max(np.abs(interior(v_filtered - v))) < 1e-3 * np.max(np.abs(v))
    a_estimate = differentiate(v_filtered, period)
    assert np.max(np.abs(interior(a_estimate - a))) < 2e-3 * np.max(np.abs(a))
    np.testing.assert_allclose(differentiate(q, period), v, atol=1e-4 * np.max(np.abs(v)))


def test_the_low_pass_removes_white_noise_in_proportion_to_its_bandwidth(mabi):
    rng = np.random.default_rng(5)
    noise = rng.standard_normal((200_000, mabi.n_joints))
    remaining = np.std(interior(lowpass(noise, mabi.lowpass_cutoff_hz, mabi.ipo_period_s)), axis=0)
    # Forward-backward Butterworth of order 4: power gain (1 + (f/fc)^8)^-2, whose integral over
    # f >= 0 is fc * (1 - 1/8) * pi / (8 sin(pi/8)).
    bandwidth = mabi.lowpass_cutoff_hz * (7 / 8) * np.pi / (8 * np.sin(np.pi / 8))
    expected = np.sqrt(bandwidth / (0.5 / mabi.ipo_period_s))
    np.testing.assert_allclose(remaining, expected, rtol=0.1)


def test_prepared_dataset_is_split_in_time_and_normalised_on_the_training_part(short_twin, mabi):
    _, result = short_twin
    dataset = prepare_dataset(result.recording, mabi)
    n = len(dataset.q)
    assert dataset.n_train == round(0.7 * n)
    assert dataset.train.stamps_ns[-1] < dataset.test.stamps_ns[0]
    assert len(dataset.train.q) + len(dataset.test.q) == n
    z = dataset.input_scaler.transform(dataset.train.inputs)
    np.testing.assert_allclose(z.min(axis=0), -1.0, atol=1e-12)
    np.testing.assert_allclose(z.max(axis=0), 1.0, atol=1e-12)
    y = dataset.target_scaler.transform(dataset.train.tau)
    np.testing.assert_allclose(
        dataset.target_scaler.inverse_transform(y), dataset.train.tau, rtol=1e-12
    )
    tau_u = result.recording.current * mabi.drives.gear_ratio * mabi.drives.torque_constant
    np.testing.assert_allclose(dataset.tau_raw, tau_u, rtol=1e-12)


def test_a_shuffled_split_draws_training_samples_at_random_and_keeps_time_whole(short_twin, mabi):
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.models.data import TrainingData

    _, result = short_twin
    contiguous = prepare_dataset(result.recording, mabi)
    shuffled = prepare_dataset(result.recording, mabi, PreprocessConfig(split='shuffled'))
    again = prepare_dataset(result.recording, mabi, PreprocessConfig(split='shuffled'))
    other = prepare_dataset(
        result.recording, mabi, PreprocessConfig(split='shuffled', split_seed=1)
    )
    n = len(shuffled.q)
    assert shuffled.is_shuffled
    assert not contiguous.is_shuffled
    assert shuffled.n_train == contiguous.n_train == int(shuffled.train_mask.sum())
    np.testing.assert_array_equal(shuffled.train_mask, again.train_mask)  # seeded
    assert not np.array_equal(shuffled.train_mask, other.train_mask)
    train, test = shuffled.train_rows, shuffled.test_rows
    assert len(np.intersect1d(train, test)) == 0
    assert len(train) + len(test) == n
    assert train.min() < n // 10  # spread over the whole run
    assert test.max() > n - n // 10
    # The recording stays whole in time (filters run along it); the arrays are the same.
    np.testing.assert_array_equal(shuffled.tau, contiguous.tau)
    (rows,) = shuffled.recording_rows()
    np.testing.assert_array_equal(rows, np.arange(n))
    # Scalers from the training samples only.
    z = shuffled.input_scaler.transform(shuffled.train.inputs)
    np.testing.assert_allclose(z.min(axis=0), -1.0, atol=1e-12)
    np.testing.assert_allclose(z.max(axis=0), 1.0, atol=1e-12)
    # Validation samples drawn from the training ones; no test sample is fitted on.
    data = TrainingData(shuffled, mabi)
    fit, validation = data.fit_rows, data.validation_rows
    assert len(np.intersect1d(fit, validation)) == 0
    np.testing.assert_array_equal(np.union1d(fit, validation), train)
    assert len(fit) == data.n_fit


def test_an_unknown_split_is_refused():
    from id_learning.dataset.preprocess import PreprocessConfig

    with pytest.raises(ConfigError, match='split must be one of'):
        PreprocessConfig(split='random')


def test_the_joint_target_needs_measured_joint_torques(short_twin, mabi):
    _, result = short_twin
    needs = r"carries no effort .*, which the 'joint' target needs"
    with pytest.raises(DatasetError, match=needs):
        prepare_dataset(result.recording, mabi, PreprocessConfig(target='joint'))


def test_a_recording_too_short_for_the_filter_is_refused(mabi):
    recording = sine_recording(500)  # 4 s, but the 0.3 Hz cut-off needs 6.7 s
    with pytest.raises(DatasetError, match=r'too short for the filter.*0.3 Hz cut-off of joint_2'):
        prepare_dataset(recording, mabi)


def test_jittered_stamps_are_snapped_and_missing_samples_are_interpolated_and_reported(mabi):
    recording = sine_recording(2000)
    rng = np.random.default_rng(1)
    jitter = rng.integers(-1_000_000, 1_000_000, recording.n_samples)  # +-1 ms of 8 ms
    jitter[0] = 0
    keep = np.ones(recording.n_samples, bool)
    keep[[500, 1200, 1201]] = False
    jittered = Recording(
        recording.joints,
        (recording.stamps_ns + jitter)[keep],
        recording.position[keep],
        recording.velocity[keep],
        recording.current[keep],
        source='jittered',
    )
    regular, report = regularise(jittered, mabi.ipo_period_s)
    assert report.filled_samples == (500, 1200, 1201)
    assert report.n_snapped > 1900
    assert report.max_jitter_s <= 1e-3
    np.testing.assert_array_equal(regular.stamps_ns, recording.stamps_ns)
    np.testing.assert_array_equal(regular.position[keep], recording.position[keep])
    assert np.max(np.abs(regular.position[500] - recording.position[500])) < 1e-4


def test_stamps_far_off_the_ipo_grid_are_refused(mabi):
    recording = sine_recording(200)
    stamps = recording.stamps_ns.copy()
    stamps[50] += 3_000_000  # 3 ms of an 8 ms period
    off = Recording(
        recording.joints,
        stamps,
        recording.position,
        recording.velocity,
        recording.current,
        source='off-grid',
    )
    with pytest.raises(DatasetError, match=r'off-grid: sample 50 .* off the 8 ms IPO grid'):
        regularise(off, mabi.ipo_period_s)


def test_preprocess_config_rejects_bad_values():
    with pytest.raises(ConfigError, match='target'):
        PreprocessConfig(target='current')  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match='train_fraction'):
        PreprocessConfig(train_fraction=1.0)


@given(arrays(np.float64, (20, 3), elements=st.floats(-1e4, 1e4)))
def test_min_max_scaler_round_trips_and_survives_serialisation(x):
    scaler = MinMaxScaler().fit(x)
    restored = MinMaxScaler.from_dict(scaler.to_dict())
    z = restored.transform(x)
    assert np.all(z >= -1 - 1e-9)
    assert np.all(z <= 1 + 1e-9)
    np.testing.assert_allclose(restored.inverse_transform(z), x, rtol=1e-9, atol=1e-6)
