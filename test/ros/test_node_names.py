"""Two nodes of one name: each is told, with the remedy; a node alone never is."""

from __future__ import annotations

import time

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.nodes.runtime import NameClash

pytestmark = pytest.mark.ros

DEADLINE_S = 20.0


@pytest.fixture
def context(domain_id):
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        yield context
    finally:
        context.try_shutdown()


def _poll_until(condition, deadline_s: float = DEADLINE_S) -> bool:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)  # the poll interval of a wait with a deadline, not synchronisation
    return False


def test_a_second_node_of_the_same_name_is_found_and_a_node_alone_never(context):
    from rclpy.node import Node

    first = Node('twin', namespace='/cell', context=context)
    alone = Node('alone', namespace='/cell', context=context)
    try:
        watch_alone = NameClash(alone, time.monotonic, 0.0, 0.0)
        seen = _poll_until(lambda: ('twin', '/cell') in alone.get_node_names_and_namespaces())
        assert seen
        assert not watch_alone.poll()
        second = Node('twin', namespace='/cell', context=context)
        try:
            watch = NameClash(first, time.monotonic, 0.0, 0.0)
            assert _poll_until(watch.poll)
            assert not NameClash(alone, time.monotonic, 0.0, 0.0).poll()
        finally:
            second.destroy_node()
    finally:
        first.destroy_node()
        alone.destroy_node()


def test_the_checks_come_at_their_times(context):
    from rclpy.node import Node

    node = Node('solo', context=context)
    now = [0.0]
    try:
        watch = NameClash(node, lambda: now[0], first_s=1.0, every_s=2.0)
        assert (watch.poll(), watch.next_s) == (False, 1.0)  # not due yet
        now[0] = 1.5
        assert (watch.poll(), watch.next_s) == (False, 3.5)
        now[0] = 2.0
        assert (watch.poll(), watch.next_s) == (False, 3.5)
    finally:
        node.destroy_node()


def test_two_recorders_of_one_name_each_say_so_on_rosout(nodes, listener, tmp_path):
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from ros.ros_helpers import STARTUP_S

    # rosout keeps its last messages for late subscribers: the line comes a second after start.
    listener.subscribe(
        Log, '/rosout', QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    for k in (1, 2):
        nodes('recorder', {'output': str(tmp_path / f'bag{k}')})

    def told() -> int:
        with listener.condition:
            return sum(
                'another node is also named /recorder' in m.msg and '__node:=' in m.msg
                for m in listener.messages['/rosout']
            )

    listener.wait_for(lambda: told() >= 2, STARTUP_S, 'both recorders told of the other')
