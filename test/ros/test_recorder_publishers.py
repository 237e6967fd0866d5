"""Two publishers on a recorded topic interleave two streams in the bag (train later finds its
stamps going backwards, probe R03): the recorder warns once, naming the topic and both nodes."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.log_wait import wait_for_log

pytestmark = pytest.mark.ros


def test_two_publishers_on_a_recorded_topic_are_named_once(tmp_path, nodes, listener):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    listener.subscribe(DiagnosticArray, '/diagnostics')
    other = rclpy.create_node('other_robot', context=listener.context)
    try:
        listener.node.create_publisher(JointState, '/joint_states', 10)
        other.create_publisher(JointState, '/joint_states', 10)
        recorder = nodes(
            'recorder', {'output': str(tmp_path / 'bag'), 'diagnostics_period_s': 0.2}
        )
        wait_for_log(recorder, '2 publishers on /joint_states')
        seen = len(listener.messages['/diagnostics'])
        listener.wait_for(
            lambda: len(listener.messages['/diagnostics']) >= seen + 3, 30, 'three diagnostics'
        )
        values = listener.diagnostics('id_learning/recorder')
        assert values is not None
        assert values['/joint_states publishers'] == '/other_robot, /test_listener'
        assert '/motor_currents publishers' not in values
        assert recorder.stop() == 0
        log = recorder.log()
        assert log.count('2 publishers on /joint_states') == 1, log
        assert 'node /other_robot, node /test_listener' in log
        assert 'interleave' in log
        assert '/motor_currents' not in log.split('2 publishers on')[1].splitlines()[0]
    finally:
        other.destroy_node()
