"""A recorder in a namespace records relative topics under the names it subscribed to.

Probe 16 (D35): run as ``-r __ns:=/r1`` with ``topics:=['joint_states', 'motor_currents']`` it
received /r1/joint_states and /r1/motor_currents but wrote them as 'joint_states' and
'motor_currents': where the data came from was recorded nowhere.
"""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording

from id_learning.bag import bag_info
from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros


def test_relative_topics_are_recorded_under_their_resolved_names(tmp_path, nodes):
    bag = write_recording(sine_recording(50), tmp_path / 'played')
    recorded = tmp_path / 'recorded'
    recorder = nodes(
        'recorder',
        {'output': str(recorded), 'topics': ['joint_states', 'motor_currents']},
        remaps={'__ns': '/r1'},
    )
    replay = nodes(
        'replay',
        {'bag': str(bag), 'wait_for_subscribers': 2, 'publish_clock': False},
        remaps={'/joint_states': '/r1/joint_states', '/motor_currents': '/r1/motor_currents'},
    )
    assert replay.wait(120) == 0, replay.log()
    assert recorder.stop() == 0, recorder.log()
    assert "(resolved: ['/r1/joint_states', '/r1/motor_currents'])" in recorder.log()
    counts = {t.name: t.count for t in bag_info(recorded).topics}
    assert counts == {'/r1/joint_states': 50, '/r1/motor_currents': 50}
