"""Every node parameter is checked where it enters: finite numbers in range, topic names,
enumerations; errors name the node, the parameter and the value. No ROS needed but the last."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, get_type_hints

import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.nodes.params import (
    PredictorNodeConfig,
    RecorderConfig,
    ReplayConfig,
    config_from_mapping,
    log_change,
    validate_change,
)

CONFIGS = (RecorderConfig, ReplayConfig, PredictorNodeConfig)
REQUIRED: dict[type, dict[str, Any]] = {ReplayConfig: {'bag': 'b'}, PredictorNodeConfig: {
    'artifact': 'a'}}  # fmt: skip


def _fields(kinds: tuple[type, ...]) -> list[tuple[type, str]]:
    return [
        (cls, item.name)
        for cls in CONFIGS
        for item in dataclasses.fields(cls)
        if get_type_hints(cls)[item.name] in kinds
    ]


def _build(cls: type, **values: Any) -> Any:
    return config_from_mapping(cls, {**REQUIRED.get(cls, {}), **values}, f'node {cls.__name__}')


@pytest.mark.parametrize(
    ('cls', 'name'), _fields((int, float)), ids=lambda x: getattr(x, '__name__', x)
)
def test_every_numeric_parameter_declares_its_range(cls: type, name: str):
    item = next(item for item in dataclasses.fields(cls) if item.name == name)
    assert item.metadata['range'] is not None, f'{cls.__name__}.{name} has no low/high'


@pytest.mark.parametrize(
    ('cls', 'name'), _fields((float,)), ids=lambda x: getattr(x, '__name__', x)
)
@pytest.mark.parametrize('value', [math.nan, math.inf, -math.inf])
def test_every_float_parameter_refuses_nan_and_inf_naming_node_parameter_and_value(
    cls: type, name: str, value: float
):
    with pytest.raises(ConfigError, match=rf'node {cls.__name__}: {name}: must be .*got {value}'):
        _build(cls, **{name: value})


@pytest.mark.parametrize(('cls', 'name'), _fields((int,)), ids=lambda x: getattr(x, '__name__', x))
def test_every_integer_parameter_refuses_a_value_beyond_its_range(cls: type, name: str):
    with pytest.raises(ConfigError, match=rf'{name}: must be an integer'):
        _build(cls, **{name: 10**12})


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_range_margin_is_accepted_exactly_when_finite_and_within_the_cores_range(value: float):
    if math.isfinite(value) and 0 <= value <= 1e3:
        assert _build(PredictorNodeConfig, range_margin=value).range_margin == value
    else:
        with pytest.raises(ConfigError, match='range_margin'):
            _build(PredictorNodeConfig, range_margin=value)


TOPIC_FIELDS = [
    (cls, item.name)
    for cls in CONFIGS
    for item in dataclasses.fields(cls)
    if item.metadata.get('topic')
]


def test_every_parameter_that_names_a_topic_is_checked_as_one():
    named = {(cls, item.name) for cls in CONFIGS for item in dataclasses.fields(cls)
             if item.name.endswith(('topic', 'topics', 'source'))}  # fmt: skip
    assert named == set(TOPIC_FIELDS)


@pytest.mark.parametrize(('cls', 'name'), TOPIC_FIELDS, ids=lambda x: getattr(x, '__name__', x))
@pytest.mark.parametrize('topic', ['tau u', '1tau', 'a//b', 'a~', '{robot}/x'])
def test_every_topic_parameter_refuses_what_rclpy_would_refuse(cls: type, name: str, topic: str):
    value = (topic,) if get_type_hints(cls)[name] == tuple[str, ...] else topic
    if cls is RecorderConfig and name == 'topics':
        value, extra = ('/joint_states', topic), {}
    else:
        extra = {}
    with pytest.raises(
        ConfigError, match=rf'node {cls.__name__}: {name}: .* is no ROS topic name'
    ):
        _build(cls, **{name: value}, **extra)


def test_an_empty_command_topic_means_off_and_passes():
    assert _build(PredictorNodeConfig, command_topic='').command_topic == ''


def test_a_runtime_change_to_nan_is_rejected_with_the_reason():
    config = PredictorNodeConfig(artifact='a')
    changed, reason = validate_change(config, {'range_margin': math.nan})
    assert changed is None
    assert reason == 'range_margin: must be a finite number in [0, 1000], got nan'
    changed, reason = validate_change(config, {'log_throttle_s': 0.0})
    assert changed is None
    assert 'log_throttle_s: must be a finite number in (0, 1000000000], got 0.0' in reason


def test_a_node_reading_nan_names_itself_and_declares_the_range():
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from id_learning.nodes.params import declare_parameters, read_snapshot

    context = Context()
    rclpy.init(context=context, domain_id=0)
    try:
        overrides = [Parameter('artifact', value='a'), Parameter('range_margin', value=math.nan)]
        node = Node('predictor', context=context, parameter_overrides=overrides)
        try:
            declare_parameters(node, PredictorNodeConfig)
            assert node.describe_parameter('range_margin').additional_constraints == 'in [0, 1000]'
            assert (
                'a ROS topic name' in node.describe_parameter('input_topic').additional_constraints
            )
            with pytest.raises(ConfigError, match=r'node predictor: range_margin: .* got nan'):
                read_snapshot(node, PredictorNodeConfig)
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()


def test_setting_an_undeclared_parameter_at_runtime_names_it_and_the_closest():
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    import rclpy
    from rclpy.context import Context
    from rclpy.exceptions import ParameterNotDeclaredException
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from id_learning.nodes.params import declare_parameters

    context = Context()
    rclpy.init(context=context, domain_id=0)
    try:
        node = Node('predictor', context=context,
                    parameter_overrides=[Parameter('artifact', value='a')])  # fmt: skip
        try:
            declare_parameters(node, PredictorNodeConfig)
            # The parameter service answers with this exception's text as the reason.
            with pytest.raises(ParameterNotDeclaredException) as raised:
                node.set_parameters_atomically([Parameter('range_margn', value=0.2)])
            assert 'range_margn (did you mean range_margin?) on node predictor' in str(
                raised.value
            )
            result = node.set_parameters_atomically([Parameter('range_margin', value=0.2)])
            assert result.successful, result.reason
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()


def test_a_runtime_change_is_logged_with_each_value_before_and_after() -> None:
    """Loosening a gate at runtime is said in the node's log, not only on /parameter_events."""
    config = config_from_mapping(PredictorNodeConfig, REQUIRED[PredictorNodeConfig], 'test')
    changed, _ = validate_change(config, {'consistency_scale': 1000.0, 'rearm_samples': 0})
    assert changed is not None
    said: list[str] = []

    class Logger:
        def warning(self, text: str) -> None:
            said.append(text)

    log_change(Logger(), config, changed)
    assert said == [
        f'parameters set at runtime: rearm_samples {config.rearm_samples!r} -> 0, '
        f'consistency_scale {config.consistency_scale!r} -> 1000.0'  # in the schema's order
    ]
    log_change(Logger(), changed, changed)  # nothing changed: nothing said
    assert len(said) == 1
