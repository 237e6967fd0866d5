"""A runtime change of log_throttle_s leaves the predictor logging and serving (probe finding).

rclpy's logger fixes a call site's throttle on its first use and raises ValueError when a later
call passes another: with the throttle taken from the parameter, every throttled line after a
change raised, and after a second change the error line of the callback's own except block did,
which killed the node. The node throttles by hand now (``nodes.log_throttle``).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.test_predictor_core import Linear, served

from id_learning.nodes.params import PredictorNodeConfig, guard_config
from id_learning.nodes.qos import reference_qos
from id_learning.predictor import FeedForwardPredictor

pytestmark = pytest.mark.ros


def test_log_throttle_changed_twice_at_runtime_keeps_the_node_serving(mabi, domain_id):
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.msg_conversions import trajectory_message

    config = PredictorNodeConfig(artifact='in-memory', log_throttle_s=1.0)
    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque, guard_config(config, mabi))
    core.warm_up()
    with served(core, mabi, config, domain_id) as (node, sender, spin_until):
        received: list[JointState] = []
        publisher = sender.create_publisher(JointTrajectory, 'reference', reference_qos(100))
        sender.create_subscription(JointState, 'tau_u', received.append, 100)
        spin_until(
            lambda: (
                publisher.get_subscription_count() >= 1 and node.count_subscribers('tau_u') >= 1
            ),
            'the node and the sender to match',
        )
        q, zeros = np.linspace(0.1, 0.6, 6), np.zeros(6)
        period_ns = round(mabi.ipo_period_s * 1e9)
        wrong = [f'other_{name}' for name in mabi.joints]
        last_ns = 0

        def send_round(n_valid: int) -> None:
            """A refused sample (wrong joint names), a bad stamp, then n_valid valid ones.

            Stamped one period apart from now on, once the stamps before are past: a sender on
            time, for the time base.
            """
            nonlocal last_ns
            spin_until(lambda: time.time_ns() > last_ns, 'the last stamp to pass')
            stamps = iter(range(time.time_ns(), 2**63, period_ns))
            publisher.publish(trajectory_message(next(stamps), wrong, q, zeros, zeros))
            bad = trajectory_message(next(stamps), mabi.joints, q, zeros, zeros)
            bad.header.stamp.nanosec = 1_500_000_000  # no time: refused before the core
            publisher.publish(bad)
            for _ in range(n_valid):
                last_ns = next(stamps)
                publisher.publish(trajectory_message(last_ns, mabi.joints, q, zeros, zeros))

        send_round(3)  # each throttled call site used once with 1.0
        spin_until(lambda: len(received) >= 3, 'the first tau_u')
        for throttle, served_before in ((0.25, 3), (2.5, 6)):
            result = node.set_parameters([Parameter('log_throttle_s', value=throttle)])[0]
            assert result.successful, result.reason
            assert node.config.log_throttle_s == throttle
            send_round(3)
            spin_until(lambda n=served_before: len(received) >= n + 3, 'tau_u after the change')
        assert len(received) == 9
        np.testing.assert_allclose(received[-1].effort, 10.0 * q, rtol=0, atol=1e-12)
        assert node.counts.callback_errors == 0
        assert node.counts.invalid_stamps == 3
        assert core.counters.rejected == 3
        assert core.counters.published == 9
