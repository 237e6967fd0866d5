"""Two publishers on one recorded topic number their messages each from 1: the recorder counts
gaps per publisher, so their interleaved numbers are no loss (probe W01: 'dropped 678')."""

from __future__ import annotations

import time

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.log_wait import wait_for_log

from id_learning.bag import bag_info

pytestmark = pytest.mark.ros


def test_two_publishers_interleaved_count_nothing_lost_and_all_is_written(
    tmp_path, nodes, listener, domain_id
):
    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    # The second publisher in a context (a DDS participant) of its own, as another process.
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    other = rclpy.create_node('pb', context=context)
    try:
        path = tmp_path / 'bag'
        recorder = nodes('recorder', {'output': str(path), 'topics': ['/joint_states'],
                                      'msg_types': ['sensor_msgs/msg/JointState'],
                                      'flush_period_s': 0.5})  # fmt: skip
        pa = listener.node.create_publisher(JointState, '/joint_states', sensor_qos(200))
        listener.wait_for(lambda: pa.get_subscription_count() >= 1, 90, 'the recorder')
        pb = None  # advertised once pa streams, as the probe's second process was
        names = [f'joint_{i}' for i in range(1, 7)]
        period, second_after, duration = 0.008, 0.5, 3.0  # 125 Hz each, pb 0.5 s later
        sent = 0
        start = time.monotonic()
        k = 0
        while (now := time.monotonic()) - start < duration:
            delay = start + k * period - now
            if delay > 0:
                time.sleep(delay)
            msg = JointState(name=names, position=[float(k)] * 6, velocity=[0.0] * 6)
            pa.publish(msg)
            sent += 1
            if pb is None and k * period >= second_after:
                pb = other.create_publisher(JointState, '/joint_states', sensor_qos(200))
            if pb is not None and pb.get_subscription_count() >= 1:  # what is matched arrives
                pb.publish(msg)
                sent += 1
            k += 1
        wait_for_log(recorder, '2 publishers on /joint_states')
        assert sent > 1.5 * duration / period  # the precondition: both streamed
        assert recorder.stop() == 0
        log = recorder.log()
        assert 'lost before reception' not in log, log
        assert f'/joint_states: received {sent}, written {sent}, dropped 0, lost 0' in log, log
        (topic,) = [t for t in bag_info(path).topics if t.name == '/joint_states']
        assert topic.count == sent
    finally:
        other.destroy_node()
        context.try_shutdown()


def test_gaps_are_counted_in_each_publishers_numbers():
    from id_learning.nodes.sequence_gaps import SequenceGaps

    publishers = [1]
    gaps = SequenceGaps(lambda: publishers[0])
    assert [gaps.take(n)[0] for n in (290, 291, 293)] == [0, 0, 1]  # one lost: counted
    publishers[0] = 2
    assert [gaps.take(n)[0] for n in (1, 294, 2, 295, 5, 296)] == [0, 0, 0, 0, 2, 0]
    assert len(gaps) == 2
    fresh = SequenceGaps(lambda: 2)  # both published before they matched: no loss
    assert [fresh.take(n)[0] for n in (100, 500, 101, 501)] == [0, 0, 0, 0]
