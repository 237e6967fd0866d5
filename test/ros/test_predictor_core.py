"""The predictor node serves the core it is given: built in memory, no artifact, no files."""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import ClassVar

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.models.base import InverseDynamicsModel
from id_learning.nodes.params import PredictorNodeConfig, guard_config
from id_learning.nodes.predictor import Predictor
from id_learning.nodes.qos import reference_qos
from id_learning.predictor import FeedForwardPredictor

pytestmark = pytest.mark.ros

#: Deadline of a wait on discovery or messages within this process [s].
WAIT_S = 30.0


class Linear(InverseDynamicsModel):
    """tau = 10 q + 2 v + a per joint: a model that is no artifact."""

    kind: ClassVar[str] = 'linear'

    def __init__(self, robot) -> None:
        self.robot = robot

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.robot.joints)

    def fit(self, data, *, progress=False):
        return self

    def predict(self, q, v, a):
        return 10.0 * np.asarray(q) + 2.0 * np.asarray(v) + np.asarray(a)

    def state(self):
        return {}

    def load_state(self, tensors, fitted):
        pass


@contextmanager
def served(core, mabi, config, domain_id, **kwargs):
    """The node on ``core`` and a sender, in a context of their own; and spin_until."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    executor = SingleThreadedExecutor(context=context)
    made: list = []
    try:
        node = Predictor(core, mabi, config, context=context, **kwargs)
        made.append(node)
        made.append(rclpy.create_node('sender', context=context))
        for each in made:
            executor.add_node(each)

        def spin_until(condition, what: str) -> None:
            deadline = time.monotonic() + WAIT_S
            while not condition():
                assert time.monotonic() < deadline, f'timed out waiting for {what}'
                executor.spin_once(timeout_sec=0.05)

        yield node, made[1], spin_until
        node.close()
    finally:
        executor.shutdown()
        for each in made:
            each.destroy_node()
        context.try_shutdown()


def test_the_node_serves_a_core_built_in_memory_with_the_parameters_it_was_given(mabi, domain_id):
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.msg_conversions import trajectory_message

    config = PredictorNodeConfig(artifact='in-memory', torque_limit_scale=0.5, output_depth=37)
    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque, guard_config(config, mabi))
    core.warm_up()
    # An override the config does not hold: the node declares its config, not overrides.
    overrides = [Parameter('torque_limit_scale', value=0.9)]
    with served(core, mabi, config, domain_id, parameter_overrides=overrides) as (
        node,
        sender,
        spin_until,
    ):
        received: list[JointState] = []
        publisher = sender.create_publisher(JointTrajectory, 'reference', reference_qos(10))
        sender.create_subscription(JointState, 'tau_u', received.append, 100)
        assert node.get_parameter('torque_limit_scale').value == 0.5
        assert node.get_parameter('artifact').value == 'in-memory'
        # A consumer that stalls for output_depth cycles loses nothing from the writer's history.
        (tau_u,) = [p for p in node.publishers if p.topic_name == '/tau_u']
        assert tau_u.qos_profile.depth == 37
        spin_until(
            lambda: (
                publisher.get_subscription_count() >= 1 and node.count_subscribers('tau_u') >= 1
            ),
            'the node and the sender to match',
        )
        q, zeros = np.linspace(0.1, 0.6, 6), np.zeros(6)
        start_ns, period_ns = time.time_ns(), round(mabi.ipo_period_s * 1e9)
        stamps = [start_ns + k * period_ns for k in range(5)]
        for stamp in stamps:
            publisher.publish(trajectory_message(stamp, mabi.joints, q, zeros, zeros))
        spin_until(lambda: len(received) >= len(stamps), f'{len(stamps)} tau_u')
        for msg, stamp in zip(received, stamps, strict=True):
            assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp
            assert tuple(msg.name) == tuple(mabi.joints)
            np.testing.assert_allclose(msg.effort, 10.0 * q, rtol=0, atol=1e-12)
        assert core.counters.published == len(stamps)


def test_a_trajectory_without_points_is_refused_saying_so(mabi):
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.msg_conversions import trajectory_to_sample
    from id_learning.predictor import Reject

    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque)
    msg = JointTrajectory(joint_names=list(mabi.joints))  # the probe's TJ1
    result = core.step(trajectory_to_sample(msg), 10**9)
    assert result.reject is Reject.SHAPE
    assert result.detail.startswith('the JointTrajectory has no points')


def test_the_command_ramps_to_zero_when_stale_and_back_over_dds(mabi, domain_id):
    # The probe's P25: the command dropped to zero and jumped back; now a ramp each way, on
    # the node's timer, at most one period's worth of the slew limit per message.
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.msg_conversions import trajectory_message

    config = PredictorNodeConfig(
        artifact='in-memory', command_topic='ff_cmd', torque_rise_s=1.0, stale_after_cycles=5
    )
    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque, guard_config(config, mabi))
    core.warm_up()
    with served(core, mabi, config, domain_id) as (node, sender, spin_until):
        commands: list[np.ndarray] = []
        publisher = sender.create_publisher(JointTrajectory, 'reference', reference_qos(10))
        sender.create_subscription(
            Float64MultiArray, 'ff_cmd', lambda m: commands.append(np.array(m.data)), 1000
        )
        spin_until(
            lambda: publisher.get_subscription_count() >= 1 and node.count_subscribers('ff_cmd'),
            'the node and the sender to match',
        )
        zeros, period_ns = np.zeros(6), round(mabi.ipo_period_s * 1e9)
        a = 0.3 * mabi.limits.torque  # tau = a: 38 steps of 0.8 % of the limit from zero

        def send(n: int) -> None:
            start_ns = time.time_ns()
            for k in range(n):
                msg = trajectory_message(start_ns + k * period_ns, mabi.joints, zeros, zeros, a)
                publisher.publish(msg)

        send(3)
        spin_until(lambda: len(commands) >= 3, 'the first commands')
        np.testing.assert_array_equal(commands[0], a)  # the first command is the first tau_u
        spin_until(lambda: not commands[-1].any(), 'the ramp to reach zero')
        ramp = len(commands) - 3
        assert ramp == 38
        send(3)  # resumed: tau_u continues at a, the command ramps back from zero
        spin_until(lambda: len(commands) >= 3 + ramp + 3, 'the commands after resuming')
        step = mabi.limits.torque / config.torque_rise_s * mabi.ipo_period_s
        np.testing.assert_allclose(commands[-3:], [k * step for k in (1, 2, 3)])
        assert (np.abs(np.diff(commands, axis=0)) <= step * (1 + 1e-12)).all()
        assert core.counters.predicted == 6
        assert core.counters.rejected == 0
