"""Preprocessing settings: finite cut-offs below the Nyquist frequency of the IPO period."""

from __future__ import annotations

import pytest
from support import sine_recording

from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
from id_learning.errors import ConfigError


@pytest.mark.parametrize(
    ('settings', 'match'),
    [
        (
            {'cutoff_hz': (1.0, float('nan'))},
            r'cutoff_hz\[1\] \[Hz\]: must be a finite number > 0',
        ),
        ({'input_smoothing_hz': (float('inf'),)}, r'input_smoothing_hz\[0\]'),
        ({'cutoff_hz': (0.0,)}, r'cutoff_hz\[0\]'),
        ({'min_filter_periods': float('nan')}, 'min_filter_periods'),
        ({'min_filter_periods': 0.0}, 'min_filter_periods'),
    ],
)
def test_a_cut_off_or_filter_length_that_is_no_positive_finite_number_is_refused(
    settings: dict, match: str
):
    with pytest.raises(ConfigError, match=match):
        PreprocessConfig(**settings)


@pytest.mark.parametrize(
    ('key', 'value'), [('cutoff_hz', 62.5), ('cutoff_hz', 80.0), ('input_smoothing_hz', 63.0)]
)
def test_a_cut_off_at_or_above_nyquist_is_refused_naming_it_and_the_period(mabi, key, value):
    recording = sine_recording()
    with pytest.raises(ConfigError) as err:
        prepare_dataset(recording, mabi, PreprocessConfig(**{key: (value,) * 6}))
    text = str(err.value)
    for word in (key, f'{value:g} Hz', 'joint_1', 'Nyquist frequency 62.5 Hz', '8 ms IPO period'):
        assert word in text


def test_a_cut_off_just_below_nyquist_passes_the_check(mabi):
    recording = sine_recording()
    dataset = prepare_dataset(recording, mabi, PreprocessConfig(input_smoothing_hz=(62.0,) * 6))
    assert dataset.tau.shape[0] == recording.n_samples
