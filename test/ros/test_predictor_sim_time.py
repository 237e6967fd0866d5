"""predictor under use_sim_time with no /clock: the stale guard and /diagnostics still run.

Also, over DDS: unusable measured currents freeze the adaptation with the reason said once (log
and /diagnostics), and a session that learnt nothing leaves the stored adaptation file as it was.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from predictor.tiny_artifacts import reference_run
from ros.ros_helpers import STARTUP_S

pytestmark = pytest.mark.ros

NAME = 'id_learning/predictor'


def send_run(listener, reference, mabi, n: int, currents=None, effort=None) -> None:
    """Publish n reference samples, each after the tau_u of the one before; with ``currents``,
    answer each with a JointState built by ``effort(names, k)`` -> (names, effort)."""
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    stamps, q, v, a = reference_run(n)
    for k in range(n):
        msg = JointTrajectory(joint_names=list(mabi.joints))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamps[k]), 1_000_000_000)
        msg.points = [
            JointTrajectoryPoint(
                positions=list(q[k]), velocities=list(v[k]), accelerations=list(a[k])
            )
        ]
        reference.publish(msg)
        listener.wait_for(
            lambda k=k: len(listener.messages['/tau_u']) > k, 10, f'tau_u of sample {k}'
        )
        if currents is not None and effort is not None:
            names, values = effort(list(mabi.joints), k)
            measured = JointState(name=names, effort=values)
            measured.header = msg.header
            currents.publish(measured)


def test_without_a_clock_the_stale_guard_fires_and_diagnostics_are_published(
    nodes, listener, tiny_artifacts, mabi
):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.qos import reference_qos

    listener.subscribe(JointState, '/tau_u')
    listener.subscribe(Float64MultiArray, '/ff/commands')
    listener.subscribe(DiagnosticArray, '/diagnostics')
    reference = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['rnea_lq']),
            'input_topic': '/reference',
            'input_depth': 100,
            'stale_after_cycles': 25,
            'diagnostics_period_s': 0.1,
            'command_topic': '/ff/commands',
            'use_sim_time': True,  # and nothing publishes /clock: ROS time stands at 0
        },
    )
    # /diagnostics comes although ROS time never advances (it carries the matched tau_u).
    listener.wait_for(
        lambda: (
            reference.get_subscription_count() >= 1
            and int((listener.diagnostics(NAME) or {}).get('tau_u_subscriptions', 0)) >= 1
        ),
        STARTUP_S,
        'the predictor to connect and publish /diagnostics',
    )
    send_run(listener, reference, mabi, 20)
    with listener.condition:
        commands_before = len(listener.messages['/ff/commands'])
    # The reference stopped: stale within 1.5 thresholds (0.3 s), zero command sent once.
    listener.wait_for(
        lambda: (listener.diagnostics(NAME) or {}).get('stale') == 'True', 10, 'the stale report'
    )
    listener.wait_for(
        lambda: any(not any(m.data) for m in listener.messages['/ff/commands'][commands_before:]),
        10,
        'the zero command on stale',
    )
    values = listener.diagnostics(NAME) or {}
    assert int(values['stale_episodes']) == 1
    assert predictor.stop() == 0
    assert 'reference stale: no valid sample' in predictor.log()


def test_unusable_currents_are_said_once_and_leave_the_stored_adaptation_as_it_was(
    nodes, listener, tiny_artifacts, mabi, tmp_path
):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    from id_learning.nodes.qos import reference_qos
    from id_learning.predictor.adaptation_store import adaptation_path

    artifact = tmp_path / 'rnea_lq'
    shutil.copytree(tiny_artifacts['rnea_lq'], artifact)
    stored = adaptation_path(artifact)
    n_joints = len(mabi.joints)
    earlier = {
        'joints': list(mabi.joints),
        'mode': 'rls',
        'theta': [[1.0, 2.0, 3.0]] * n_joints,
        'error_scale_nm': [5.0] * n_joints,
        'updates': 300,
        'updates_total': 300,
        # Learnt on this model: a state of another model is not continued.
        'artifact_sha256': json.loads((artifact / 'model.json').read_text())['artifact_sha256'],
    }
    stored.write_text(json.dumps(earlier), encoding='utf-8')
    before = stored.read_bytes()
    listener.subscribe(JointState, '/tau_u')
    listener.subscribe(DiagnosticArray, '/diagnostics')
    reference = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    currents = listener.node.create_publisher(JointState, '/motor_currents', reference_qos(100))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(artifact),
            'input_topic': '/reference',
            'input_depth': 100,
            'stale_after_cycles': 5000,
            # One sample per tau_u: a loaded machine sends slower than the stamps advance.
            'max_age_s': 0.0,
            'diagnostics_period_s': 0.1,
            'adaptation': 'rls',
        },
    )
    listener.wait_for(
        lambda: (
            reference.get_subscription_count() >= 1
            and currents.get_subscription_count() >= 1
            and int((listener.diagnostics(NAME) or {}).get('tau_u_subscriptions', 0)) >= 1
        ),
        STARTUP_S,
        'the predictor to connect',
    )

    def renamed_then_nan(names, k):
        if k < 10:
            return [f'axis_{j + 1}' for j in range(len(names))], [0.1] * len(names)
        return names, [0.1, np.nan, *[0.1] * (len(names) - 2)]

    send_run(listener, reference, mabi, 20, currents, renamed_then_nan)
    listener.wait_for(
        lambda: int((listener.diagnostics(NAME) or {}).get('adaptation_frozen', 0)) >= 20,
        10,
        'every sample frozen',
    )
    values = listener.diagnostics(NAME) or {}
    assert "['joint_2'] not finite" in values['adaptation_frozen_reason']
    assert '/motor_currents' in values['adaptation_frozen_reason']
    # Continued from the stored values: the correction is on from the first sample.
    assert float(values['adapted_offset_nm_joint_1']) == 3.0
    assert predictor.stop() == 0
    log = predictor.log()
    assert log.count("are not the model's joints") == 1
    assert log.count('adaptation learns nothing from a sample') == 2  # one per kind
    assert 'adaptation continues from' in log
    assert 'left as it was' in log
    assert stored.read_bytes() == before
