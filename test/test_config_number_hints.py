"""A config number written as text is a type error, said as one, whatever the text.

'8ms' (a number with its unit), '0.008' (a quoted number) and 'fast' are no numbers: the message
says so and how to write it, never only that the value is out of range.
"""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.config_io import finite_number, load_yaml_mapping, number_hint
from id_learning.errors import ConfigError
from id_learning.robot.config import robot_config_from_dict

CONFIG = Path(__file__).resolve().parents[1] / 'config'
UNITS = ['ms', 's', ' s', 'Hz', ' rad/s', 'deg', '%', 'A']


@given(number=st.floats(-1e6, 1e6, allow_nan=False), unit=st.sampled_from(UNITS))
def test_a_number_with_a_unit_is_named_as_one(number: float, unit: str) -> None:
    with pytest.raises(ConfigError) as err:
        finite_number(f'{number:g}{unit}', 'f.yaml: k', low=-1e7, high=1e7)
    text = str(err.value)
    assert text.startswith('f.yaml: k: must be a finite number in [-10000000, 10000000], not a ')
    assert 'a number with a unit is text, not a number' in text


@given(number=st.floats(-1e6, 1e6, allow_nan=False))
def test_a_quoted_number_is_told_to_lose_its_quotes(number: float) -> None:
    assert number_hint(repr(number)) == f'; write the number without quotes: {number!r}'
    assert number_hint(number) == ''


@pytest.mark.parametrize(
    ('value', 'hint'),
    [
        ('8ms', 'a number with a unit is text, not a number: write the bare number in s'),
        ('0.008', 'write the number without quotes: 0.008'),
        ('fast', "got 'fast'"),
    ],
)
def test_ipo_period_as_text_is_a_type_error(value: str, hint: str) -> None:
    data = copy.deepcopy(load_yaml_mapping(CONFIG / 'mabi_max100.yaml'))
    data['ipo_period_s'] = value
    with pytest.raises(ConfigError, match=r'yaml: ipo_period_s must be in .* a number') as err:
        robot_config_from_dict(data, CONFIG, 'robot.yaml')
    assert 'not a string' in str(err.value)
    assert hint in str(err.value)
    data['ipo_period_s'] = True  # a bool is no number either, and said so
    with pytest.raises(ConfigError, match=r'ipo_period_s .* a number, not a bool: got True'):
        robot_config_from_dict(data, CONFIG, 'robot.yaml')
    data['ipo_period_s'] = 2.0  # a number out of range keeps its range message
    with pytest.raises(ConfigError, match=r'ipo_period_s must be in \[1e-5, 1\] s, got 2.0'):
        robot_config_from_dict(data, CONFIG, 'robot.yaml')
