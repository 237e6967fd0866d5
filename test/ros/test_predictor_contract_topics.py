"""The predictor publishes nothing on the robot's contract topics (joint_states, motor_currents).

tau_u there would be recorded as the robot's joint states or currents, replayed, and learnt from.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import node_environment, random_domain
from ros.test_predictor_core import Linear

from id_learning.errors import ConfigError
from id_learning.nodes.params import PredictorNodeConfig, guard_config
from id_learning.nodes.predictor import Predictor
from id_learning.predictor import FeedForwardPredictor

pytestmark = pytest.mark.ros


@pytest.fixture
def ros_context(domain_id):
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        yield context
    finally:
        context.try_shutdown()


def _node(mabi, context, config, **kwargs):
    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque, guard_config(config, mabi))
    return Predictor(core, mabi, config, context=context, **kwargs)


@pytest.mark.parametrize(
    ('values', 'kwargs', 'key', 'topic', 'robot_key'),
    [
        ({'output_topic': '/motor_currents'}, {}, 'output_topic', "'/motor_currents'",
         'motor_currents'),
        ({'output_topic': 'joint_states'}, {}, 'output_topic', "'joint_states'", 'joint_states'),
        ({'command_topic': '/joint_states'}, {}, 'command_topic', "'/joint_states'",
         'joint_states'),
        (
            {},
            {'cli_args': ['--ros-args', '-r', 'tau_u:=/motor_currents']},
            'output_topic',
            "'tau_u'",
            'motor_currents',
        ),
    ],
)  # fmt: skip
def test_an_output_on_a_contract_topic_is_refused_naming_key_and_topic(
    mabi, ros_context, values, kwargs, key, topic, robot_key
):
    config = PredictorNodeConfig(artifact='in-memory', **values)
    with pytest.raises(ConfigError) as raised:
        _node(mabi, ros_context, config, **kwargs)
    text = str(raised.value)
    assert text.startswith(f'node predictor: {key} {topic} resolves to /{robot_key}')
    assert f"the robot's {robot_key} topic" in text
    assert '\n' not in text


@pytest.mark.parametrize(
    ('values', 'kwargs'),
    [
        ({'input_topic': '/joint_states', 'input_type': 'joint_state'}, {}),
        ({}, {}),
        ({'output_topic': 'joint_states'}, {'namespace': '/robot'}),  # /robot/joint_states
    ],
)
def test_an_input_on_a_contract_topic_and_outputs_elsewhere_start(
    mabi, ros_context, values, kwargs
):
    config = PredictorNodeConfig(artifact='in-memory', **values)
    node = _node(mabi, ros_context, config, **kwargs)
    try:
        assert node.get_parameter('output_topic').value == config.output_topic
    finally:
        node.close()
        node.destroy_node()


def test_the_process_refuses_a_contract_output_topic_in_one_line(tmp_path, tiny_artifacts):
    process = subprocess.run(
        [
            sys.executable,
            '-m',
            'id_learning.nodes.predictor',
            '--ros-args',
            '-p',
            f'artifact:={tiny_artifacts["mlp"]}',
            '-p',
            'output_topic:=/motor_currents',
        ],
        check=False,
        env=node_environment(random_domain()),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert process.returncode == 2, process.stderr
    assert (
        "error: node predictor: output_topic '/motor_currents' resolves to /motor_currents, the "
        "robot's motor_currents topic"
    ) in process.stderr
    assert 'Traceback' not in process.stdout + process.stderr
