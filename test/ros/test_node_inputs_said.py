"""What the nodes say once about how they are run: the predictor's input and threads, the
recorder's output. Real nodes in their own processes, real DDS over loopback."""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from predictor.tiny_artifacts import reference_run
from ros.ros_helpers import STARTUP_S

from id_learning.bag import bag_info

pytestmark = pytest.mark.ros

PREDICTOR = 'id_learning/predictor'


def _trajectory(joints, q, v, a, stamp_ns: int, ahead_s: int):
    from builtin_interfaces.msg import Duration, Time
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    point = JointTrajectoryPoint(positions=list(q), velocities=list(v), accelerations=list(a),
                                 time_from_start=Duration(sec=ahead_s))  # fmt: skip
    msg = JointTrajectory(joint_names=list(joints), points=[point])
    msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    return msg


def test_predictor_says_once_a_point_ahead_a_second_publisher_and_too_many_threads(
    nodes, listener, domain_id, tiny_artifacts, mabi
):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.qos import reference_qos
    from id_learning.predictor.threads import cpu_cores

    cores = cpu_cores()
    listener.subscribe(DiagnosticArray, '/diagnostics')
    publisher = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['mlp']),
            'input_topic': '/reference',
            'input_depth': 100,
            'diagnostics_period_s': 0.05,
            'torch_threads': len(cores) + 1,
        },
    )

    def diagnostics() -> dict[str, str]:
        return listener.diagnostics(PREDICTOR) or {}

    def messages() -> list[str]:
        with listener.condition:
            return [status.message for msg in listener.messages['/diagnostics']
                    for status in msg.status if status.name == PREDICTOR]  # fmt: skip

    listener.wait_for(lambda: publisher.get_subscription_count() >= 1, STARTUP_S, 'the predictor')
    listener.wait_for(lambda: diagnostics().get('input_publishers') == '1', 30, 'one publisher')
    # A controller that sends the point one second ahead: taken, counted, said once.
    _, q, v, a = reference_run(40)
    start_ns = time.time_ns()
    for k in range(40):
        publisher.publish(_trajectory(mabi.joints, q[k], v[k], a[k], start_ns + k * 8_000_000, 1))
    listener.wait_for(lambda: diagnostics().get('points_ahead') == '40', 30, '40 points ahead')
    assert diagnostics()['received'] == '40'  # taken as the current cycle's, as documented

    # A second publisher on the input, in another node: named on /diagnostics, said once.
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    sender = rclpy.create_node('second_sender', context=context)
    try:
        second = sender.create_publisher(JointTrajectory, '/reference', reference_qos(10))
        listener.wait_for(
            lambda: diagnostics().get('input_publishers') == '2', STARTUP_S, 'two publishers'
        )
        listener.wait_for(
            lambda: any('2 publishers on /reference' in m for m in messages()[-3:]),
            30,
            'the two publishers in the diagnostics message',
        )
        listener.wait_for(
            lambda: 'publishers on /reference (node /second_sender' in predictor.log(),
            30,
            'the two publishers said in the log, the second one named',
        )
        sender.destroy_publisher(second)
        listener.wait_for(
            lambda: diagnostics().get('input_publishers') == '1', STARTUP_S, 'one publisher again'
        )
    finally:
        sender.destroy_node()
        context.try_shutdown()
    assert 'publishers on /reference' not in messages()[-1]
    assert predictor.stop() == 0
    log = predictor.log()
    assert log.count('points[0].time_from_start is 1 s, not 0') == 1, log
    assert (
        log.count(
            '2 publishers on /reference (node /second_sender, node /test_listener): the '
            'predictor takes one reference'
        )
        == 1
    ), log
    assert f'torch_threads {len(cores) + 1} oversubscribes the {len(cores)} CPU core' in log, log


