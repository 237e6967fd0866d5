"""Another node publishing on a node's output is named, on /diagnostics while it lasts, and when
it is gone (the probe's B49/B76: two predictors on one tau_u gave a consumer two torques per
cycle, from two models, without a word)."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.log_wait import wait_for_log
from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros


def _status(listener, name: str):
    """The latest /diagnostics status of that name, or None."""
    for msg in reversed(listener.messages['/diagnostics']):
        for status in msg.status:
            if status.name == name:
                return status
    return None


def test_two_predictors_on_one_output_each_name_the_other_until_it_goes(
    nodes, listener, tiny_artifacts
):
    from diagnostic_msgs.msg import DiagnosticArray

    listener.subscribe(DiagnosticArray, '/diagnostics')
    common = {'input_topic': '/reference', 'diagnostics_period_s': 0.2}
    first = nodes('predictor', {'artifact': str(tiny_artifacts['mlp']), **common})
    second = nodes(
        'predictor',
        {'artifact': str(tiny_artifacts['rnea_lq']), **common},
        name='predictor_b',
        remaps={'__node': 'predictor_b'},
    )
    said = "another publisher on /tau_u, the topic of this node's output_topic: node /predictor_b"
    wait_for_log(first, said)  # before the fix: never
    wait_for_log(second, 'another publisher on /tau_u')
    assert 'node /predictor;' in second.log()

    def warned() -> bool:
        status = _status(listener, 'id_learning/predictor')
        return status is not None and 'another publisher on /tau_u' in status.message

    listener.wait_for(warned, STARTUP_S, 'the first predictor to report the other on /diagnostics')
    assert _status(listener, 'id_learning/predictor').level == b'\x01'  # warn
    values = listener.diagnostics('id_learning/predictor')
    assert values['other_output_publishers'] == '1'
    assert second.stop() == 0
    wait_for_log(first, '/tau_u (output_topic): no other publisher now')
    assert first.log().count(said) == 1  # once per episode


def test_two_replays_on_one_reference_each_name_the_other(tmp_path, nodes):
    bag = write_recording(sine_recording(100), tmp_path / 'bag')
    common = {
        'bag': str(bag),
        'loop': True,
        'publish_clock': False,
        'topics': ['/joint_states'],
        'diagnostics_period_s': 0.2,
    }
    first = nodes('replay', common)
    second = nodes('replay', common, name='replay_b', remaps={'__node': 'replay_b'})
    wait_for_log(  # before the fix: never
        first, "another publisher on /reference, the topic of this node's reference_topic"
    )
    wait_for_log(first, "another publisher on /joint_states, the topic of this node's topics[0]")
    assert 'node /replay_b' in first.log()
    wait_for_log(second, 'node /replay;')


def test_a_publisher_of_another_type_on_the_output_is_named_with_its_type(
    nodes, listener, tiny_artifacts
):
    # Probe 16 (D15): a std_msgs/String publisher on /tau_u was warned of as 'two torques per
    # cycle, from two models'.
    from std_msgs.msg import String

    publisher = listener.node.create_publisher(String, '/tau_u', 10)
    try:
        predictor = nodes('predictor', {'artifact': str(tiny_artifacts['mlp'])})
        wait_for_log(predictor, "the topic of this node's output_topic, of another type: node /")
        assert '(std_msgs/msg/String)' in predictor.log()
        assert 'two per cycle' not in predictor.log()
    finally:
        listener.node.destroy_publisher(publisher)
