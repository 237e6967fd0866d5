"""Values checked where they enter: YAML without duplicate keys, finite numbers in range, topic
names, and the command-line options that take numbers."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.cli import options
from id_learning.cli.main import build_parser
from id_learning.config_io import (
    finite_number,
    load_yaml_mapping,
    parse_yaml,
    range_problem,
    topic_name_problem,
)
from id_learning.errors import ConfigError

# -- YAML -----------------------------------------------------------------------------------------


def test_a_key_given_twice_is_refused_naming_the_file_the_key_and_both_lines(tmp_path: Path):
    path = tmp_path / 'robot.yaml'
    path.write_text('name: arm\nipo_period_s: 0.008\njoints: [a]\nipo_period_s: 0.004\n')
    with pytest.raises(ConfigError, match=r"duplicate key 'ipo_period_s' at lines 2 and 4") as err:
        load_yaml_mapping(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    ('text', 'key', 'lines'),
    [
        (
            'drives:\n  gear_ratio: 1\n  torque_constant: 2\n  gear_ratio: 3\n',
            'gear_ratio',
            '2 and 4',
        ),
        ('joints:\n  - name: j\n    position: 1\n    position: 2\n', 'position', '3 and 4'),
        ('limits: {velocity: 1, velocity: 2}\n', 'velocity', '1 and 1'),
    ],
    ids=['nested', 'in-a-list', 'flow-mapping'],
)
def test_a_duplicate_key_is_found_at_any_depth(text: str, key: str, lines: str):
    with pytest.raises(ConfigError, match=rf"duplicate key '{key}' at lines {lines}"):
        parse_yaml(text, 'config.yaml')


def test_keys_given_once_and_yaml_merge_keys_are_read_as_before():
    text = 'base: &b {gear_ratio: 1, torque_constant: 2}\njoint: {<<: *b, gear_ratio: 3}\n'
    assert parse_yaml(text, 'x') == {
        'base': {'gear_ratio': 1, 'torque_constant': 2},
        'joint': {'gear_ratio': 3, 'torque_constant': 2},
    }
    assert parse_yaml('a: 1\nb: {a: 2}\n', 'x') == {'a': 1, 'b': {'a': 2}}


def test_invalid_and_non_mapping_yaml_is_refused_naming_the_file(tmp_path: Path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: [unclosed\n')
    with pytest.raises(ConfigError, match=r'broken\.yaml: not valid YAML'):
        load_yaml_mapping(broken)
    listing = tmp_path / 'list.yaml'
    listing.write_text('- a\n- b\n')
    with pytest.raises(ConfigError, match=r'list\.yaml: expected a mapping'):
        load_yaml_mapping(listing)


# -- numbers --------------------------------------------------------------------------------------
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_a_number_is_accepted_exactly_when_finite_and_in_range(value: float):
    inside = math.isfinite(value) and 0.0 < value <= 10.0
    problem = range_problem(value, low=0.0, high=10.0, low_open=True)
    assert (problem is None) == inside
    if not inside:
        with pytest.raises(ConfigError, match=r'key: must be a finite number in \(0, 10\], got'):
            finite_number(value, 'key', low=0.0, high=10.0, low_open=True)
    else:
        assert finite_number(value, 'key', low=0.0, high=10.0, low_open=True) == value


@given(st.integers(min_value=-(10**30), max_value=10**30))
def test_an_integer_range_compares_exactly_even_beyond_the_float_range(value: int):
    accepted = range_problem(value, low=0, high=2**62, integer=True) is None
    assert accepted == (0 <= value <= 2**62)


@pytest.mark.parametrize('value', [True, '1.0', None, [1.0], 10**400])
def test_no_bool_string_list_or_overflowing_integer_passes_as_a_finite_float(value: object):
    with pytest.raises(ConfigError, match='key: '):
        finite_number(value, 'key')


def test_an_integer_range_refuses_a_float_and_names_the_range_in_full():
    with pytest.raises(ConfigError, match=r'harmonics: must be an integer in \[1, 10\], got 2.5'):
        finite_number(2.5, 'harmonics', low=1, high=10, integer=True)
    assert range_problem(-1, low=0, high=2**32 - 1, integer=True) == (
        'must be an integer in [0, 4294967295]'
    )


# -- command-line options -------------------------------------------------------------------------
@given(st.floats(min_value=1e-300, max_value=1e300))
def test_a_finite_option_reads_back_any_number_in_its_range(value: float):
    assert options.finite(0.0, low_open=True)(repr(value)) == value


@pytest.mark.parametrize('text', ['nan', 'NaN', 'inf', '-inf', '-1', '0', 'twelve'])
def test_a_positive_option_refuses_nan_inf_zero_negatives_and_words(text: str):
    with pytest.raises(argparse.ArgumentTypeError, match=text if text != 'twelve' else 'number'):
        options.positive_float(text)


@pytest.mark.parametrize(
    ('argv', 'words'),
    [
        (['simulate', '--config', 'c.yaml', '--out', 'o', '--duration', 'nan'],
         ('argument --duration', 'finite number > 0', 'nan')),
        (['simulate', '--config', 'c.yaml', '--out', 'o', '--seed', '-2'],
         ('argument --seed', '[0, 4294967295]', '-2')),
        (['sweep', '--bag', 'b', '--model', 'mlp', '--out', 'o', '--trials', '0'],
         ('argument --trials', '[1, 100000]', '0')),
        (['sweep', '--bag', 'b', '--model', 'mlp', '--out', 'o', '--storage-timeout', 'inf'],
         ('argument --storage-timeout', '(0, 3600]', 'inf')),
        (['sweep', '--bag', 'b', '--model', 'mlp', '--out', 'o', '--max-seconds-per-trial',
          'nan'], ('argument --max-seconds-per-trial', 'nan')),
        (['train', '--bag', 'b', '--out', 'o', '--split-seed', '1e3'],
         ('argument --split-seed', 'expected an integer', '1e3')),
    ],
)  # fmt: skip
def test_a_numeric_option_out_of_range_is_refused_naming_option_value_and_range(
    argv: list[str], words: tuple[str, ...], capsys: pytest.CaptureFixture[str]
):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(argv)
    assert exit_.value.code == 2
    said = capsys.readouterr().err
    for word in words:
        assert word in said


def test_hyper_parameters_read_numbers_and_refuse_nan_and_inf_naming_the_item():
    # 1e-3 is a number (YAML 1.2), not the string PyYAML's YAML 1.1 would make of it.
    assert options.hyper_parameters(['mlp.learning_rate=1e-3']) == {'mlp': {'learning_rate': 1e-3}}
    with pytest.raises(ConfigError, match=r'--hyper mlp.learning_rate: must be a finite number'):
        options.hyper_parameters(['mlp.learning_rate=.nan'])
    with pytest.raises(ConfigError, match=r'--hyper mlp.widths\[1\]'):
        options.hyper_parameters(['mlp.widths=[3, .inf]'])


def test_a_hyper_parameter_file_with_a_key_twice_or_a_nan_is_refused(tmp_path: Path):
    twice = tmp_path / 'best.yaml'
    twice.write_text('mlp:\n  width: 64\n  width: 128\n')
    with pytest.raises(ConfigError, match=r"best.yaml: duplicate key 'width' at lines 2 and 3"):
        options.hyper_file(str(twice))
    nan = tmp_path / 'nan.yaml'
    nan.write_text('mlp: {learning_rate: .nan}\n')
    with pytest.raises(ConfigError, match=r'nan.yaml.mlp.learning_rate: must be a finite number'):
        options.hyper_file(str(nan))


def test_a_hyper_parameter_file_of_another_kind_names_its_flat_keys(tmp_path: Path):
    # Probe 15 (A93): a robot config given as --hyper-file was "expected a mapping".
    robot = tmp_path / 'robot.yaml'
    robot.write_text('name: arm\nipo_period_s: 0.008\njoints: [a, b]\nlimits: {torque: [1, 2]}\n')
    with pytest.raises(
        ConfigError, match=r'but name, ipo_period_s, joints hold\(s\) no mapping; is this another'
    ):
        options.hyper_file(str(robot))


# -- topic names (test/ros/test_topic_names.py holds them equal to rclpy's) ----------------------
@pytest.mark.parametrize(
    'name', ['joint_states', '/joint_states', '~/tau_u', '{node}/out', '/a/b_2', '~', '~x']
)
def test_valid_topic_names_pass(name: str):
    assert topic_name_problem(name) is None


@pytest.mark.parametrize(
    ('name', 'why'),
    [
        ('', 'empty'),
        ('joint states', 'only letters'),
        ('/a/', "end with '/'"),
        ('a//b', "'//'"),
        ('1a', 'digit'),
        ('/a/2b', 'digit'),
        ('a~', 'first character'),
        ('~ab', "followed by '/'"),
        ('{node', 'balanced'),
        ('{robot}/x', 'unknown substitution'),
        ('a' * 250, 'at most 247'),
        (3, 'a string'),
    ],
)
def test_invalid_topic_names_are_refused_saying_why(name: object, why: str):
    problem = topic_name_problem(name)
    assert problem is not None
    assert why in problem


def test_a_number_written_as_a_string_is_named_a_string():
    from id_learning.config_io import range_problem

    assert range_problem('0.008', low=1e-5, high=1.0) == (
        'must be a finite number in [1e-05, 1], not a string'
    )
    assert range_problem(None, low=1e-5, high=1.0) == 'must be a finite number in [1e-05, 1]'


def test_what_a_path_is_when_it_is_no_regular_file(tmp_path):
    from id_learning.config_io import not_a_file

    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    (tmp_path / 'file').write_text('x')

    assert not_a_file(tmp_path / 'file') is None
    assert not_a_file(tmp_path) == 'a folder'
    assert not_a_file(fifo) == 'a FIFO (named pipe)'
    assert not_a_file(tmp_path / 'none') == 'no such file'
    assert not_a_file('/dev/null') == 'a character device'


def test_a_model_file_that_is_a_fifo_is_named_as_one_not_as_missing(tmp_path, mabi):
    from id_learning.errors import CheckpointError
    from id_learning.models.artifact import read_artifact

    (tmp_path / 'model.json').write_text('{}')
    os.mkfifo(tmp_path / 'weights.safetensors')

    with pytest.raises(
        CheckpointError, match=r'weights\.safetensors: a FIFO \(named pipe\), not a'
    ):
        read_artifact(tmp_path, mabi)


def test_a_node_robot_config_that_is_a_folder_is_named_as_one(tmp_path):
    from id_learning.nodes.params import resolve_robot_config

    with pytest.raises(ConfigError, match=r'robot_config: .*: a folder, not a robot config file'):
        resolve_robot_config(str(tmp_path))
    fifo = tmp_path / 'robot.yaml'
    os.mkfifo(fifo)
    assert resolve_robot_config(str(fifo)) == fifo  # read as it comes, as --robot <(...)
