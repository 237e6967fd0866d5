"""A recorded topic that never arrives is warned of: once, a while after another topic's first
message, and in the final summary (a warning naming it). In-process, on a short wait."""

from __future__ import annotations

import threading

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

pytestmark = pytest.mark.ros

DEADLINE_S = 30.0


def test_a_topic_that_never_arrives_is_warned_of_while_recording_and_at_close(
    tmp_path, domain_id, listener, monkeypatch
):
    import rclpy
    from rcl_interfaces.msg import Log
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from sensor_msgs.msg import JointState

    from id_learning.nodes import recorder as module

    monkeypatch.setattr(module, 'SILENT_AFTER_S', 0.3)
    listener.subscribe(
        Log, '/rosout', QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    executor = SingleThreadedExecutor(context=context)
    stop = threading.Event()
    overrides = [
        Parameter('output', value=str(tmp_path / 'bag')),
        Parameter('flush_period_s', value=0.1),
    ]
    recorder = module.Recorder(context=context, parameter_overrides=overrides)

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    executor.add_node(recorder)
    thread.start()

    def warnings(text: str) -> list[str]:
        with listener.condition:
            return [
                m.msg
                for m in listener.messages['/rosout']
                if m.name == 'recorder' and m.level == Log.WARN and text in m.msg
            ]

    try:
        publisher = listener.node.create_publisher(JointState, '/joint_states', 10)
        message = JointState(name=['a'], position=[0.0], velocity=[0.0], effort=[0.0])
        timer = listener.node.create_timer(0.01, lambda: publisher.publish(message))
        early = 'nothing received on /motor_currents for 0.3 s while other topics arrive'
        listener.wait_for(lambda: warnings(early), DEADLINE_S, 'the warning while recording')
        timer.cancel()
        assert recorder.counts['/joint_states'].received > 0
    finally:
        stop.set()
        thread.join(DEADLINE_S)
        executor.remove_node(recorder)
        recorder.close()
        recorder.destroy_node()
        executor.shutdown()
        context.try_shutdown()
    final = 'nothing received on /motor_currents: the bag has no messages of it'
    listener.wait_for(lambda: warnings(final), DEADLINE_S, 'the final summary as a warning')
    (summary,) = warnings(final)
    assert '/motor_currents: received 0, written 0' in summary
    assert 'on /joint_states' not in summary
    assert len(warnings(early)) == 1  # said once
