"""A quoted number or a bool where a config wants a number is refused, naming file, key, value."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

from id_learning.config_io import float_vector, load_yaml_mapping
from id_learning.errors import ConfigError
from id_learning.robot.config import robot_config_from_dict
from id_learning.twin.simulate import twin_config_from_dict

CONFIG = Path(__file__).resolve().parents[1] / 'config'


@pytest.mark.parametrize('value', ['420', ['420'] * 6, [1.0, 2.0, '3', 4.0, 5.0, 6.0], True,
                                   [True, 1, 1, 1, 1, 1]])  # fmt: skip
def test_float_vector_refuses_words(value: object) -> None:
    with pytest.raises(ConfigError, match=r'f\.yaml: k: expected numbers'):
        float_vector(value, 'f.yaml: k', 6)


def test_float_vector_hints_quotes_and_keeps_numbers() -> None:
    with pytest.raises(ConfigError, match="got '1e-3'; write the number without quotes: 1e-3"):
        float_vector('1e-3', 'f.yaml: k', 2)
    assert float_vector([1, 2.5], 'k', 2).tolist() == [1.0, 2.5]


def test_yaml_reads_exponent_as_number() -> None:
    from id_learning.config_io import parse_yaml

    assert parse_yaml('x: 1e-3', 'f.yaml') == {'x': 0.001}


@pytest.mark.parametrize('value', ['420', ['420'] * 6])
def test_twin_coefficient_string(value: object) -> None:
    data = load_yaml_mapping(CONFIG / 'twin_default.yaml')
    data['effects']['viscous_friction']['coefficient'] = value
    with pytest.raises(
        ConfigError, match=r"twin\.yaml: effects\.viscous_friction\.coefficient.*'420'"
    ):
        twin_config_from_dict(data, CONFIG, 'twin.yaml')


@pytest.mark.parametrize(
    ('key', 'value'),
    [('gear_ratio', '205'), ('input_smoothing_hz', '10'), ('ipo_period_s', True)],
)
def test_robot_number_strings(key: str, value: object) -> None:
    data = copy.deepcopy(load_yaml_mapping(CONFIG / 'mabi_max100.yaml'))
    (data['drives'] if key == 'gear_ratio' else data)[key] = value
    with pytest.raises(ConfigError, match=rf'robot\.yaml: (drives\.)?{key}.*{value!r}'):
        robot_config_from_dict(data, CONFIG, 'robot.yaml')
