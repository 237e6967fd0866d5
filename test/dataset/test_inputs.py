"""Model inputs, a controller's (the default) and the study's; the label filter per recording."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal
from support import sine_recording

from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
from id_learning.dataset.signals import differentiate, lowpass, time_shifted
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.training import combine_datasets


def zero_phase(x: np.ndarray, cutoff_hz: np.ndarray, period_s: float) -> np.ndarray:
    """An independent reference: scipy's own design and sosfiltfilt, column by column."""
    out = np.empty_like(x)
    for j in range(x.shape[1]):
        sos = signal.butter(4, cutoff_hz[j], fs=1 / period_s, output='sos')
        out[:, j] = signal.sosfiltfilt(sos, x[:, j])
    return out


def test_controller_inputs_keep_recorded_positions_and_smooth_only_velocities(short_twin, mabi):
    _, result = short_twin
    recording = result.recording
    dataset = prepare_dataset(recording, mabi)

    assert dataset.mode == 'through_filter'
    assert dataset.controller_inputs.name == 'controller'
    np.testing.assert_array_equal(dataset.q, recording.position)
    v = zero_phase(recording.velocity, mabi.input_smoothing_hz, mabi.ipo_period_s)
    np.testing.assert_allclose(dataset.v, v, rtol=0, atol=1e-12)
    a = np.gradient(v, mabi.ipo_period_s, axis=0, edge_order=2)
    np.testing.assert_allclose(dataset.a, a, rtol=0, atol=1e-9)
    # The fitting inputs are the controller's, and the study's are kept beside them.
    assert dataset.controller.q is dataset.q
    assert dataset.fitting_inputs == dataset.controller_inputs


def test_controller_inputs_keep_motion_faster_than_the_label_filter_the_study_removes(mabi):
    # A 2 Hz motion on every joint: well inside a controller's band, far above 0.3-1.2 Hz.
    recording = sine_recording(5000)
    t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    omega = 2 * np.pi * 2.0
    position = 0.01 * np.sin(omega * t)[:, None] * np.ones(6)
    velocity = 0.01 * omega * np.cos(omega * t)[:, None] * np.ones(6)
    recording = replace(recording, position=position, velocity=velocity)

    dataset = prepare_dataset(recording, mabi)

    inner = slice(1000, -1000)
    amplitude = 0.01 * omega
    controller = np.max(np.abs(dataset.controller.v[inner]), axis=0)
    study = np.max(np.abs(dataset.study.v[inner]), axis=0)
    np.testing.assert_allclose(controller, amplitude, rtol=0.01)
    assert (study < 0.1 * amplitude).all(), study


def test_study_mode_fits_on_inputs_low_passed_like_the_labels(short_twin, mabi):
    _, result = short_twin
    recording = result.recording
    dataset = prepare_dataset(recording, mabi, PreprocessConfig(mode='study'))

    period = mabi.ipo_period_s
    q = zero_phase(recording.position, mabi.lowpass_cutoff_hz, period)
    v = zero_phase(recording.velocity, mabi.lowpass_cutoff_hz, period)
    np.testing.assert_allclose(dataset.q, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dataset.v, v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dataset.a, differentiate(v, period), rtol=0, atol=1e-9)
    assert dataset.study.q is dataset.q
    assert dataset.fitting_inputs.name == 'study'
    # The labels and the controller inputs do not depend on the mode.
    default = prepare_dataset(recording, mabi)
    np.testing.assert_array_equal(dataset.tau, default.tau)
    np.testing.assert_array_equal(dataset.controller.v, default.controller.v)


def test_a_stored_input_definition_overrides_the_robot_configs_smoothing(short_twin, mabi):
    _, result = short_twin
    config = PreprocessConfig(input_smoothing_hz=(4.0,) * 6)
    dataset = prepare_dataset(result.recording, mabi, config)
    assert dataset.controller_inputs.velocity_cutoff_hz == (4.0,) * 6
    with pytest.raises(ConfigError, match='input_smoothing_hz needs 6 values'):
        prepare_dataset(result.recording, mabi, PreprocessConfig(input_smoothing_hz=(4.0,)))


def test_an_unknown_preprocessing_mode_is_refused():
    with pytest.raises(ConfigError, match="mode must be one of \\('through_filter', 'study'\\)"):
        PreprocessConfig(mode='filtered')  # type: ignore[arg-type]


def test_input_definitions_survive_json_and_refuse_a_malformed_one():
    for definition in (
        InputDefinition.controller(np.array([10.0, 8.0])),
        InputDefinition.study(np.array([0.3, 1.2]), filter_order=2),
    ):
        assert InputDefinition.from_dict(definition.to_dict()) == definition
    with pytest.raises(CheckpointError, match='velocity_cutoff_hz'):
        InputDefinition.from_dict({'name': 'controller', 'filter_order': 4})


def test_the_label_filter_runs_on_each_recording_of_a_combined_dataset_alone(short_twin, mabi):
    _, result = short_twin
    first = prepare_dataset(result.recording, mabi)
    second = replace(first, source='second')
    combined = combine_datasets([first, second])
    rng = np.random.default_rng(3)
    x = {name: rng.normal(size=first.tau.shape) for name in ('first', 'second')}
    # Rows of the combined dataset: both training parts, then both test parts.
    n, m = first.n_train, len(first.tau)
    stacked = np.concatenate([x['first'][:n], x['second'][:n], x['first'][n:], x['second'][n:]])

    filtered = combined.filter_like_labels(stacked)

    period, cutoff = mabi.ipo_period_s, first.cutoff_hz
    expected = {name: lowpass(value, cutoff, period) for name, value in x.items()}
    np.testing.assert_allclose(filtered[:n], expected['first'][:n], atol=1e-12)
    np.testing.assert_allclose(filtered[n : 2 * n], expected['second'][:n], atol=1e-12)
    np.testing.assert_allclose(filtered[2 * n : n + m], expected['first'][n:], atol=1e-12)
    np.testing.assert_allclose(filtered[n + m :], expected['second'][n:], atol=1e-12)


def test_a_sampled_signal_shifts_by_a_fraction_of_a_sample():
    period, delay = 0.008, 0.027  # 3.375 samples
    t = np.arange(2000) * period
    x = np.stack([np.sin(2 * np.pi * 1.1 * t), np.cos(2 * np.pi * 0.3 * t + 1.0)], axis=1)
    shifted = time_shifted(x, delay, period)
    expected = np.stack(
        [np.sin(2 * np.pi * 1.1 * (t - delay)), np.cos(2 * np.pi * 0.3 * (t - delay) + 1.0)],
        axis=1,
    )
    np.testing.assert_allclose(shifted[10:], expected[10:], atol=1e-6)
    with pytest.raises(DatasetError, match='too few'):
        time_shifted(x[:3], delay, period)
