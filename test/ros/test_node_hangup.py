"""A closed terminal or ssh session (SIGHUP) stops a node as SIGTERM does: its work is kept.

The probe's B44: SIGHUP's default ended a recorder at once (no metadata.yaml, the messages of
its last flush period lost) and a predictor without saving what its adaptation had learnt.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import signal

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from record.hangup import hangup_at_default
from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.bag import read_joint_states
from id_learning.dataset.recording import write_recording
from id_learning.models.registry import load_model

pytestmark = pytest.mark.ros

TOPICS = ('/joint_states', '/motor_currents')
#: Deadline for a node to exit after the signal [s].
EXIT_S = 30.0
N_CYCLES = 50


def test_a_recorder_hung_up_finishes_its_bag_with_every_message_it_received(
    tmp_path, nodes, listener
):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import sensor_qos

    path = tmp_path / 'bag'
    listener.subscribe(DiagnosticArray, '/diagnostics')
    # A long flush period: the messages are received, not yet on disk, when the signal comes.
    with hangup_at_default():
        recorder = nodes(
            'recorder', {'output': str(path), 'diagnostics_period_s': 0.1, 'flush_period_s': 0.5}
        )
    publishers = listener.publishers_subscribed(JointState, TOPICS, sensor_qos(200))
    names = [f'joint_{i}' for i in range(1, 7)]
    for k in range(N_CYCLES):
        msg = JointState(name=names, position=[float(k)] * 6, velocity=[0.0] * 6)
        msg.header.stamp.sec = k + 1
        for publisher in publishers.values():
            publisher.publish(msg)

    def received() -> bool:
        values = listener.diagnostics('id_learning/recorder')
        return values is not None and int(values['received']) >= len(TOPICS) * N_CYCLES

    listener.wait_for(received, EXIT_S, 'the recorder to receive every message')
    recorder.process.send_signal(signal.SIGHUP)
    assert recorder.wait(EXIT_S) == 0, recorder.log()[-2000:]  # before the fix: -1
    log = recorder.log()
    assert 'Traceback' not in log
    assert f'received {len(TOPICS) * N_CYCLES}, written {len(TOPICS) * N_CYCLES}' in log, log
    assert (path / 'metadata.yaml').is_file()  # closed: the bag is whole
    for topic in TOPICS:
        stamps = read_joint_states(path, topic).stamps_ns
        assert stamps.tolist() == [(k + 1) * 1_000_000_000 for k in range(N_CYCLES)], topic


def test_an_adapting_predictor_hung_up_saves_what_it_learnt(
    nodes, listener, tiny_artifacts, mabi, tmp_path
):
    from diagnostic_msgs.msg import DiagnosticArray

    artifact = tmp_path / 'rnea_lq'
    shutil.copytree(tiny_artifacts['rnea_lq'], artifact)
    model = load_model(artifact, mabi)
    n = 200
    recording = sine_recording(n)
    a = np.gradient(recording.velocity, 0.008, axis=0)
    tau = model.predict(recording.position, recording.velocity, a)
    per_ampere = mabi.drives.gear_ratio * mabi.drives.torque_constant
    extra = np.zeros(6)
    extra[0] = 40.0
    bag = write_recording(
        dataclasses.replace(recording, current=(tau + extra) / per_ampere), tmp_path / 'bag'
    )
    listener.subscribe(DiagnosticArray, '/diagnostics')
    with hangup_at_default():
        predictor = nodes(
            'predictor',
            {
                'artifact': str(artifact),
                'input_topic': '/reference',
                'input_depth': 100,
                'diagnostics_period_s': 0.1,
                'adaptation': 'rls',
            },
        )
    replay = nodes(
        'replay',
        {
            'bag': str(bag),
            'reference_topic': '/reference',
            'publish_clock': False,
            'wait_for_subscribers': 2,  # the predictor's reference and currents
            'wait_timeout_s': STARTUP_S,
        },
    )
    assert replay.wait(120) == 0

    def updates() -> int:
        values = listener.diagnostics('id_learning/predictor') or {}
        return int(values.get('adaptation_updates', 0))

    listener.wait_for(lambda: updates() >= n // 2, EXIT_S, 'the adaptation to learn')
    predictor.process.send_signal(signal.SIGHUP)
    assert predictor.wait(EXIT_S) == 0, predictor.log()[-2000:]  # before the fix: -1
    assert 'Traceback' not in predictor.log()
    saved = tmp_path / 'rnea_lq.adaptation.json'
    assert saved.is_file(), predictor.log()[-2000:]
    assert json.loads(saved.read_text())['updates'] >= n // 2
