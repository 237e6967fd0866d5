"""Two replays of one name are each told, though a replay may finish before run_node's first
name check (1 s after start): it also looks as it starts playing and as it finishes."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording, write_contract_bag

pytestmark = pytest.mark.ros

DEADLINE_S = 30.0


def test_two_replays_of_one_name_each_say_so_without_run_node(tmp_path, domain_id, listener):
    import rclpy
    from rcl_interfaces.msg import Log
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from sensor_msgs.msg import JointState

    from id_learning.nodes.replay import Replay

    bag = write_contract_bag(tmp_path / 'bag', sine_recording(1000))
    listener.subscribe(
        Log, '/rosout', QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    made: list[Replay] = []

    def replay(**values: object) -> Replay:
        overrides = [Parameter(k, value=v) for k, v in {'bag': str(bag), **values}.items()]
        made.append(Replay(context=context, parameter_overrides=overrides))
        return made[-1]

    try:
        # Not spun by run_node: only the replay's own checks can tell. The first waits for a
        # subscriber (so it starts playing once the twin is on the graph) and plays on while the
        # second, which plays at once, finishes.
        first = replay(wait_for_subscribers=1, wait_timeout_s=DEADLINE_S, duration_s=6.0)
        second = replay(duration_s=1.0, publish_clock=False)
        graph = listener.node.get_node_names_and_namespaces
        listener.wait_for(lambda: graph().count(('replay', '/')) == 2, DEADLINE_S, 'two replays')
        listener.subscribe(JointState, '/joint_states')
        listener.wait_for(second.done.done, DEADLINE_S, 'the second replay finished')

        def told() -> list[str]:
            return [
                m.name
                for m in listener.messages['/rosout']
                if 'another node is also named /replay' in m.msg and '__node:=' in m.msg
            ]

        listener.wait_for(lambda: len(told()) >= 2, DEADLINE_S, 'both replays told')
        assert first.done.done() is False  # the first was told as it started playing
    finally:
        for node in made:
            node.close()
            node.destroy_node()
        context.try_shutdown()
