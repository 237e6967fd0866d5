"""Node parameters (schema, YAML file, runtime changes) and message conversions."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import REPO

from id_learning.errors import ConfigError
from id_learning.nodes.params import (
    PredictorNodeConfig,
    RecorderConfig,
    ReplayConfig,
    config_from_mapping,
    declare_parameters,
    load_node_config,
    read_snapshot,
    validate_change,
)

pytestmark = pytest.mark.ros

NODE_CONFIGS = {
    'recorder': RecorderConfig,
    'replay': ReplayConfig,
    'predictor': PredictorNodeConfig,
}


@pytest.mark.parametrize('node', sorted(NODE_CONFIGS))
def test_the_shipped_parameter_file_sets_every_parameter_of_every_node(node):
    import yaml

    cls = NODE_CONFIGS[node]
    config = load_node_config(REPO / 'config/nodes.yaml', node, cls)
    assert isinstance(config, cls)
    section = yaml.safe_load((REPO / 'config/nodes.yaml').read_text())[node]['ros__parameters']
    assert set(section) == {item.name for item in dataclasses.fields(cls)}


def test_every_parameter_has_a_description():
    for cls in NODE_CONFIGS.values():
        for item in dataclasses.fields(cls):
            assert len(item.metadata['description']) > 20, (cls.__name__, item.name)


@pytest.mark.parametrize(
    ('cls', 'values', 'match'),
    [
        (RecorderConfig, {'flush_period_s': 0.8}, 'flush_period_s'),
        (RecorderConfig, {'topics': ['/a'], 'msg_types': []}, 'msg_types'),
        (RecorderConfig, {'reliability': 'sometimes'}, 'reliability'),
        (RecorderConfig, {'qos_depth': 'deep'}, 'qos_depth'),
        (RecorderConfig, {'recording': 'x'}, 'unknown parameter'),
        (ReplayConfig, {}, 'bag is required'),
        (ReplayConfig, {'bag': 'b', 'rate': 0.0}, 'rate'),
        (ReplayConfig, {'bag': 'b', 'reference_mode': 'both'}, 'reference_mode'),
        (PredictorNodeConfig, {}, 'artifact is required'),
        (PredictorNodeConfig, {'artifact': 'a', 'torque_limit_scale': 2.0}, 'torque_limit_scale'),
        (PredictorNodeConfig, {'artifact': 'a', 'stale_after_cycles': 0}, 'stale_after_cycles'),
        (PredictorNodeConfig, {'artifact': 'a', 'input_type': 'twist'}, 'input_type'),
    ],
)
def test_node_configs_reject_bad_values_naming_the_key(cls, values, match):
    with pytest.raises(ConfigError, match=match):
        config_from_mapping(cls, values, 'test')


def test_an_integer_is_accepted_for_a_float_parameter():
    config = config_from_mapping(ReplayConfig, {'bag': 'b', 'rate': 2}, 'test')
    assert config.rate == 2.0
    assert isinstance(config.rate, float)


@pytest.fixture
def ros_context():
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=0)
    try:
        yield context
    finally:
        context.try_shutdown()


def test_declared_parameters_read_back_as_the_dataclass_with_overrides(ros_context):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    node = Node(
        'predictor',
        context=ros_context,
        parameter_overrides=[
            Parameter('artifact', value='models/mlp'),
            Parameter('max_age_s', value=1),  # an integer for a float: accepted
            Parameter('input_type', value='joint_state'),
        ],
    )
    try:
        declare_parameters(node, PredictorNodeConfig)
        config = read_snapshot(node, PredictorNodeConfig)
        assert config == PredictorNodeConfig(
            artifact='models/mlp', max_age_s=1.0, input_type='joint_state'
        )
        descriptor = node.describe_parameter('torque_limit_scale')
        assert 'torque limits' in descriptor.description
        assert not descriptor.read_only
        assert node.describe_parameter('artifact').read_only
        assert 'one of' in node.describe_parameter('out_of_range').additional_constraints
        # Read-only parameters cannot change at runtime.
        result = node.set_parameters([Parameter('artifact', value='other')])[0]
        assert not result.successful
    finally:
        node.destroy_node()


def test_runtime_changes_are_validated_with_a_reason():
    config = PredictorNodeConfig(artifact='a')
    changed, reason = validate_change(config, {'torque_limit_scale': 0.5})
    assert changed is not None
    assert changed.torque_limit_scale == 0.5
    assert reason == ''
    changed, reason = validate_change(config, {'torque_limit_scale': 1.5})
    assert changed is None
    assert 'torque_limit_scale' in reason
    changed, reason = validate_change(config, {'artifact': 'b'})
    assert changed is None
    assert 'read-only' in reason


@pytest.mark.parametrize(
    ('module', 'parameters', 'message'),
    [
        ('replay', [], 'bag is required'),
        ('predictor', ['-p', 'artifact:=/nonexistent/model'], 'not a model artifact'),
        ('recorder', ['-p', 'flush_period_s:=2.0'], 'flush_period_s'),
        ('predictor', ['-p', 'input_depth:=ten'], "input_depth: 'ten' is no integer"),
        ('replay', ['-p', 'rat:=2.0'], 'unknown parameter(s) rat (did you mean rate?)'),
        ('recorder', ['--params-file', 'absent.yaml'], "Couldn't parse params file"),
    ],
)
def test_a_node_with_bad_parameters_exits_with_status_2_and_says_why(
    module, parameters, message, tmp_path
):
    from ros.ros_helpers import node_environment, random_domain

    result = subprocess.run(
        [sys.executable, '-m', f'id_learning.nodes.{module}', '--ros-args', *parameters],
        env=node_environment(random_domain()),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 2, result.stderr
    assert message in result.stderr


# -- message conversions --------------------------------------------------------------------------
def test_trajectory_messages_convert_to_reference_samples_and_back():
    from id_learning.nodes.msg_conversions import trajectory_message, trajectory_to_sample

    names = ['b', 'a']
    msg = trajectory_message(1_234_567_890_123, names, [1.0, 2.0], [3.0, 4.0], [5.0, 6.0])
    sample = trajectory_to_sample(msg)
    assert sample.stamp_ns == 1_234_567_890_123
    assert sample.names == ('b', 'a')
    np.testing.assert_array_equal(sample.q, [1.0, 2.0])
    np.testing.assert_array_equal(sample.v, [3.0, 4.0])
    np.testing.assert_array_equal(sample.a, [5.0, 6.0])
    msg.points[0].accelerations = []
    assert trajectory_to_sample(msg).a is None  # estimate them
    msg.points = []
    assert trajectory_to_sample(msg).q.shape == (0,)  # the core rejects it as a shape error


def test_joint_states_convert_to_samples_without_accelerations():
    from id_learning.nodes.msg_conversions import joint_state_message, joint_state_to_sample

    msg = joint_state_message(5, ['j'], position=np.array([0.5]), velocity=np.array([-1.0]))
    sample = joint_state_to_sample(msg)
    assert (sample.stamp_ns, sample.names, sample.a) == (5, ('j',), None)
    np.testing.assert_array_equal(sample.q, [0.5])
    assert list(msg.effort) == []


def test_torque_command_and_diagnostics_carry_the_values():
    from diagnostic_msgs.msg import DiagnosticStatus

    from id_learning.nodes.msg_conversions import diagnostic_array, torque_command

    command = torque_command(np.array([1.5, -2.0]))
    assert list(command.data) == [1.5, -2.0]
    assert command.layout.dim[0].size == 2
    msg = diagnostic_array(
        7, name='n', hardware_id='h', level='warn', message='m', values={'x': 1, 'y': 0.25}
    )
    status = msg.status[0]
    assert status.level == DiagnosticStatus.WARN
    assert {kv.key: kv.value for kv in status.values} == {'x': '1', 'y': '0.25'}
