"""How long the twin simulates: a stated maximum, the memory, and finite excitation numbers."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st
from support import REPO, twin_config

from id_learning.errors import ConfigError
from id_learning.twin import load_twin_config, simulate
from id_learning.twin.bounds import (
    BYTES_PER_SAMPLE_JOINT,
    MAX_DURATION_S,
    MEMORY_SHARE,
    check_duration,
)

PERIOD_S, JOINTS = 0.008, 6
GIB = 2**30


@pytest.mark.parametrize('duration', [1e9, float('inf'), float('nan'), 0.0, -1.0, '600'])
def test_a_duration_beyond_a_day_or_not_a_positive_number_is_refused(duration: object):
    with pytest.raises(ConfigError, match=r'--duration: must be a finite number in \(0, 86400\]'):
        check_duration(duration, PERIOD_S, JOINTS, '--duration', available=1024 * GIB)


@given(st.floats(min_value=1.0, max_value=MAX_DURATION_S))
def test_a_duration_is_refused_exactly_when_it_needs_more_than_the_memory_share(duration: float):
    available = 8 * GIB
    need = (duration / PERIOD_S + 1) * JOINTS * BYTES_PER_SAMPLE_JOINT
    if need > MEMORY_SHARE * available:
        with pytest.raises(ConfigError, match=r'GiB of memory available: at most \d+ s fit'):
            check_duration(duration, PERIOD_S, JOINTS, 'excitation.duration_s', available)
    else:
        assert check_duration(duration, PERIOD_S, JOINTS, 'x', available) == duration


def test_the_bound_named_in_the_refusal_is_accepted():
    available = 2 * GIB
    with pytest.raises(ConfigError) as err:
        check_duration(MAX_DURATION_S, PERIOD_S, JOINTS, '--duration', available)
    fits = float(str(err.value).split('at most ')[1].split(' s fit')[0])
    assert 0 < fits < MAX_DURATION_S
    assert check_duration(fits, PERIOD_S, JOINTS, '--duration', available) == fits


def _twin_file(tmp_path: Path, **excitation: object) -> Path:
    data = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text())
    data['robot'] = str(REPO / 'config/mabi_max100.yaml')
    data['excitation'].update(excitation)
    path = tmp_path / 'twin.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ('key', 'value', 'message'),
    [
        (
            'duration_s',
            float('inf'),
            r'excitation.duration_s: must be a finite number in \(0, 86400\]',
        ),
        ('harmonics', 2.5, r'excitation.harmonics: must be an integer in \[1, 10\], got 2.5'),
        ('rest_s', float('nan'), r'excitation.rest_s: must be a finite number in \[0, 86400\]'),
        ('base_frequency_hz', float('inf'), 'excitation.base_frequency_hz: must be a finite'),
    ],
)
def test_an_excitation_number_that_is_no_finite_number_in_range_is_refused_naming_the_file(
    tmp_path: Path, key: str, value: object, message: str
):
    path = _twin_file(tmp_path, **{key: value})
    with pytest.raises(ConfigError, match=message) as err:
        load_twin_config(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    ('key', 'value'), [('shift_start_s', float('nan')), ('start_time_ns', 2**64)]
)
def test_a_twin_number_beyond_its_range_is_refused(tmp_path: Path, key: str, value: object):
    with pytest.raises(ConfigError, match=key):
        load_twin_config(_twin_file(tmp_path), {key: value})


def test_simulate_refuses_a_duration_set_in_code_before_any_work():
    config = twin_config(10.0)
    huge = replace(config, excitation=replace(config.excitation, duration_s=1e9))
    with pytest.raises(ConfigError, match=r'excitation.duration_s: .*\(0, 86400\]'):
        simulate(huge)
