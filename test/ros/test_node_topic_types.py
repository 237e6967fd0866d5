"""A topic parameter on a topic the node itself uses with another type: refused at start, naming
the parameter and the topic, never a traceback (the probe's B74 and B64)."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.bag import BagWriter, iter_raw
from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros


def _refused(node) -> str:
    """The node's log once it has exited with 2 (refused at start)."""
    assert node.wait(STARTUP_S) == 2, node.log()[-3000:]
    log = node.log()
    assert 'Traceback' not in log, log
    return log


def test_a_replay_whose_reference_is_diagnostics_is_refused_naming_it(tmp_path, nodes):
    bag = write_recording(sine_recording(50), tmp_path / 'bag')
    replay = nodes('replay', {'bag': str(bag), 'reference_topic': '/diagnostics'})
    log = _refused(replay)  # before: RCLError 'incompatible type', exit 1
    assert "reference_topic '/diagnostics' is the topic of the node's diagnostics" in log, log


def test_a_bag_topic_named_diagnostics_of_another_type_is_refused_naming_it(tmp_path, nodes):
    source = write_recording(sine_recording(50), tmp_path / 'source')
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/diagnostics', 'sensor_msgs/msg/JointState')
        for _, log_ns, data in iter_raw(source, ['/joint_states']):
            writer.write('/diagnostics', log_ns, data)
    replay = nodes(
        'replay',
        {'bag': str(bag), 'topics': ['/diagnostics'], 'reference_mode': 'none'},
    )
    log = _refused(replay)  # before: RCLError 'incompatible type', exit 1
    assert "topics[0] (sensor_msgs/msg/JointState in the bag) '/diagnostics'" in log, log
    assert 'a publisher of diagnostic_msgs/msg/DiagnosticArray' in log, log


def test_recording_parameter_events_as_joint_states_names_the_nodes_own_publisher(tmp_path, nodes):
    recorder = nodes(
        'recorder',
        {
            'output': str(tmp_path / 'bag'),
            'topics': ['/parameter_events'],
            'msg_types': ['sensor_msgs/msg/JointState'],
        },
    )
    log = _refused(recorder)  # before: rcl's 'invalid allocator' alone
    assert "topics[0] '/parameter_events'" in log, log
    assert 'itself already has a publisher of rcl_interfaces/msg/ParameterEvent' in log, log
    assert not (tmp_path / 'bag').exists()
