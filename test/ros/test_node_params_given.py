"""Every value the command line gives a node counts: checked alone, never dropped, [] handled.

rcl keeps the first of two values of one parameter when the later has another type, and reads
``[]`` as a value of no type (rclpy then raised ParameterUninitializedException). The nodes check
each ``-p`` and params-file value alone, refuse a value ROS dropped naming both, and take ``[]``
as an empty list for a list parameter (the schema says whether one may be empty).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.nodes.param_schema import (
    STRING_LIST,
    command_line_sources,
    config_from_mapping,
    field_types,
    value_problem,
)
from id_learning.nodes.params import PredictorNodeConfig, RecorderConfig, ReplayConfig

pytestmark = pytest.mark.ros

CONFIGS = (RecorderConfig, ReplayConfig, PredictorNodeConfig)
REQUIRED: dict[type, dict[str, Any]] = {ReplayConfig: {'bag': 'b'}, PredictorNodeConfig: {
    'artifact': 'a'}}  # fmt: skip
FIELDS = [(cls, item.name) for cls in CONFIGS for item in dataclasses.fields(cls)]
LIST_FIELDS = [(cls, name) for cls, name in FIELDS if field_types(cls)[name] == STRING_LIST]
#: Values of every type a command line can give (rcl's YAML types).
VALUES = st.one_of(
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.lists(st.text(alphabet='/abc_', min_size=1, max_size=6), max_size=3).map(tuple),
    st.lists(st.integers(0, 9), min_size=1, max_size=3).map(tuple),
)


# -- without ROS ----------------------------------------------------------------------------------
def test_the_command_line_gives_its_parameter_sources_in_order():
    args = ['prog', '--ros-args', '-r', '-p:=x', '-p', 'rate:=2.0', '--params-file', 'a.yaml',
            '--param', 'replay:loop:=true', '--log-level', 'debug', '--', '-p', 'not:=ros',
            '--ros-args', '-p', 'rate:=fast', '-p']  # fmt: skip
    assert command_line_sources(args) == [
        ('-p rate:=2.0', ['-p', 'rate:=2.0']),
        ('--params-file a.yaml', ['--params-file', 'a.yaml']),
        ('-p replay:loop:=true', ['-p', 'replay:loop:=true']),
        ('-p rate:=fast', ['-p', 'rate:=fast']),
    ]
    assert command_line_sources([]) == []


@settings(max_examples=300, deadline=None)
@given(field=st.sampled_from(FIELDS), value=VALUES)
def test_one_value_is_refused_alone_exactly_when_the_snapshot_refuses_it_by_its_field(
    field: tuple[type, str], value: Any
):
    """The check of a value alone agrees with the snapshot's, but for rules between fields."""
    cls, name = field
    problem = value_problem(cls, name, value)
    refused = ''
    try:
        config_from_mapping(cls, {**REQUIRED.get(cls, {}), name: value}, 'node n')
    except ConfigError as err:
        refused = str(err)
    if problem:
        assert problem.startswith(name), problem
        assert refused.startswith(f'node n: {name}'), refused
    else:
        assert not refused or not refused.startswith(f'node n: {name}'), refused


def _empty_list(build: Any, name: str) -> None:
    """``build()`` gives an empty ``name``, or refuses it naming it and saying it is empty."""
    refused = ''
    try:
        config = build()
    except ConfigError as err:
        refused = str(err)
    else:
        assert getattr(config, name) == ()
    assert not refused or f'{name}: an empty list' in refused, refused


@pytest.mark.parametrize(('cls', 'name'), LIST_FIELDS, ids=lambda x: getattr(x, '__name__', x))
def test_an_empty_list_is_taken_or_refused_by_name(cls: type, name: str):
    _empty_list(lambda: config_from_mapping(cls, {**REQUIRED.get(cls, {}), name: []}, 'n'), name)


def test_which_lists_may_be_empty():
    with pytest.raises(ConfigError, match='topics: an empty list; give at least one topic'):
        RecorderConfig(topics=())
    with pytest.raises(ConfigError, match='msg_types: an empty list; give one pkg/msg/Type'):
        RecorderConfig(msg_types=())
    assert ReplayConfig(bag='b', topics=()).topics == ()  # the reference alone
    with pytest.raises(ConfigError, match='nothing to publish'):
        ReplayConfig(bag='b', topics=(), reference_mode='none')


# -- on a node ------------------------------------------------------------------------------------
@pytest.fixture
def ros_context():
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    import rclpy
    from rclpy.context import Context
    from ros.ros_helpers import random_domain

    context = Context()
    rclpy.init(context=context, domain_id=random_domain())
    try:
        yield context
    finally:
        context.try_shutdown()


