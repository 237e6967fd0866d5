"""Ctrl-C pressed again while a node closes: the close finishes, the exit status is its own.

The probe's R10: a recorder given a second SIGINT after the first exited by signal (-2),
although its bag was finished.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import time

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.bag import read_joint_states

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/motor_currents')
#: Deadline for the node to exit under repeated signals [s].
EXIT_S = 60.0


def test_a_recorder_signalled_again_and_again_finishes_its_bag_and_exits_0(
    tmp_path, nodes, listener
):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    path = tmp_path / 'bag'
    listener.subscribe(DiagnosticArray, '/diagnostics')
    recorder = nodes('recorder', {'output': str(path), 'diagnostics_period_s': 0.2})
    publishers = {
        topic: listener.node.create_publisher(JointState, topic, sensor_qos(200))
        for topic in TOPICS
    }
    listener.wait_for(
        lambda: all(p.get_subscription_count() >= 1 for p in publishers.values()),
        90,
        'the recorder to subscribe',
    )
    names = [f'joint_{i}' for i in range(1, 7)]
    for k in range(50):
        msg = JointState(name=names, position=[float(k)] * 6, velocity=[0.0] * 6)
        msg.header.stamp.sec = k
        for publisher in publishers.values():
            publisher.publish(msg)

    def written() -> bool:
        values = listener.diagnostics('id_learning/recorder')
        return values is not None and int(values['written']) >= 100

    listener.wait_for(written, 30, 'the recorder to write the 100 messages')
    # Signals every 20 ms until it exits: many land while it closes its bag.
    deadline = time.monotonic() + EXIT_S
    while recorder.is_running:
        assert time.monotonic() < deadline, 'the recorder did not exit'
        recorder.process.send_signal(signal.SIGINT)
        with contextlib.suppress(subprocess.TimeoutExpired):
            recorder.process.wait(0.02)
    assert recorder.process.returncode == 0, recorder.log()[-2000:]
    assert (path / 'metadata.yaml').is_file()  # closed: the bag is whole
    assert 'Traceback' not in recorder.log()
    assert len(read_joint_states(path, TOPICS[0]).stamps_ns) == 50
