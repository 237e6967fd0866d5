"""recorder, in its own process: replay -> recorder round trip, a SIGKILL mid-recording, and a
publisher of the wrong message type."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.bag import bag_info, iter_raw, read_joint_states
from id_learning.bag.recover import recover_bag
from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/motor_currents')


def recorder_name() -> str:
    return 'id_learning/recorder'


def test_replay_to_recorder_gives_back_the_played_bag(tmp_path, nodes, listener):
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    from id_learning.nodes.qos import CLOCK_QOS

    played = write_recording(sine_recording(250), tmp_path / 'played')
    recorded = tmp_path / 'recorded'
    listener.subscribe(DiagnosticArray, '/diagnostics')
    listener.subscribe(Clock, '/clock', CLOCK_QOS)
    recorder = nodes(
        'recorder',
        {'output': str(recorded), 'split_duration_s': 0.5, 'diagnostics_period_s': 0.2},
    )
    replay = nodes(
        'replay',
        {
            'bag': str(played),
            'reference_mode': 'none',
            'wait_for_subscribers': 3,  # the recorder's two subscriptions and our /clock
            'diagnostics_period_s': 0.2,
        },
    )
    assert replay.wait(120) == 0, replay.log()
    assert 'lateness against the 8 ms grid' in replay.log()

    def recorder_has_all() -> bool:
        values = listener.diagnostics(recorder_name())
        return values is not None and int(values['written']) >= 500

    listener.wait_for(recorder_has_all, 30, 'the recorder to write 500 messages')
    assert recorder.stop() == 0
    assert 'received 500, written 500, dropped 0' in recorder.log()

    info = bag_info(recorded)
    assert len(info.files) >= 3  # split every 0.5 s of log time over a 2 s replay
    assert {t.name: t.count for t in info.topics} == {'/joint_states': 250, '/motor_currents': 250}
    for topic in TOPICS:
        original = [data for _, _, data in iter_raw(played, [topic])]
        copy = [data for _, _, data in iter_raw(recorded, [topic])]
        assert copy == original  # byte for byte, in order
        expected, got = read_joint_states(played, topic), read_joint_states(recorded, topic)
        np.testing.assert_array_equal(got.stamps_ns, expected.stamps_ns)
        for field in ('position', 'velocity', 'effort'):
            a, b = getattr(expected, field), getattr(got, field)
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_array_equal(b, a)
    # /clock carried the cycle stamps (best effort: some may be missing, none invented).
    with listener.condition:
        clock = [
            m.clock.sec * 1_000_000_000 + m.clock.nanosec for m in listener.messages['/clock']
        ]
    assert clock
    assert set(clock) <= set(read_joint_states(played, '/joint_states').stamps_ns.tolist())
    # Log times are receive times: increasing, spanning about the played 2 s.
    log_ns = read_joint_states(recorded, '/joint_states').log_ns
    assert np.all(np.diff(log_ns) >= 0)
    assert 1.5e9 < log_ns[-1] - log_ns[0] < 10e9


def test_a_sigkilled_recorder_leaves_everything_received_until_one_second_before(
    tmp_path, nodes, listener
):
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    path = tmp_path / 'killed'
    recorder = nodes('recorder', {'output': str(path)})
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
    sent_at: list[float] = []  # monotonic time of message k on both topics [s]
    period = 0.008
    start = time.monotonic()
    kill_after = 3.0  # seconds of streaming before the kill
    killed_at = None
    k = 0
    while killed_at is None or time.monotonic() < killed_at + 0.3:
        # Paced on absolute deadlines: this is the stream under test, not synchronisation.
        delay = start + k * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        msg = JointState(name=names, position=[float(k)] * 6, velocity=[0.0] * 6)
        msg.header.stamp.sec = k
        for publisher in publishers.values():
            publisher.publish(msg)
        sent_at.append(time.monotonic())
        k += 1
        if killed_at is None and sent_at[-1] - start >= kill_after:
            recorder.kill()
            killed_at = time.monotonic()
    assert killed_at is not None
    assert not (path / 'metadata.yaml').exists()  # torn: the writer never closed

    report = recover_bag(path)
    assert not report.is_intact
    must_have = sum(1 for t in sent_at if t <= killed_at - 1.0)
    assert must_have > 200  # the precondition: two seconds of data to look for
    for topic in TOPICS:
        seconds = _stamps_s(path, topic)
        # Everything up to one second before the kill, in order, nothing invented.
        assert seconds[:must_have] == list(range(must_have)), topic
        assert seconds == list(range(len(seconds))), topic
        assert len(seconds) <= len(sent_at)


def _stamps_s(path, topic) -> list[int]:
    series = read_joint_states(path, topic)
    return (series.stamps_ns // 1_000_000_000).tolist()


def test_a_publisher_of_another_type_is_named_once_in_the_log_and_on_diagnostics(
    tmp_path, nodes, listener
):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    listener.subscribe(DiagnosticArray, '/diagnostics')
    wrong = listener.node.create_publisher(String, '/motor_currents', 10)
    recorder = nodes('recorder', {'output': str(tmp_path / 'bag'), 'diagnostics_period_s': 0.2})

    def named() -> bool:
        values = listener.diagnostics(recorder_name())
        return values is not None and values.get('/motor_currents wrong type') == (
            'std_msgs/msg/String'
        )

    listener.wait_for(named, 30, "the recorder's diagnostics to name std_msgs/msg/String")
    # A few more diagnostics periods: the warning is not repeated.
    seen = len(listener.messages['/diagnostics'])
    listener.wait_for(
        lambda: len(listener.messages['/diagnostics']) >= seen + 3, 10, 'three more diagnostics'
    )
    assert recorder.stop() == 0
    log = recorder.log()
    warning = 'a publisher sends std_msgs/msg/String, but the topic is recorded as'
    assert log.count(warning) == 1, log
    assert 'sensor_msgs/msg/JointState' in log
    assert '/joint_states wrong type' not in listener.diagnostics(recorder_name())
    listener.node.destroy_publisher(wrong)


def test_every_topic_the_nodes_publish_reads_back_from_a_recording(
    tmp_path, nodes, listener, tiny_artifacts
):
    """replay -> predictor -> recorder of every topic: each message decodes strictly, in the
    package's reader and in rosbags (no trailing bytes from rclpy's serializer)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rosbags.rosbag2 import Reader

    from id_learning.bag import iter_messages
    from id_learning.bag.messages import typestore

    played = write_recording(sine_recording(120), tmp_path / 'played')
    recorded = tmp_path / 'recorded'
    types = {
        '/joint_states': 'sensor_msgs/msg/JointState',
        '/motor_currents': 'sensor_msgs/msg/JointState',
        '/reference': 'trajectory_msgs/msg/JointTrajectory',
        '/tau_u': 'sensor_msgs/msg/JointState',
        '/commands': 'std_msgs/msg/Float64MultiArray',
        '/clock': 'rosgraph_msgs/msg/Clock',
        '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    }
    listener.subscribe(DiagnosticArray, '/diagnostics')
    recorder = nodes(
        'recorder',
        {
            'output': str(recorded),
            'topics': list(types),
            'msg_types': list(types.values()),
            'reliability': 'best_effort',  # to match /clock too
            'diagnostics_period_s': 0.2,
        },
    )
    nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['mlp']),
            'input_topic': '/reference',
            'input_depth': 200,
            'command_topic': '/commands',
            'diagnostics_period_s': 0.2,
        },
    )

    def predictor_is_recorded() -> bool:
        values = listener.diagnostics('id_learning/predictor') or {}
        return int(values.get('tau_u_subscriptions', 0)) >= 1

    listener.wait_for(predictor_is_recorded, STARTUP_S, 'the recorder to match /tau_u')
    replay = nodes(
        'replay',
        {
            'bag': str(played),
            'reference_topic': '/reference',
            'wait_for_subscribers': 5,  # recorder: 3 played topics and /clock; predictor: 1
            'diagnostics_period_s': 0.2,
        },
    )
    assert replay.wait(120) == 0, replay.log()

    def tau_u_recorded() -> bool:
        values = listener.diagnostics(recorder_name()) or {}
        return int(values.get('/tau_u written', 0)) >= 100

    listener.wait_for(tau_u_recorded, 30, 'the recorder to write 100 tau_u')
    assert recorder.stop() == 0, recorder.log()

    counts = {t.name: t.count for t in bag_info(recorded).topics}
    assert set(counts) == set(types)
    assert all(counts[topic] > 0 for topic in types), counts
    for topic in types:
        assert len(list(iter_messages(recorded, topic))) == counts[topic]
    store = typestore()
    with Reader(recorded) as reader:
        for connection, _, data in reader.messages():
            assert connection.msgtype == types[connection.topic]
            store.deserialize_cdr(data, connection.msgtype)  # strict: raises on a size mismatch
    tau_u = read_joint_states(recorded, '/tau_u')
    assert tau_u.effort is not None
    assert np.isfinite(tau_u.effort).all()
