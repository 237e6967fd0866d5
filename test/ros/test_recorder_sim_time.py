"""recorder under use_sim_time: log times on /clock, or on the system clock (said) without one.

The probe's recorder with use_sim_time and no /clock logged every message at time 0 without a
word: a bag that no split_duration_s could split and no ``timing: log_time`` replay could
schedule. Now the recording goes on the system clock, says so (log, /diagnostics, summary), and
its timers (flush, /diagnostics) run on the steady clock whatever /clock does.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import STARTUP_S

from id_learning.bag import read_joint_states

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/motor_currents')
NAME = 'id_learning/recorder'
COUNT = 40
#: The simulated time /clock starts at [ns]: a bag's time, years before the system clock's.
SIM_START_NS = 1_600_000_000_000_000_000


def _publish(listener, count: int, clock=None) -> None:
    """Wait for the recorder's subscriptions, then send ``count`` messages on each topic (and,
    with ``clock``, a /clock before each pair, 8 ms apart)."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    publishers = listener.publishers_subscribed(JointState, TOPICS, sensor_qos(200))
    if clock is not None:
        listener.wait_for(
            lambda: clock.get_subscription_count() >= 1, STARTUP_S, "the recorder's /clock"
        )
    names = [f'joint_{i}' for i in range(1, 7)]
    for k in range(count):
        stamp = SIM_START_NS + k * 8_000_000
        if clock is not None:
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(stamp, 1_000_000_000)
            clock.publish(msg)
        for publisher in publishers.values():
            state = JointState(name=names, position=[0.0] * 6, velocity=[0.0] * 6)
            state.header.stamp.sec, state.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            publisher.publish(state)


def _written(listener, count: int):
    def done() -> bool:
        values = listener.diagnostics(NAME)
        return values is not None and int(values['written']) >= count

    return done


def test_without_clock_the_recording_is_on_the_system_clock_and_says_so(tmp_path, nodes, listener):
    from diagnostic_msgs.msg import DiagnosticArray

    path = tmp_path / 'bag'
    listener.subscribe(DiagnosticArray, '/diagnostics')
    recorder = nodes(
        'recorder', {'output': str(path), 'use_sim_time': True, 'diagnostics_period_s': 0.2}
    )
    _publish(listener, COUNT)
    # /diagnostics comes at all: its timer runs on the steady clock, /clock stands still.
    listener.wait_for(_written(listener, 2 * COUNT), 60, 'every message written')
    values = listener.diagnostics(NAME)
    assert values is not None
    assert values['log_time'].startswith('the system clock (use_sim_time, but no /clock')
    assert recorder.stop() == 0
    log = recorder.log()
    assert 'use_sim_time is set, but no /clock had come (ROS time reads 0)' in log
    assert f'received {2 * COUNT}, written {2 * COUNT}, dropped 0, lost 0' in log
    assert 'log times: the system clock (use_sim_time, but no /clock' in log
    for topic in TOPICS:
        states = read_joint_states(path, topic)
        assert len(states.stamps_ns) == COUNT  # nothing recorded is lost
        assert (states.log_ns > 1_700_000_000_000_000_000).all()  # receive times, never 0
        assert np.all(np.diff(states.log_ns) >= 0)


def test_with_clock_the_log_times_are_the_clocks(tmp_path, nodes, listener):
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    from id_learning.nodes.qos import CLOCK_QOS

    path = tmp_path / 'bag'
    listener.subscribe(DiagnosticArray, '/diagnostics')
    recorder = nodes(
        'recorder', {'output': str(path), 'use_sim_time': True, 'diagnostics_period_s': 0.2}
    )
    clock = listener.node.create_publisher(Clock, '/clock', CLOCK_QOS)
    start = Clock()
    start.clock.sec = SIM_START_NS // 1_000_000_000

    def on_clock() -> bool:
        """Its /diagnostics are stamped on /clock once the recorder follows it."""
        clock.publish(start)
        for msg in reversed(listener.messages['/diagnostics']):
            if any(status.name == NAME for status in msg.status):
                return msg.header.stamp.sec >= start.clock.sec
        return False

    listener.wait_for(on_clock, STARTUP_S, 'the recorder to follow /clock')
    _publish(listener, COUNT, clock)
    listener.wait_for(_written(listener, 2 * COUNT), 60, 'every message written')
    assert recorder.stop() == 0
    assert 'no /clock' not in recorder.log()
    states = read_joint_states(path, '/joint_states')
    assert len(states.stamps_ns) == COUNT
    end = SIM_START_NS + (COUNT - 1) * 8_000_000
    # /clock is best effort: a log time is the latest /clock the recorder had, never another.
    assert ((states.log_ns >= SIM_START_NS) & (states.log_ns <= end)).all(), states.log_ns