def test_a_second_recorder_on_the_same_output_is_refused_naming_the_parameter(
    nodes, listener, tmp_path
):
    from diagnostic_msgs.msg import DiagnosticArray

    listener.subscribe(DiagnosticArray, '/diagnostics')
    out = tmp_path / 'bag'
    first = nodes('recorder', {'output': str(out), 'diagnostics_period_s': 0.1}, name='first')
    listener.wait_for(
        lambda: listener.diagnostics('id_learning/recorder') is not None,
        STARTUP_S,
        'the first recorder to record',
    )
    second = nodes('recorder', {'output': str(out)}, name='second')
    long_name = nodes('recorder', {'output': str(tmp_path / ('x' * 300))}, name='long')
    assert second.wait(STARTUP_S) == 2
    said = second.log()
    assert f'another process (pid {first.process.pid}) is writing it' in said, said
    assert 'choose another output:=PATH' in said
    assert '--out' not in said
    assert long_name.wait(STARTUP_S) == 2
    said = long_name.log()
    assert 'file name too long' in said
    assert 'choose a shorter output:=PATH' in said
    assert 'Traceback' not in said
    assert first.stop() == 0
    assert bag_info(out).topics  # the first one's bag, finished
    assert sorted(os.listdir(tmp_path)) == ['bag', 'first.log', 'long.log', 'second.log']


def _graph(monkeypatch, topic: str, expected: str):
    """A graph of (node name, type) publishers on ``topic``, its watcher and its clock [s]."""
    from types import SimpleNamespace

    from id_learning.nodes import endpoints
    from id_learning.nodes.endpoints import ForeignPublishers

    graph: list[tuple[str, str]] = []
    node = SimpleNamespace(get_publishers_info_by_topic=lambda _: [
        SimpleNamespace(node_name=name, node_namespace='/', topic_type=kind)
        for name, kind in graph])  # fmt: skip
    clock = [100.0]
    monkeypatch.setattr(endpoints.time, 'monotonic', lambda: clock[0])
    return graph, ForeignPublishers(node, {topic: expected}), clock


def test_several_publishers_are_said_once_per_episode_and_wait_for_their_names(monkeypatch):
    from id_learning.nodes import endpoints
    from id_learning.nodes.endpoints import shared_text

    graph, publishers, clock = _graph(
        monkeypatch, '/reference', 'trajectory_msgs/msg/JointTrajectory'
    )

    def look(*nodes: str) -> bool:
        graph[:] = [(name, 'trajectory_msgs/msg/JointTrajectory') for name in nodes]
        publishers.look()
        return publishers.newly_shared('/reference')

    assert not look('a')
    assert look('a', 'b')  # said
    assert not look('a', 'b')  # once
    assert not look('a', 'b', 'b')
    assert not look('a')  # the episode ends
    unknown = endpoints.UNKNOWN_NODE
    assert not look('a', unknown)  # its name may come with the next look
    clock[0] += endpoints.NAME_WAIT_S / 2
    assert look('a', 'c')  # it came
    assert not look('a')
    assert not look('a', unknown)
    clock[0] += endpoints.NAME_WAIT_S
    assert look('a', unknown)  # said without it after a while
    assert publishers.shared('/reference') == sorted(['/a', f'/{unknown}'])
    assert shared_text('/r', ['/a', '/b', '/b'], 'why') == (
        '3 publishers on /r (node /a, node /b twice): why'
    )
    assert 'a node not discovered yet' in shared_text('/r', ['/a', f'/{unknown}'], 'why')


def test_a_publisher_of_another_type_is_said_once_by_its_name(monkeypatch):
    """Discovery may show it first without its node's name: it waits for the name (CI race)."""
    from id_learning.nodes import endpoints
    from id_learning.nodes.endpoints import Foreign

    graph, publishers, clock = _graph(monkeypatch, '/motor_currents', 'sensor_msgs/msg/JointState')
    unknown, string = endpoints.UNKNOWN_NODE, 'std_msgs/msg/String'

    graph[:] = [(unknown, string)]
    assert publishers.look() == []  # its name may come with the next look
    assert publishers.types_seen('/motor_currents') == [string]  # known for the final report
    clock[0] += endpoints.NAME_WAIT_S / 2
    graph[:] = [('listener', string)]
    assert publishers.look() == [Foreign('/motor_currents', '/listener', string)]
    assert publishers.look() == []  # once
    graph[:] = [('listener', string), (unknown, string)]
    assert publishers.look() == []
    clock[0] += endpoints.NAME_WAIT_S
    assert publishers.look() == [Foreign('/motor_currents', f'/{unknown}', string)]  # unnamed