def _declare(context: Any, cls: type, words: list[str]) -> Any:
    """Declare ``cls`` on a replay-named node given ``words`` as rcl merges them; its snapshot."""
    from rclpy.node import Node

    from id_learning.nodes.param_ros import declare_parameters, read_snapshot

    node = Node(
        'replay' if cls is ReplayConfig else 'recorder',
        context=context,
        cli_args=['--ros-args', *words],
        start_parameter_services=False,
        enable_rosout=False,
    )
    try:
        from id_learning.nodes import param_ros

        param_ros.COMMAND_LINE = ['--ros-args', *words]
        declare_parameters(node, cls)
        return read_snapshot(node, cls)
    finally:
        param_ros.COMMAND_LINE = None
        node.destroy_node()


@pytest.mark.parametrize(
    ('words', 'message'),
    [
        (['-p', 'rate:=10.0', '-p', 'rate:=fast'],
         r"node replay: rate: 'fast' is no number .* \(given as -p rate:=fast\)"),
        (['-p', 'wait_for_subscribers:=0', '-p', 'wait_for_subscribers:=2.5'],
         r'wait_for_subscribers: 2\.5 is no integer .*given as -p wait_for_subscribers:=2\.5'),
        (['-p', 'rate:=fast', '-p', 'rate:=10.0'], r"rate: 'fast' is no number"),
        (['-p', 'rate:=500.0', '-p', 'rate:=2.0'],
         r'rate: must be .*got 500\.0 \(given as -p rate:=500\.0\)'),
        (['-p', 'loop:=[]'], r'loop: \[\] is no boolean .*given as -p loop:=\[\]'),
    ],
)  # fmt: skip
def test_every_value_given_is_checked_also_one_a_later_value_replaces(ros_context, words, message):
    with pytest.raises(ConfigError, match=message):
        _declare(ros_context, ReplayConfig, ['-p', 'bag:=b', *words])


@pytest.mark.parametrize(
    ('words', 'rate'),
    [
        (['-p', 'rate:=2', '-p', 'rate:=20.0'], 20.0),  # rcl kept the first: another type
        (['-p', 'rate:=2.0', '-p', 'rate:=3'], 3.0),
        (['-p', 'rate:=2.0', '-p', 'rate:=3.0', '-p', 'rate:=4'], 4.0),
    ],
)
def test_the_last_value_given_counts_whatever_its_type(ros_context, words, rate):
    assert _declare(ros_context, ReplayConfig, ['-p', 'bag:=b', *words]).rate == rate


def test_a_params_file_value_is_checked_and_a_later_p_wins(ros_context, tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('replay:\n  ros__parameters:\n    bag: b\n    rate: 2.0\n')
    config = _declare(ros_context, ReplayConfig, ['--params-file', str(path), '-p', 'rate:=3.0'])
    assert config.rate == 3.0  # the documented override
    words = ['-p', 'rate:=1.0', '--params-file', str(path), '-p', 'rate:=5']
    assert _declare(ros_context, ReplayConfig, words).rate == 5.0  # rcl kept the file's 2.0
    path.write_text('replay:\n  ros__parameters:\n    bag: b\n    rate: fast\n')
    with pytest.raises(ConfigError, match=rf"rate: 'fast' is no number .*--params-file {path}"):
        _declare(ros_context, ReplayConfig, ['--params-file', str(path), '-p', 'rate:=3.0'])


@pytest.mark.parametrize(('cls', 'name'), LIST_FIELDS, ids=lambda x: getattr(x, '__name__', x))
def test_an_empty_list_on_the_command_line_is_an_empty_list_or_refused_by_name(
    ros_context, cls, name
):
    """ROS reads '[]' as no type; rclpy raised ParameterUninitializedException on it."""
    required = ['-p', 'bag:=b'] if cls is ReplayConfig else []
    _empty_list(lambda: _declare(ros_context, cls, [*required, '-p', f'{name}:=[]']), name)


def _node(module: str, *words: str, cwd) -> subprocess.CompletedProcess[str]:
    from ros.ros_helpers import node_environment, random_domain

    return subprocess.run(
        [sys.executable, '-m', 'id_learning.entry', module, '--ros-args', *words],
        env=node_environment(random_domain()),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.mark.parametrize(
    ('module', 'words', 'message'),
    [
        ('recorder', ['-p', 'topics:=[]'],
         'node recorder: topics: an empty list; give at least one topic to record'),
        ('recorder', ['-p', 'msg_types:=[]'], 'node recorder: msg_types: an empty list'),
        ('replay', ['-p', 'bag:=b', '-p', 'rate:=10.0', '-p', 'rate:=fast'],
         "node replay: rate: 'fast' is no number"),
    ],
)  # fmt: skip
def test_the_node_programs_refuse_with_status_2_and_one_reason(module, words, message, tmp_path):
    output = ['-p', f'output:={tmp_path / "bag"}'] if module == 'recorder' else []
    result = _node(module, *output, *words, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert message in result.stderr
    assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'bag').exists()
